"""`isolab serve` and `isolab calibrate` start without the heavy libraries: they load where a request or a
fit needs them (Dask when the service starts its cluster; the engine's kernels with numba at the first
simulation or validation of a study; xarray, matplotlib, scipy's fitting, filtering and statistics on first
use). The figures are in `python -m benchmarks startup`."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from benchmarks.startup import command_imports

HEAVY = (
    "numba",
    "distributed",
    "xarray",
    "pandas",
    "matplotlib",
    "netCDF4",
    "SALib",
    "scipy.optimize",
    "scipy.signal",
    "scipy.stats",
)
"""Libraries that take a tenth of a second or more each to import."""


def _loaded_after_importing(modules: list[str]) -> list[str]:
    code = "import sys\nimport isolab.service.cli\n" + "".join(f"import {m}\n" for m in modules)
    code += f"print(__import__('json').dumps(sorted(m for m in {HEAVY!r} if m in sys.modules)))"
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True
    )
    return json.loads(out.stdout.splitlines()[-1])


@pytest.mark.parametrize("command", ["serve", "calibrate"])
def test_the_command_imports_no_heavy_library(command: str) -> None:
    modules = command_imports()[command]
    if command == "serve":  # the whole app, every route module with it
        assert "isolab.service.api.app" in modules
    assert _loaded_after_importing(modules) == []


def test_the_check_sees_a_library_imported() -> None:
    loaded = _loaded_after_importing(["scipy.stats", "distributed"])
    assert "distributed" in loaded and "scipy.stats" in loaded
