"""Classical fourth-order Runge-Kutta at a fixed step.

The driver (``engine.integrators.stepping``) splits a step that contains breakpoints of the stage profiles
into sub-steps, each on one polynomial piece: the forcing is smooth inside every sub-step, so the method
keeps fourth order, and a jerk phase shorter than the step is integrated over the time it lasts instead of
being sampled. Stable for an undamped mode while ``w dt < 2 sqrt(2)`` (the sub-steps are shorter, so no
less stable).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from isolab.engine.dynamics import NONLINEAR, derivative

NAME = "rk4"
LEVELS = ("lti", "ltv", "nonlinear")
ORDER = 4
EXACT = False
GUARDED = True
"""An explicit fixed-step method: the stability guard sizes its step."""
SCRATCH_ROWS = 5
"""State-sized rows of scratch a step needs: the stage state and the four slopes."""


@njit(cache=True)
def step(P, c, level, t, h, x, S, idx, W):
    """One RK4 step of ``h`` s from ``t`` (s) on the pieces ``idx``, ``x`` in place; ``S`` (5, nx)
    scratch. Returns False when a mass matrix is singular."""
    nx = x.shape[0]
    xs, k1, k2, k3, k4 = S[0], S[1], S[2], S[3], S[4]
    ok = derivative(P, c, level, t, x, idx, W, k1)
    for i in range(nx):
        xs[i] = x[i] + 0.5 * h * k1[i]
    ok &= derivative(P, c, level, t + 0.5 * h, xs, idx, W, k2)
    for i in range(nx):
        xs[i] = x[i] + 0.5 * h * k2[i]
    ok &= derivative(P, c, level, t + 0.5 * h, xs, idx, W, k3)
    for i in range(nx):
        xs[i] = x[i] + h * k3[i]
    ok &= derivative(P, c, level, t + h, xs, idx, W, k4)
    if not ok:
        return False
    for i in range(nx):
        x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
    if level == NONLINEAR:
        n = np.sqrt(x[3] ** 2 + x[4] ** 2 + x[5] ** 2 + x[6] ** 2)
        for i in range(3, 7):
            x[i] /= n
    return True


def step_matrix(A: np.ndarray, h: np.ndarray) -> np.ndarray:
    """One-step map (C, n, n) of classical RK4 on ``x' = A x``; ``A`` (C, n, n) 1/s, steps ``h`` (C,) s:
    the degree-4 Taylor polynomial of ``expm(A h)``."""
    h = np.asarray(h, dtype=float)[:, None, None]
    Z = h * A
    Z2 = Z @ Z
    return np.eye(A.shape[-1]) + Z + Z2 / 2 + Z2 @ Z / 6 + Z2 @ Z2 / 24
