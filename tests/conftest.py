"""Suite-wide set-up."""

from __future__ import annotations

import os

import anyio

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
