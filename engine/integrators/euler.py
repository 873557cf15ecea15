"""Semi-implicit (symplectic) Euler at a fixed step: the source article's scheme.

Velocities are updated with the accelerations of the old state, positions with the new velocities. First
order; for an undamped mode stable while ``w dt < 2``, and with damping ratio ``zeta`` while
``w dt < 2 (sqrt(1 + zeta^2) - zeta)`` (see ``engine.stability``). The driver (``engine.integrators.
stepping``) splits a step that contains breakpoints of the stage profiles, so each sub-step starts on the
piece it spans (a jerk phase shorter than a step is not skipped).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from isolab.engine.kernels.dynamics import accel
from isolab.engine.kernels.params import NONLINEAR
from isolab.engine.kernels.rotations import quat_step

NAME = "euler"
LEVELS = ("lti", "ltv", "nonlinear")
ORDER = 1
EXACT = False
GUARDED = True
"""An explicit fixed-step method: the stability guard sizes its step."""


@njit(cache=True, fastmath=False)
def step(P, c, level, t, h, x, idx, W):
    """One semi-implicit Euler step of ``h`` s from ``t`` (s) on the pieces ``idx``, ``x`` in place.

    Returns False when a mass matrix is singular."""
    if not accel(P, c, level, t, x, idx, W):
        return False
    off = 7 if level == NONLINEAR else 6
    for i in range(6):
        x[off + i] += h * W.acc[i]
    for i in range(3):
        x[i] += h * x[off + i]
    if level == NONLINEAR:
        quat_step(x[3:7], x[off + 3], x[off + 4], x[off + 5], h)
    else:
        for i in range(3):
            x[3 + i] += h * x[off + 3 + i]
    return True


def step_matrix(A: np.ndarray, h: np.ndarray) -> np.ndarray:
    """One-step map (C, n, n) of semi-implicit Euler on ``x' = A x``, ``x = [q, v]``; ``A`` (C, n, n) 1/s,
    steps ``h`` (C,) s: ``v+ = v + h (A21 q + A22 v)``, ``q+ = q + h v+``."""
    h = np.asarray(h, dtype=float)[:, None, None]
    n = A.shape[-1]
    half = n // 2
    A21, A22 = A[:, half:, :half], A[:, half:, half:]
    Ih = np.eye(half)
    S = np.empty_like(A)
    S[:, :half, :half] = Ih + h * h * A21
    S[:, :half, half:] = h * (Ih + h * A22)
    S[:, half:, :half] = h * A21
    S[:, half:, half:] = Ih + h * A22
    return S
