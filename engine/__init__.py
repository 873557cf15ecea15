"""isolab's physics engine: a rigid machine base on vibration isolators, shaken by its own stages.

Plain numpy arrays in (``SceneBatch``), arrays out (``SimulationResult``); Numba kernels run many cases
per call. See ``simulate``.
"""

import hashlib
import os
import sys
from collections.abc import Mapping
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

ENGINE_FOLDER = Path(__file__).resolve().parent
"""Where the engine's sources are (their hash names the kernel cache folder)."""


def engine_source_hash(folder: Path = ENGINE_FOLDER) -> str:
    """A 12-digit hash of every engine source (``*.py`` of ``folder`` and its sub-folders, by relative path).

    Numba notices an edit only in a kernel's own file, while the kernels inline code from each other's
    modules: a cache folder named by this hash starts fresh after an edit anywhere in the engine."""
    digest = hashlib.sha1()
    for path in sorted(folder.rglob("*.py")):
        if "__pycache__" in path.parts:
            continue
        digest.update(path.relative_to(folder).as_posix().encode())
        digest.update(b"\0")
        digest.update(path.read_bytes())
    return digest.hexdigest()[:12]


def default_kernel_cache_folder(
    folder: Path = ENGINE_FOLDER, environ: Mapping[str, str] = os.environ
) -> Path:
    """The folder the compiled kernels go to unless ``NUMBA_CACHE_DIR`` names one:
    ``<XDG_CACHE_HOME or ~/.cache>/isolab/numba/<engine_source_hash>``, one per machine and engine version."""
    base = environ.get("XDG_CACHE_HOME") or str(Path(environ.get("HOME") or Path.home()) / ".cache")
    return Path(base) / "isolab" / "numba" / engine_source_hash(folder)


def _choose_kernel_cache() -> Path:
    """Set ``NUMBA_CACHE_DIR`` (unless the user did) before numba is imported, so every process of this
    machine, Dask's spawned workers included (they inherit it, and would choose the same), share one
    cache."""
    chosen = os.environ.get("NUMBA_CACHE_DIR")
    if not chosen:
        chosen = str(default_kernel_cache_folder())
        os.environ["NUMBA_CACHE_DIR"] = chosen
        config = sys.modules.get("numba.core.config")
        if config is not None and not getattr(config, "CACHE_DIR", ""):  # numba imported first: tell it too
            setattr(config, "CACHE_DIR", chosen)  # noqa: B010  (numba's config has no stub for it)
    return Path(chosen)


_KERNEL_CACHE = _choose_kernel_cache()


def kernel_cache_folder() -> Path:
    """The folder numba keeps the engine's compiled kernels in: ``NUMBA_CACHE_DIR`` when the user set it,
    else :func:`default_kernel_cache_folder`. Chosen when ``isolab.engine`` is first imported."""
    return _KERNEL_CACHE


from isolab.engine.results import STATUS_NAMES, SimulationResult  # noqa: E402  (after the cache folder)
from isolab.engine.scene import GRAVITY, SceneBatch, SceneError, concat  # noqa: E402

_LAZY = {
    "simulate": "isolab.engine.simulation",
    "check_choice": "isolab.engine.simulation",
    "general_observer_called": "isolab.engine.simulation",
}
"""Names loaded on first use, by the module that holds them: ``engine.simulation`` brings numba and the
kernels' definitions (about 0.4 s), which a process that reads scenes, results or the store never needs
(``isolab serve`` among them)."""


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        import importlib

        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


try:
    __version__ = version("isolab")
    """isolab's version: pyproject.toml's, as installed (the one place it is written)."""
except PackageNotFoundError:  # pragma: no cover - the source tree used without installing it
    __version__ = "0+unknown"

__all__ = [
    "GRAVITY",
    "STATUS_NAMES",
    "SceneBatch",
    "SceneError",
    "SimulationResult",
    "check_choice",
    "concat",
    "default_kernel_cache_folder",
    "engine_source_hash",
    "general_observer_called",
    "kernel_cache_folder",
    "simulate",
    "__version__",
]
