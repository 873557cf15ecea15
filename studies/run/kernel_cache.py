"""Whether the engine's compiled kernels are on disk already, so a command can say when the first run of a
process compiles them (numba, about 10 s, once per machine and engine version).

Numba keeps each ``cache=True`` kernel under ``NUMBA_CACHE_DIR`` (else beside its source, in
``__pycache__``): an index file per kernel lists the compiled signatures, each keyed by the machine's target
and a hash of the kernel's bytecode, and counts only while the source file is unchanged. A kernel is cached
when its index holds an entry for this machine and this bytecode. Only the entry kernels an integrator
calls from Python are read (what they call is compiled, and cached, with them): one small file each.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

STEPPED = ("euler", "rk4", "exact")
"""Integrators whose cases run through one cached driver loop each (``engine.integrators.stepping``)."""


def entry_kernels(integrator: str | None) -> list[Any]:
    """The numba dispatchers a run with ``integrator`` calls from Python; every integrator's for None (a
    model still to be chosen)."""
    from isolab.engine.integrators.stepping import ENTRIES as _ENTRIES
    from isolab.engine.kernels.dynamics import derivative
    from isolab.engine.kernels.peaks import observe

    if integrator in STEPPED:
        return [_ENTRIES[integrator]]
    if integrator == "reference":  # scipy's solve_ivp calls the right-hand side and the observer
        return [derivative, observe]
    return [_ENTRIES[name] for name in STEPPED] + [derivative, observe]


def kernels_cached(integrators: Sequence[str | None] = (None,), kernels: Sequence[Any] | None = None) -> bool:
    """True when every entry kernel of ``integrators`` (or the given numba ``kernels``) has a compiled
    version on disk for this machine and its current code, so nothing is compiled on first use. Reads one
    small index file per kernel. When numba's cache cannot be inspected, answers True (nothing is said)."""
    if kernels is None:
        kernels = [k for name in integrators for k in entry_kernels(name)]
    for kernel in kernels:
        try:
            cache = kernel._cache
            index = cache._cache_file._load_index()
            _, target, code = cache._index_key(None, kernel.targetctx.codegen())
        except Exception:  # a numba without these internals, or an unreadable index: cannot tell
            continue
        if not any(key[1] == target and key[2] == code for key in index):
            return False
    return True
