"""Classical fourth-order Runge-Kutta at a fixed step.

A step that contains breakpoints of the stage profiles is split there into sub-steps, each on one
polynomial piece: the forcing is smooth inside every sub-step, so the method keeps fourth order, and a jerk
phase shorter than the step is integrated over the time it lasts instead of being sampled. Stable for an
undamped mode while ``w dt < 2 sqrt(2)`` (the sub-steps are shorter, so no less stable).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from isolab.engine.dynamics import NONLINEAR, advance_pieces, derivative, kernel_struct, next_breakpoint
from isolab.engine.peaks import observe

ORDER = 4
LEVELS = ("lti", "ltv", "nonlinear")


@njit(cache=True)
def _step(P, c, level, t, h, x, xs, k1, k2, k3, k4, idx, W):
    """One RK4 step of ``h`` s from ``t`` on the pieces ``idx``; False when a mass matrix is singular."""
    nx = x.shape[0]
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


@njit(cache=True, nogil=True)
def _run(P, level, dt, n_steps, O, W, status):
    """Integrate every case ``c`` over ``n_steps[c]`` steps of ``dt[c]`` s; set ``status[c]``
    (0 done, 1 diverged, 3 singular mass matrix)."""
    C = dt.shape[0]
    m = P.sm.shape[1]
    nx = 13 if level == NONLINEAR else 12
    x = np.zeros(nx)
    xs = np.zeros(nx)
    k1 = np.zeros(nx)
    k2 = np.zeros(nx)
    k3 = np.zeros(nx)
    k4 = np.zeros(nx)
    idx = np.zeros(m, dtype=np.int64)
    for c in range(C):
        if status[c] != 0:
            continue
        x[:] = 0.0
        if level == NONLINEAR:
            x[3] = 1.0
        idx[:] = -1
        h = dt[c]
        tol = 1e-6 * h
        observe(P, c, level, 0.0, x, W, O, 0)
        for k in range(n_steps[c]):
            t_end = (k + 1) * h
            ta = k * h
            advance_pieces(P, c, ta, idx, tol)
            ok = True
            while True:
                tb = next_breakpoint(P, c, idx, t_end, tol)
                ok = _step(P, c, level, ta, tb - ta, x, xs, k1, k2, k3, k4, idx, W)
                if not ok or tb == t_end:
                    break
                ta = tb
                advance_pieces(P, c, ta, idx, tol)
            if not ok:
                status[c] = 3
                break
            if not observe(P, c, level, (k + 1) * h, x, W, O, k + 1):
                status[c] = 1
                break


def run(P, level, dt, n_steps, O, W, status):
    """Integrate every case ``c`` over ``n_steps[c]`` steps of ``dt[c]`` s; set ``status[c]``
    (0 done, 1 diverged, 3 singular mass matrix)."""
    _run(kernel_struct(P), level, dt, n_steps, kernel_struct(O), kernel_struct(W), status)
