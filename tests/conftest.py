"""Suite-wide set-up."""

from __future__ import annotations

import os
import re
from pathlib import Path

# One BLAS and OpenMP thread per test process (set before numpy loads; the services and subprocesses the
# tests start inherit it). The suite runs in 2 processes on 2 cores: with the libraries' default of one
# thread per core, their spinning threads contend, and a test of a few matrix products (a kernel density
# per rank class of the delta estimator) took 40 s beside another process instead of 2 s.
for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import anyio  # noqa: E402
import pytest  # noqa: E402

# The suite starts dozens of short-lived services: warming each one's workers would cost every start a few
# seconds of CPU (and, on an empty kernel cache, compile pairs no test of that service runs). The tests of
# the warm-up, and the browser tests, turn it on for their own services.
os.environ["ISOLAB_KERNEL_WARMUP"] = "off"

# anyio imports its submodules on first use. The live-service tests run the app in threads; such an import
# there, while pytest's assertion rewriting parses a module on the main thread, trips a CPython 3.11 race
# in ast.parse ("SystemError: AST constructor recursion depth mismatch") and the request fails. Import
# them all before any thread starts.
for _name in dir(anyio):
    if not _name.startswith("_"):
        getattr(anyio, _name)


# On an empty kernel cache (a fresh clone, or any engine edit), each test process, and each service's Dask
# workers that a test starts, compiled the kernels of every pair it met first: the two test processes
# started on the same pairs at once and compiled them twice, and services started meanwhile a third and
# fourth time. The controller of a parallel run compiles each pair once before the test processes start,
# one pair per child process, as many at a time as the machine has cores: compiling is CPU-bound, and three
# compiles on 2 cores took 146 s (279 s of CPU) where two at a time took 119 s (224 s of CPU), on an empty
# cache one after the other (`ISOLAB_TEST_PREWARM=off` skips it).
PREWARM_ORDER = (
    ("nonlinear", "rk4"),
    ("lti", "exact"),
    ("nonlinear", "euler"),
    ("ltv", "rk4"),
    ("lti", "rk4"),
    ("lti", "euler"),
    ("ltv", "euler"),
    ("nonlinear", "reference"),
)
"""Every (fidelity, integrator) pair the suite runs, the longest to compile first (so the processes finish
together). CPU of each on an empty cache, one after the other in one process, the first with the kernels
every pair shares (2026-11-28, each linear pair with its two drivers, ``engine.integrators.stepping``):
nonlinear/rk4 50 s, lti/exact 45 s, nonlinear/euler 40 s, ltv/rk4 24 s, lti/rk4 20 s, lti/euler 18 s,
ltv/euler 18 s, the reference 8 s (its right-hand side and samples' observers; the general observer it
calls comes with the linear pairs)."""


def pytest_configure(config: pytest.Config) -> None:
    """Compile the engine's kernels once, in parallel, before the test processes of a parallel run start."""
    import subprocess
    import sys
    import time
    from concurrent.futures import ThreadPoolExecutor

    if hasattr(config, "workerinput") or os.environ.get("ISOLAB_TEST_PREWARM") == "off":
        return  # a test process, or turned off
    processes = getattr(config.option, "numprocesses", None)
    if not isinstance(processes, int) or processes < 2:
        return
    from isolab.studies.run.kernel_cache import kernels_cached

    pairs = [pair for pair in PREWARM_ORDER if not kernels_cached([pair[1]], fidelity=pair[0])]
    if not pairs:
        return
    script = "import sys\nfrom isolab.studies.run import kernel_cache as k\nk.warm_kernels([sys.argv[1:]])"
    at_once = max(1, min(processes, len(os.sched_getaffinity(0))))
    started = time.perf_counter()
    print(f"\nisolab: compiling the kernels of {len(pairs)} pairs, {at_once} at a time ...", flush=True)

    def compile_pair(pair: tuple[str, str]) -> int:
        return subprocess.run([sys.executable, "-c", script, *pair], check=False).returncode

    with ThreadPoolExecutor(max_workers=at_once) as pool:
        codes = list(pool.map(compile_pair, pairs))
    failed = [f"{f}/{i}" for (f, i), code in zip(pairs, codes, strict=True) if code]
    print(
        f"isolab: kernels compiled in {time.perf_counter() - started:.0f} s"
        + (f" (failed, left to the tests: {', '.join(failed)})" if failed else ""),
        flush=True,
    )


SLOW_MODULE = re.compile(r"^pytestmark = (pytest\.mark\.slow\b|\[\s*pytest\.mark\.slow\b)", re.MULTILINE)
"""A test module whose every test is slow: its module-level ``pytestmark`` is (or starts with) the mark."""


def pytest_ignore_collect(collection_path: Path, config: pytest.Config) -> bool | None:
    """Under ``-m "not slow"`` (``make test-fast``) a module whose every test is slow (:data:`SLOW_MODULE`)
    is not imported: each test process imported and collected 18 of them only to deselect every test (4-5 s,
    the fuzz tests' ~130 cases built from the app's schema among them)."""
    if (config.option.markexpr or "").strip() != "not slow":
        return None
    if collection_path.suffix != ".py" or not collection_path.name.startswith("test_"):
        return None
    return True if SLOW_MODULE.search(collection_path.read_text(encoding="utf-8")) else None


FIRST_MODULES = ("tests/reliability/test_faults.py",)
"""The longest module (real kills, restarts and two starts of ``isolab serve``: about 2 minutes in one test
process, mostly waiting on its services), scheduled first."""


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Schedule the long modules first: a parallel run hands whole modules (``--dist loadfile``) to the test
    processes in the order collected, so a long module handed out last kept one process busy alone at the
    end. :data:`FIRST_MODULES`, then every module with a test marked slow (services in subprocesses, the
    browser, fault injection), then the others, each group in the order collected."""
    slow = {item.path for item in items if item.get_closest_marker("slow") is not None}
    root = config.rootpath

    def group(item: pytest.Item) -> int:
        if item.path.relative_to(root).as_posix() in FIRST_MODULES:
            return 0
        return 1 if item.path in slow else 2

    items.sort(key=group)  # stable: each module's tests stay together and in order


def pytest_sessionfinish(session: pytest.Session) -> None:
    """Close the clusters this test process shared between its test modules (tests/shared_cluster.py)."""
    import sys

    shared = sys.modules.get("tests.shared_cluster")
    if shared is not None:
        shared.close_shared_clusters()
