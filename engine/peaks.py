"""Running peaks, minima, RMS and settling of one case, updated at every output time.

No time history is kept unless a case is recorded: the integrators call ``observe`` after each step.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit
from numba.experimental import structref

from isolab.engine.dynamics import (
    NONLINEAR,
    KernelPeaks,
    PeaksType,
    floor_motion,
    isolator_forces,
    quat_to_matrix,
    quat_to_rotvec,
)

Peaks = namedtuple(
    "Peaks",
    [
        "u",
        "th",
        "poi",
        "force",
        "min_load",
        "sumsq",
        "nobs",
        "last_viol",
        "target",
        "t_last",
        "tol",
        "diverged",
        "slot",
        "h_u",
        "h_th",
        "h_poi",
        "h_force",
        "h_t",
    ],
)
structref.define_proxy(KernelPeaks, PeaksType, list(Peaks._fields))

DIVERGED_DISPLACEMENT = 1.0
"""A c.g. or point displacement beyond this (m) can only come from a diverging integration."""
DIVERGED_ROTATION = 0.5
"""A rotation beyond this (rad) likewise."""


def allocate(
    n_cases: int,
    n_points: int,
    n_isolators: int,
    target: np.ndarray,
    t_last: np.ndarray,
    tol: np.ndarray,
    record: list[int] | None,
    n_steps: int,
) -> Peaks:
    """Accumulators for ``n_cases`` cases; histories of ``n_steps + 1`` samples for the ``record`` cases.

    ``target`` (C, 6) is the final static displacement and rotation the case settles to, m and rad;
    ``t_last`` (C,) the end of the last stage move, s; ``tol`` (C,) the settling tolerance, m.
    """
    slot = np.full(n_cases, -1, dtype=np.int64)
    record = list(record or [])
    for i, c in enumerate(record):
        slot[c] = i
    R = len(record)
    T = n_steps + 1 if R else 0
    return Peaks(
        u=np.zeros((n_cases, 3)),
        th=np.zeros((n_cases, 3)),
        poi=np.zeros((n_cases, n_points, 3)),
        force=np.zeros((n_cases, n_isolators, 3)),
        min_load=np.full((n_cases, n_isolators), np.inf),
        sumsq=np.zeros((n_cases, 3)),
        nobs=np.zeros(n_cases),
        last_viol=np.full(n_cases, -np.inf),
        target=np.ascontiguousarray(target, dtype=float),
        t_last=np.ascontiguousarray(t_last, dtype=float),
        tol=np.ascontiguousarray(tol, dtype=float),
        diverged=np.full(n_cases, np.nan),
        slot=slot,
        h_u=np.zeros((R, T, 3)),
        h_th=np.zeros((R, T, 3)),
        h_poi=np.zeros((R, T, n_points, 3)),
        h_force=np.zeros((R, T, n_isolators, 3)),
        h_t=np.zeros((R, T)),
    )


@njit(cache=True)
def observe(P, c, level, t, x, W, O, step):
    """Update case ``c``'s peaks with the state ``x`` at time ``t`` (s), output sample ``step``.

    Returns False (and stores ``t`` in ``O.diverged``) when the state is not finite or has left any
    physically possible range.
    """
    if level == NONLINEAR:
        quat_to_matrix(x[3:7], W.R)
        quat_to_rotvec(x[3:7], W.acc)
    else:
        W.acc[0], W.acc[1], W.acc[2] = x[3], x[4], x[5]
    u0, u1, u2 = x[0], x[1], x[2]
    ok = True
    for i in range(3):
        if not (abs(x[i]) < DIVERGED_DISPLACEMENT and abs(W.acc[i]) < DIVERGED_ROTATION):
            ok = False
    if not ok:
        O.diverged[c] = t
        return False
    slot = O.slot[c]
    settle = t >= O.t_last[c] - 1e-12
    err = 0.0
    for i in range(3):
        a = abs(x[i])
        if a > O.u[c, i]:
            O.u[c, i] = a
        a = abs(W.acc[i])
        if a > O.th[c, i]:
            O.th[c, i] = a
        O.sumsq[c, i] += x[i] * x[i]
        if settle:
            e = abs(x[i] - O.target[c, i])
            if e > err:
                err = e
    O.nobs[c] += 1.0
    if slot >= 0:
        O.h_t[slot, step] = t
        for i in range(3):
            O.h_u[slot, step, i] = x[i]
            O.h_th[slot, step, i] = W.acc[i]
    # points of interest: u + (R - I) d  (linear: u + theta x d)
    for p in range(P.pts.shape[1]):
        d0, d1, d2 = P.pts[c, p, 0], P.pts[c, p, 1], P.pts[c, p, 2]
        if level == NONLINEAR:
            r0 = W.R[0, 0] * d0 + W.R[0, 1] * d1 + W.R[0, 2] * d2 - d0
            r1 = W.R[1, 0] * d0 + W.R[1, 1] * d1 + W.R[1, 2] * d2 - d1
            r2 = W.R[2, 0] * d0 + W.R[2, 1] * d1 + W.R[2, 2] * d2 - d2
        else:
            r0 = W.acc[1] * d2 - W.acc[2] * d1
            r1 = W.acc[2] * d0 - W.acc[0] * d2
            r2 = W.acc[0] * d1 - W.acc[1] * d0
        pv0, pv1, pv2 = u0 + r0, u1 + r1, u2 + r2
        if abs(pv0) > O.poi[c, p, 0]:
            O.poi[c, p, 0] = abs(pv0)
        if abs(pv1) > O.poi[c, p, 1]:
            O.poi[c, p, 1] = abs(pv1)
        if abs(pv2) > O.poi[c, p, 2]:
            O.poi[c, p, 2] = abs(pv2)
        if settle:
            # target point displacement from the linearised static offset
            e0 = O.target[c, 4] * d2 - O.target[c, 5] * d1 + O.target[c, 0]
            e1 = O.target[c, 5] * d0 - O.target[c, 3] * d2 + O.target[c, 1]
            e2 = O.target[c, 3] * d1 - O.target[c, 4] * d0 + O.target[c, 2]
            e = max(abs(pv0 - e0), abs(pv1 - e1), abs(pv2 - e2))
            if e > err:
                err = e
        if slot >= 0:
            O.h_poi[slot, step, p, 0] = pv0
            O.h_poi[slot, step, p, 1] = pv1
            O.h_poi[slot, step, p, 2] = pv2
    if settle and err > O.tol[c]:
        O.last_viol[c] = t
    floor_motion(P, c, t, W.xf, W.vf)
    isolator_forces(P, c, level, x, W.R, W.xf, W.vf, W.F)
    for j in range(P.d.shape[1]):
        for i in range(3):
            a = abs(W.F[j, i])
            if a > O.force[c, j, i]:
                O.force[c, j, i] = a
            if slot >= 0:
                O.h_force[slot, step, j, i] = W.F[j, i]
        load = P.f0[c, j] + W.F[j, 2]
        if load < O.min_load[c, j]:
            O.min_load[c, j] = load
    return True
