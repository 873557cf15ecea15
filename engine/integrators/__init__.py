"""Time integrators, one module each, behind one small interface.

Each method module declares its own facts (``NAME``, ``LEVELS`` it integrates, convergence ``ORDER`` or
None, ``EXACT``, ``GUARDED`` when the stability guard must size its step) and supplies its step; the
stepped methods (``euler``, ``rk4``, ``exact``) share one driver loop (``stepping.drive``), the adaptive
``reference`` runs scipy's ``solve_ivp``. :data:`INTEGRATORS` holds an :class:`Integrator` per method:
``run(P, level, dt, n_steps, peaks, work, status, messages=None)`` integrates every case ``c`` over
``n_steps[c]`` steps of ``dt[c]`` s, updates the running peaks and sets ``status[c]`` (``OK``,
``UNSTABLE`` or ``FAILED`` of ``engine.results``) instead of raising.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from types import ModuleType

import numpy as np

from isolab.engine.integrators import euler, exact, reference, rk4, stepping


@dataclass(frozen=True)
class Integrator:
    """What an integration method is and declares about itself."""

    name: str
    levels: tuple[str, ...]
    """Fidelity levels it integrates."""
    order: int | None
    """Convergence order in the step; None for exact or adaptive methods."""
    exact: bool
    """No step-size error on the levels it integrates."""
    guarded: bool
    """An explicit fixed-step method: the stability guard divides its step where needed."""
    step_matrix: Callable[[np.ndarray, np.ndarray], np.ndarray] | None
    """One-step map ``S(A (C, n, n) 1/s, h (C,) s)`` on ``x' = A x`` (guarded methods)."""
    run: Callable[..., None]


def _integrator(module: ModuleType, run: Callable[..., None]) -> Integrator:
    return Integrator(
        name=module.NAME,
        levels=module.LEVELS,
        order=module.ORDER,
        exact=module.EXACT,
        guarded=module.GUARDED,
        step_matrix=getattr(module, "step_matrix", None),
        run=run,
    )


INTEGRATORS: dict[str, Integrator] = {
    m.NAME: _integrator(m, functools.partial(stepping.run, m.NAME)) for m in (euler, rk4, exact)
}
INTEGRATORS["reference"] = _integrator(reference, reference.run)
