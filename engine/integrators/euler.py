"""Semi-implicit (symplectic) Euler at a fixed step: the source article's scheme.

Velocities are updated with the accelerations of the old state, positions with the new velocities. First
order; for an undamped mode stable while ``w dt < 2``, and with damping ratio ``zeta`` while
``w dt < 2 (sqrt(1 + zeta^2) - zeta)`` (see ``engine.stability``). A step that contains breakpoints of
the stage profiles is split there, so each sub-step starts on the piece it spans (a jerk phase shorter
than a step is not skipped).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from isolab.engine.dynamics import NONLINEAR, accel, advance_pieces, kernel_struct, next_breakpoint, quat_step
from isolab.engine.peaks import observe

ORDER = 1
LEVELS = ("lti", "ltv", "nonlinear")


@njit(cache=True)
def _step(P, c, level, t, h, x, idx, W, off):
    """One semi-implicit Euler step of ``h`` s from ``t`` on the pieces ``idx``; False when a mass matrix
    is singular."""
    if not accel(P, c, level, t, x, idx, W):
        return False
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


@njit(cache=True, nogil=True)
def _run(P, level, dt, n_steps, O, W, status):
    """Integrate every case ``c`` over ``n_steps[c]`` steps of ``dt[c]`` s; set ``status[c]``
    (0 done, 1 diverged, 3 singular mass matrix)."""
    C = dt.shape[0]
    m = P.sm.shape[1]
    nx = 13 if level == NONLINEAR else 12
    off = 7 if level == NONLINEAR else 6
    x = np.zeros(nx)
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
                ok = _step(P, c, level, ta, tb - ta, x, idx, W, off)
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
