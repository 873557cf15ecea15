"""Suite-wide set-up."""

from __future__ import annotations

import anyio

# anyio imports its submodules on first use. The live-service tests run the app in threads; such an import
# there, while pytest's assertion rewriting parses a module on the main thread, trips a CPython 3.11 race
# in ast.parse ("SystemError: AST constructor recursion depth mismatch") and the request fails. Import
# them all before any thread starts.
for _name in dir(anyio):
    if not _name.startswith("_"):
        getattr(anyio, _name)
