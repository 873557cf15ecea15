"""Suite-wide set-up."""

from __future__ import annotations

import os

# One BLAS and OpenMP thread per test process (set before numpy loads; the services and subprocesses the
# tests start inherit it). The suite runs in 2 processes on 2 cores: with the libraries' default of one
# thread per core, their spinning threads contend, and a test of a few matrix products (a kernel density
# per rank class of the delta estimator) took 40 s beside another process instead of 2 s.
for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import anyio  # noqa: E402

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
