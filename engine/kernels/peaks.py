"""Running peaks, minima, RMS and settling of one case, updated at every output time.

No time history is kept unless a case is recorded: the integrators call ``observe`` after each step.

Peaks (and the smallest and largest loads) are taken at their extremum between output times too: each
peaked quantity follows the cubic Hermite interpolant of its values and time derivatives at the two output
times (``last_*`` keep the previous ones), whose interior extremum has a closed form; the solve runs only
where the cubic's Bernstein control points reach beyond the running peak (``engine.kernels.between_steps``).

Settling of the points of interest after each stage move: the rest intervals of a case (every stage at
rest, from a move's end ``t_k`` to the next move's start ``s_k`` or the run's end) and the static
displacement the base settles to in each come precomputed (``rest``, ``rest_n``, ``rest_target``); as time
only increases, ``observe`` keeps a cursor ``rest_k`` on the interval it is in, records per point the last
output time outside ``point_tol`` of that interval's static position (``p_viol``), and on leaving the
interval folds ``p_viol - t_k`` (the interval's length if the point was still outside at its last output
time, ``rest_tprev``; 0 if never outside) into the running worst ``p_settle``. :func:`finish_settling`
closes the interval a run ends in.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit

from isolab.engine.kernels.between_steps import (
    ONE_THIRD,
    cubic_beyond,
    cubic_extremes,
    hermite,
    interval_peak,
    peak_point,
)
from isolab.engine.kernels.excitation import floor_motion, recorded_floor
from isolab.engine.kernels.mounts import diagonal_force, isolator_forces, mount_force, mount_offset
from isolab.engine.kernels.params import LTI, NONLINEAR, borrowed
from isolab.engine.kernels.rotations import cross, quat_matrix

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
        "defl",
        "max_load",
        "rest",
        "rest_n",
        "rest_target",
        "point_tol",
        "rest_k",
        "rest_tprev",
        "p_viol",
        "p_settle",
        "last_t",
        "h_interp",
        "last_u",
        "last_th",
        "last_poi",
        "last_defl",
        "last_floor",
        "last_force",
        "point_offset",
        "rest_point_offset",
    ],
)

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
    rest: np.ndarray | None = None,
    rest_n: np.ndarray | None = None,
    rest_target: np.ndarray | None = None,
    point_tol: np.ndarray | None = None,
    h_interp: np.ndarray | None = None,
    point_offset: np.ndarray | None = None,
    rest_point_offset: np.ndarray | None = None,
) -> Peaks:
    """Accumulators for ``n_cases`` cases; histories of ``n_steps + 1`` samples for the ``record`` cases.

    ``target`` (C, 6) is the final static displacement and rotation the case settles to, m and rad;
    ``t_last`` (C,) the end of the last stage move, s; ``tol`` (C,) the settling tolerance, m.
    ``rest`` (C, K, 2) the rest intervals after each stage move (start, end; s), ``rest_n`` (C,) their
    number per case and ``rest_target`` (C, K, 6) the static displacement and rotation in each (m, rad),
    as ``engine.model.rest_offsets`` gives them (default: none); ``point_tol`` (C, p) the settling
    tolerance of each point of interest, m (default: ``tol``); ``h_interp`` (C,) the longest interval
    between output times over which a peak is interpolated, s (default: every interval).
    ``point_offset`` (C, p, 3) and ``rest_point_offset`` (C, K, p, 3), m, are what a point's static
    displacement adds to the linearised ``u + theta x d`` of ``target`` and ``rest_target`` (the nonlinear
    level's ``(R - I) d - theta x d``; default zero).
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
        defl=np.zeros((n_cases, n_isolators, 3)),
        max_load=np.full((n_cases, n_isolators), -np.inf),
        rest=np.ascontiguousarray(np.full((n_cases, 1, 2), np.nan) if rest is None else rest, dtype=float),
        rest_n=np.ascontiguousarray(np.zeros(n_cases) if rest_n is None else rest_n, dtype=np.int64),
        rest_target=np.ascontiguousarray(
            np.zeros((n_cases, 1, 6)) if rest_target is None else rest_target, dtype=float
        ),
        point_tol=np.ascontiguousarray(
            np.repeat(np.asarray(tol, dtype=float).reshape(-1, 1), n_points, axis=1)
            if point_tol is None
            else point_tol,
            dtype=float,
        ),
        rest_k=np.zeros(n_cases, dtype=np.int64),
        rest_tprev=np.full(n_cases, -np.inf),
        p_viol=np.full((n_cases, n_points), -np.inf),
        p_settle=np.zeros((n_cases, n_points)),
        last_t=np.zeros(n_cases),
        h_interp=np.full(n_cases, np.inf)
        if h_interp is None
        else np.ascontiguousarray(h_interp, dtype=float),
        last_u=np.zeros((n_cases, 3, 2)),
        last_th=np.zeros((n_cases, 3, 2)),
        last_poi=np.zeros((n_cases, n_points, 3, 2)),
        last_defl=np.zeros((n_cases, n_isolators, 3, 2)),
        last_floor=np.zeros((n_cases, 3, 2)),
        last_force=np.zeros((n_cases, n_isolators, 3)),
        point_offset=np.ascontiguousarray(
            np.zeros((n_cases, n_points, 3)) if point_offset is None else point_offset, dtype=float
        ),
        rest_point_offset=np.ascontiguousarray(
            np.zeros((n_cases, 1 if rest_target is None else np.shape(rest_target)[1], n_points, 3))
            if rest_point_offset is None
            else rest_point_offset,
            dtype=float,
        ),
    )


def finish_settling(O: Peaks, t_end: np.ndarray) -> np.ndarray:
    """Per case and point, the settling time after each stage move, worst over the moves (C, p), s.

    Folds the rest interval each run ended in (run end ``t_end`` (C,), s; the run's end closes it) into
    what ``observe`` gathered over the intervals it left. Intervals the run never reached count 0.
    """
    out = np.array(O.p_settle, dtype=float)
    k = np.asarray(O.rest_k)
    cases = np.flatnonzero(k < O.rest_n)
    if cases.size == 0:
        return out
    kk = k[cases]
    t0 = O.rest[cases, kk, 0]
    t1 = np.minimum(O.rest[cases, kk, 1], np.asarray(t_end, dtype=float)[cases])
    viol = O.p_viol[cases]  # (c, p)
    outside = viol == O.rest_tprev[cases, None]
    value = np.where(outside, (t1 - t0)[:, None], viol - t0[:, None])
    value = np.where(np.isfinite(viol), np.maximum(value, 0.0), 0.0)
    out[cases] = np.maximum(out[cases], value)
    return out


@njit(cache=True, fastmath=False)
def observe(P, c, t, x, W, O, step):
    """Update case ``c``'s peaks with the state ``x`` (12 + nz,) of a linear level at time ``t`` (s), output
    sample ``step``: the general observer of a case under floor motion, recorded, or with mounts on their
    own axes (others: ``engine.integrators.output_map``; the nonlinear level: :func:`observe_nonlinear`).
    One compiled body serves both linear levels (alike here: no level argument) and the reference.

    Returns False (and stores ``t`` in ``O.diverged``) when the state is not finite or has left any
    physically possible range.
    """
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
    # the rest interval after a stage move that t falls in (time only increases: a cursor moves on)
    k = O.rest_k[c]
    nk = O.rest_n[c]
    while k < nk and t > O.rest[c, k, 1] + 1e-12:
        t0 = O.rest[c, k, 0]
        for p in range(O.p_viol.shape[1]):
            v = O.p_viol[c, p]
            if v > -np.inf:
                if v == O.rest_tprev[c]:
                    v = O.rest[c, k, 1]  # still outside at the interval's last output: its length
                if v - t0 > O.p_settle[c, p]:
                    O.p_settle[c, p] = v - t0
                O.p_viol[c, p] = -np.inf
        k += 1
        O.rest_k[c] = k
    rest = k < nk and t >= O.rest[c, k, 0] - 1e-12
    if rest:
        O.rest_tprev[c] = t
    # between the previous output time and this one, each peaked quantity follows the cubic Hermite
    # interpolant of its values and time derivatives at both ends: its interior extremum is a peak too
    h = t - O.last_t[c]
    # (only over intervals the cubic can follow: at most 1/omega of the fastest mode, ``O.h_interp``; over
    # longer ones it would overshoot, and the output samples alone are the honest peak)
    between = step > 0 and h > 0.0 and h <= O.h_interp[c]
    inv_h = 1.0 / h if between else 0.0
    orient = P.orient  # a mount with its own axes: its force peaks at the output times (no per-axis cubic)
    off = 6  # the velocities
    nz = x.shape[0] - 12  # the extra linear states
    wf0, wf1, wf2 = x[off + 3], x[off + 4], x[off + 5]
    err = 0.0
    for i in range(3):
        a = max(abs(x[i]), O.u[c, i])
        if between:
            a = max(a, interval_peak(O.last_u[c, i, 0], O.last_u[c, i, 1], x[i], x[off + i], h, a))
        if a > O.u[c, i]:
            O.u[c, i] = a
        O.last_u[c, i, 0] = x[i]
        O.last_u[c, i, 1] = x[off + i]
        wi = wf0 if i == 0 else (wf1 if i == 1 else wf2)
        a = max(abs(W.acc[i]), O.th[c, i])
        if between:
            a = max(a, interval_peak(O.last_th[c, i, 0], O.last_th[c, i, 1], W.acc[i], wi, h, a))
        if a > O.th[c, i]:
            O.th[c, i] = a
        O.last_th[c, i, 0] = W.acc[i]
        O.last_th[c, i, 1] = wi
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
    v0, v1, v2 = x[off], x[off + 1], x[off + 2]
    # points of interest: u + theta x d; rate v + w x d
    th0, th1, th2 = W.acc[0], W.acc[1], W.acc[2]
    for p in range(P.pts.shape[1]):
        d0, d1, d2 = P.pts[c, p, 0], P.pts[c, p, 1], P.pts[c, p, 2]
        r0, r1, r2 = cross(th0, th1, th2, d0, d1, d2)
        q0, q1, q2 = cross(wf0, wf1, wf2, d0, d1, d2)
        # a material point moves with the base; a relative point (or a following error) only by ``zO``
        material = P.pr[c, p] != 0.0
        b0, b1, b2 = (u0, u1, u2) if material else (0.0, 0.0, 0.0)
        s0, s1, s2 = (v0, v1, v2) if material else (0.0, 0.0, 0.0)
        pv0, pv1, pv2 = b0 + r0, b1 + r1, b2 + r2
        if nz > 0:  # the extra linear states' share (a flexible base's modes, servo errors)
            pv0, q0 = _slot_share(P.zO, c, 3 * p, x, pv0, q0)
            pv1, q1 = _slot_share(P.zO, c, 3 * p + 1, x, pv1, q1)
            pv2, q2 = _slot_share(P.zO, c, 3 * p + 2, x, pv2, q2)
        peak_point(O.poi, O.last_poi, c, p, 0, pv0, s0 + q0, h, between)
        peak_point(O.poi, O.last_poi, c, p, 1, pv1, s1 + q1, h, between)
        peak_point(O.poi, O.last_poi, c, p, 2, pv2, s2 + q2, h, between)
        if settle:
            # target point displacement from the static offset (linearised, plus the nonlinear rest)
            t0, t1, t2 = (O.target[c, 0], O.target[c, 1], O.target[c, 2]) if material else (0.0, 0.0, 0.0)
            e0 = O.target[c, 4] * d2 - O.target[c, 5] * d1 + t0 + O.point_offset[c, p, 0]
            e1 = O.target[c, 5] * d0 - O.target[c, 3] * d2 + t1 + O.point_offset[c, p, 1]
            e2 = O.target[c, 3] * d1 - O.target[c, 4] * d0 + t2 + O.point_offset[c, p, 2]
            e = max(abs(pv0 - e0), abs(pv1 - e1), abs(pv2 - e2))
            if e > err:
                err = e
        if rest:
            # the static position of the point in this rest interval
            t0, t1, t2 = (
                (O.rest_target[c, k, 0], O.rest_target[c, k, 1], O.rest_target[c, k, 2])
                if material
                else (0.0, 0.0, 0.0)
            )
            e0 = O.rest_target[c, k, 4] * d2 - O.rest_target[c, k, 5] * d1 + t0
            e1 = O.rest_target[c, k, 5] * d0 - O.rest_target[c, k, 3] * d2 + t1
            e2 = O.rest_target[c, k, 3] * d1 - O.rest_target[c, k, 4] * d0 + t2
            e0 += O.rest_point_offset[c, k, p, 0]
            e1 += O.rest_point_offset[c, k, p, 1]
            e2 += O.rest_point_offset[c, k, p, 2]
            if max(abs(pv0 - e0), abs(pv1 - e1), abs(pv2 - e2)) > O.point_tol[c, p]:
                O.p_viol[c, p] = t
        if slot >= 0:
            O.h_poi[slot, step, p, 0] = pv0
            O.h_poi[slot, step, p, 1] = pv1
            O.h_poi[slot, step, p, 2] = pv2
    if settle and err > O.tol[c]:
        O.last_viol[c] = t
    floor_motion(P, c, t, W.xf, W.vf)
    isolator_forces(P, c, LTI, x, W.R, W.xf, W.vf, W.F)  # the linear levels' mount forces: alike at both
    for j in range(P.d.shape[1]):
        d0, d1, d2 = P.d[c, j, 0], P.d[c, j, 1], P.d[c, j, 2]
        # deflection of the mount from its static state: the base's mount point minus the floor under it
        r0, r1, r2 = cross(th0, th1, th2, d0, d1, d2)
        q0, q1, q2 = cross(wf0, wf1, wf2, d0, d1, d2)
        sky = P.sky[c, j]
        load = P.f0[c, j] + W.F[j, 2]
        lo = load
        hi = load
        for i in range(3):
            if i == 0:
                dl, dd = u0 + r0, v0 + q0
            elif i == 1:
                dl, dd = u1 + r1, v1 + q1
            else:
                dl, dd = u2 + r2, v2 + q2
            dl -= W.xf[i]
            dd -= W.vf[i]
            F1 = W.F[j, i]
            if nz > 0:  # the mount point's share of the extra linear states, and its force
                r = 3 * P.pts.shape[1] + 3 * j + i
                sl, sd = _slot_share(P.zO, c, r, x, 0.0, 0.0)
                dl += sl
                dd += sd
                F1 -= P.k[c, j, i] * sl + P.cd[c, j, i] * sd
                F1 = _slot_force(P.zF, c, 3 * j + i, x, F1)  # a relaxation branch's, a valve's share
                W.F[j, i] = F1
                if i == 2:
                    lo = hi = P.f0[c, j] + F1
            a = max(abs(F1), O.force[c, j, i])
            b = max(abs(dl), O.defl[c, j, i])
            if between and not orient:
                # the deflection's and the floor's cubics; the force law -k delta - c (delta' + sky x_f')
                # on them, shifted linearly to meet the computed forces at both ends
                p0, m0 = O.last_defl[c, j, i, 0], O.last_defl[c, j, i, 1]
                c0, c1, c2, c3 = hermite(p0, m0, dl, dd, h)
                b = max(b, cubic_beyond(c0, c1, c2, c3, b))  # the deflection's hull: p0, b1, b2, dl
                f1 = f2 = f3 = 0.0
                if sky != 0.0:
                    _, f1, f2, f3 = hermite(O.last_floor[c, i, 0], O.last_floor[c, i, 1], W.xf[i], W.vf[i], h)
                kk, cc = P.k[c, j, i], P.cd[c, j, i] * inv_h
                g0 = -kk * c0 - cc * (c1 + sky * f1)
                g1 = -kk * c1 - cc * (2.0 * (c2 + sky * f2))
                g2 = -kk * c2 - cc * (3.0 * (c3 + sky * f3))
                g3 = -kk * c3
                e0 = O.last_force[c, j, i] - g0
                e1 = F1 - (g0 + g1 + g2 + g3)
                g0 += e0
                g1 += e1 - e0
                a = max(a, cubic_beyond(g0, g1, g2, g3, a))
                if i == 2:
                    # the Bernstein control points bound the cubic: solve only if a new extreme may lie inside
                    b1 = g0 + g1 * ONE_THIRD
                    b2 = b1 + (g1 + g2) * ONE_THIRD
                    f0j = P.f0[c, j]
                    if f0j + min(b1, b2) < min(lo, O.min_load[c, j]) or f0j + max(b1, b2) > max(
                        hi, O.max_load[c, j]
                    ):
                        glo, ghi = cubic_extremes(g0, g1, g2, g3)
                        lo = min(lo, f0j + glo)
                        hi = max(hi, f0j + ghi)
            if a > O.force[c, j, i]:
                O.force[c, j, i] = a
            if b > O.defl[c, j, i]:
                O.defl[c, j, i] = b
            if slot >= 0:
                O.h_force[slot, step, j, i] = F1
            O.last_defl[c, j, i, 0] = dl
            O.last_defl[c, j, i, 1] = dd
            O.last_force[c, j, i] = F1
        if lo < O.min_load[c, j]:
            O.min_load[c, j] = lo
        if hi > O.max_load[c, j]:
            O.max_load[c, j] = hi
    for i in range(3):
        O.last_floor[c, i, 0] = W.xf[i]
        O.last_floor[c, i, 1] = W.vf[i]
    O.last_t[c] = t
    return True


@njit(cache=True, fastmath={"contract"})
def observe_nonlinear(P, c, t, x, W, O, step):
    """:func:`observe` at the nonlinear level, the same arithmetic on arrays bound once as views whose
    references numba does not count (``engine.kernels.params.borrowed``; :func:`observer_views`), each
    mount's force computed in the mount loop (``engine.kernels.mounts.diagonal_force`` on the mount point's
    velocity the loop takes; ``engine.kernels.mounts.mount_force`` for a mount on its own axes), each
    multiply fused with the add that takes it (``fastmath={"contract"}``, as in the nonlinear level's RK4
    driver, which inlines :func:`observe_nonlinear_on` on views it makes once per case)."""
    return observe_nonlinear_on(P, O, c, t, step, observer_views(P, W, O, x))


@njit(cache=True, inline="always")
def observer_views(P, W, O, x):
    """The arrays :func:`observe_nonlinear_on` reads of the state ``x``, the batch ``P``, the workspace ``W``
    and the peaks ``O``, as views without owner: a view made once serves every output time of a case (each
    made anew costs its loads, and each array read from a struct an atomic add and subtract)."""
    b = borrowed
    return (
        (b(x), b(W.R), b(W.xf), b(W.vf), b(W.F)),
        (b(P.famp), b(P.fomega), b(P.fphase), P.ft.shape[0] > 0, P.orient),
        (b(P.pts), b(P.pr), b(P.d), b(P.sky), b(P.f0), b(P.k), b(P.cd), b(P.qm)),
        (b(O.u), b(O.th), b(O.poi), b(O.force), b(O.defl), b(O.min_load), b(O.max_load)),
        (b(O.last_u), b(O.last_th), b(O.last_poi), b(O.last_defl), b(O.last_floor), b(O.last_force)),
        (b(O.rest), b(O.rest_n), b(O.rest_k), b(O.rest_tprev), b(O.rest_target), b(O.p_viol), b(O.p_settle)),
        (b(O.point_tol), b(O.point_offset), b(O.rest_point_offset), b(O.target), b(O.sumsq), b(O.nobs)),
        (b(O.last_viol), b(O.last_t), b(O.slot), b(O.diverged), b(O.t_last), b(O.tol), b(O.h_interp)),
    )


@njit(cache=True, inline="always")
def observe_nonlinear_on(P, O, c, t, step, V):
    """:func:`observe_nonlinear` on the views ``V`` (:func:`observer_views`); ``P`` and ``O`` read only for a
    recorded floor and a recorded case's histories."""
    (x, R, xf, vf, F), (famp, fomega, fphase, recorded, orient), (pts, pr, D, sky, f0, kk, cd, qm) = V[:3]
    peak_u, peak_th, poi, force, defl, min_load, max_load = V[3]
    last_u, last_th, last_poi, last_defl, last_floor, last_force = V[4]
    rest, rest_n, rest_k, rest_tprev, rest_target, p_viol, p_settle = V[5]
    point_tol, point_offset, rest_point_offset, target, sumsq, nobs = V[6]
    last_viol, last_t, slots, diverged, t_last, tol, h_interp = V[7]
    for dd in range(3):  # ``floor_motion``
        amp = famp[c, dd]
        if amp == 0.0:
            xf[dd] = 0.0
            vf[dd] = 0.0
        else:
            w = fomega[c, dd]
            arg = w * t + fphase[c, dd]
            xf[dd] = amp * np.sin(arg)
            vf[dd] = amp * w * np.cos(arg)
    if recorded:
        recorded_floor(P, c, t, xf, vf)
    slot = slots[c]
    qw, qx, qy, qz = x[3], x[4], x[5], x[6]
    quat_matrix(qw, qx, qy, qz, R)  # R, then the rotation vector th (axis times angle, rad)
    s2 = qx * qx + qy * qy + qz * qz
    sign = 1.0
    if qw < 0.0:
        qw = -qw
        sign = -1.0
    if s2 < 1e-4 * qw * qw:
        # below about 0.02 rad, 2 atan(z) / z with z = |q_xyz| / q_w by its series to z^8 (the next term is
        # below 1e-20): neither the square root nor the arc tangent's call
        iw = 1.0 / qw
        z2 = s2 * iw * iw
        fr = sign * 2.0 * iw * (1.0 - z2 * (ONE_THIRD - z2 * (0.2 - z2 * (1.0 / 7.0 - z2 * (1.0 / 9.0)))))
    else:
        sn = np.sqrt(s2)
        fr = 2.0 * sign if sn < 1e-12 else sign * 2.0 * np.arctan2(sn, qw) / sn
    th = (fr * qx, fr * qy, fr * qz)
    u0, u1, u2 = x[0], x[1], x[2]
    for i in range(3):
        if not (abs(x[i]) < DIVERGED_DISPLACEMENT and abs(th[i]) < DIVERGED_ROTATION):
            diverged[c] = t
            return False
    settle = t >= t_last[c] - 1e-12
    k = rest_k[c]
    nk = rest_n[c]
    while k < nk and t > rest[c, k, 1] + 1e-12:
        t0 = rest[c, k, 0]
        for p in range(p_viol.shape[1]):
            v = p_viol[c, p]
            if v > -np.inf:
                if v == rest_tprev[c]:
                    v = rest[c, k, 1]
                if v - t0 > p_settle[c, p]:
                    p_settle[c, p] = v - t0
                p_viol[c, p] = -np.inf
        k += 1
        rest_k[c] = k
    at_rest = k < nk and t >= rest[c, k, 0] - 1e-12
    if at_rest:
        rest_tprev[c] = t
    h = t - last_t[c]
    between = step > 0 and h > 0.0 and h <= h_interp[c]
    inv_h = 1.0 / h if between else 0.0
    wb0, wb1, wb2 = x[10], x[11], x[12]
    wf0 = R[0, 0] * wb0 + R[0, 1] * wb1 + R[0, 2] * wb2
    wf1 = R[1, 0] * wb0 + R[1, 1] * wb1 + R[1, 2] * wb2
    wf2 = R[2, 0] * wb0 + R[2, 1] * wb1 + R[2, 2] * wb2
    err = 0.0
    for i in range(3):
        a = max(abs(x[i]), peak_u[c, i])
        if between:
            a = max(a, interval_peak(last_u[c, i, 0], last_u[c, i, 1], x[i], x[7 + i], h, a))
        if a > peak_u[c, i]:
            peak_u[c, i] = a
        last_u[c, i, 0] = x[i]
        last_u[c, i, 1] = x[7 + i]
        wi = wf0 if i == 0 else (wf1 if i == 1 else wf2)
        a = max(abs(th[i]), peak_th[c, i])
        if between:
            a = max(a, interval_peak(last_th[c, i, 0], last_th[c, i, 1], th[i], wi, h, a))
        if a > peak_th[c, i]:
            peak_th[c, i] = a
        last_th[c, i, 0] = th[i]
        last_th[c, i, 1] = wi
        sumsq[c, i] += x[i] * x[i]
        if settle:
            e = abs(x[i] - target[c, i])
            if e > err:
                err = e
    nobs[c] += 1.0
    if slot >= 0:
        O.h_t[slot, step] = t
        h_u, h_th = O.h_u, O.h_th
        for i in range(3):
            h_u[slot, step, i] = x[i]
            h_th[slot, step, i] = th[i]
    v0, v1, v2 = x[7], x[8], x[9]
    for p in range(pts.shape[1]):
        d0, d1, d2 = pts[c, p, 0], pts[c, p, 1], pts[c, p, 2]
        r0, r1, r2 = mount_offset(NONLINEAR, x, R, d0, d1, d2)
        q0, q1, q2 = _arm_rate(NONLINEAR, wf0, wf1, wf2, r0, r1, r2, d0, d1, d2)
        # as :func:`observe`: a material point moves with the base, a relative point does not (``pts`` 0)
        material = pr[c, p] != 0.0
        b0, b1, b2 = (u0, u1, u2) if material else (0.0, 0.0, 0.0)
        s0, s1, s2 = (v0, v1, v2) if material else (0.0, 0.0, 0.0)
        pv0, pv1, pv2 = b0 + r0, b1 + r1, b2 + r2
        peak_point(poi, last_poi, c, p, 0, pv0, s0 + q0, h, between)
        peak_point(poi, last_poi, c, p, 1, pv1, s1 + q1, h, between)
        peak_point(poi, last_poi, c, p, 2, pv2, s2 + q2, h, between)
        if settle:
            t0, t1, t2 = (target[c, 0], target[c, 1], target[c, 2]) if material else (0.0, 0.0, 0.0)
            e0 = target[c, 4] * d2 - target[c, 5] * d1 + t0 + point_offset[c, p, 0]
            e1 = target[c, 5] * d0 - target[c, 3] * d2 + t1 + point_offset[c, p, 1]
            e2 = target[c, 3] * d1 - target[c, 4] * d0 + t2 + point_offset[c, p, 2]
            e = max(abs(pv0 - e0), abs(pv1 - e1), abs(pv2 - e2))
            if e > err:
                err = e
        if at_rest:
            t0, t1, t2 = (
                (rest_target[c, k, 0], rest_target[c, k, 1], rest_target[c, k, 2])
                if material
                else (0.0, 0.0, 0.0)
            )
            e0 = rest_target[c, k, 4] * d2 - rest_target[c, k, 5] * d1 + t0
            e1 = rest_target[c, k, 5] * d0 - rest_target[c, k, 3] * d2 + t1
            e2 = rest_target[c, k, 3] * d1 - rest_target[c, k, 4] * d0 + t2
            e0 += rest_point_offset[c, k, p, 0]
            e1 += rest_point_offset[c, k, p, 1]
            e2 += rest_point_offset[c, k, p, 2]
            if max(abs(pv0 - e0), abs(pv1 - e1), abs(pv2 - e2)) > point_tol[c, p]:
                p_viol[c, p] = t
        if slot >= 0:
            O.h_poi[slot, step, p, 0] = pv0
            O.h_poi[slot, step, p, 1] = pv1
            O.h_poi[slot, step, p, 2] = pv2
    if settle and err > tol[c]:
        last_viol[c] = t
    for j in range(D.shape[1]):
        d0, d1, d2 = D[c, j, 0], D[c, j, 1], D[c, j, 2]
        r0, r1, r2 = mount_offset(NONLINEAR, x, R, d0, d1, d2)
        q0, q1, q2 = _arm_rate(NONLINEAR, wf0, wf1, wf2, r0, r1, r2, d0, d1, d2)
        # the mount's force (as ``isolator_forces``, in this loop, on the mount point's velocity just taken)
        if orient:
            F[j, 0], F[j, 1], F[j, 2] = mount_force(
                NONLINEAR, x, R, xf, vf, c, j, kk, cd, sky, orient, qm, d0, d1, d2, r0, r1, r2
            )
        else:
            rel = 1.0 - sky[c, j]
            F[j, 0], F[j, 1], F[j, 2] = diagonal_force(
                kk,
                cd,
                c,
                j,
                u0 + r0 - xf[0],
                u1 + r1 - xf[1],
                u2 + r2 - xf[2],
                v0 + q0 - rel * vf[0],
                v1 + q1 - rel * vf[1],
                v2 + q2 - rel * vf[2],
            )
        skj = sky[c, j]
        f0j = f0[c, j]
        load = f0j + F[j, 2]
        lo = load
        hi = load
        for i in range(3):
            if i == 0:
                dl, dd = u0 + r0, v0 + q0
            elif i == 1:
                dl, dd = u1 + r1, v1 + q1
            else:
                dl, dd = u2 + r2, v2 + q2
            dl -= xf[i]
            dd -= vf[i]
            F1 = F[j, i]
            a = max(abs(F1), force[c, j, i])
            b = max(abs(dl), defl[c, j, i])
            if between and not orient:
                # as :func:`observe`: the deflection's and the floor's cubics through the force law, the
                # force's cubic written by its end values (``observe``'s shift to meet them, in one step):
                # its constant the force at the previous output time, its linear term what makes it the
                # force now, so only the two highest terms come from the law
                p0, m0 = last_defl[c, j, i, 0], last_defl[c, j, i, 1]
                c0, c1, c2, c3 = hermite(p0, m0, dl, dd, h)
                b = max(b, cubic_beyond(c0, c1, c2, c3, b))
                f3 = 0.0
                if skj != 0.0:
                    _, _, _, f3 = hermite(last_floor[c, i, 0], last_floor[c, i, 1], xf[i], vf[i], h)
                kj, cj = kk[c, j, i], cd[c, j, i] * inv_h
                g2 = -kj * c2 - cj * (3.0 * (c3 + skj * f3))
                g3 = -kj * c3
                g0 = last_force[c, j, i]
                g1 = F1 - g0 - g2 - g3
                a = max(a, cubic_beyond(g0, g1, g2, g3, a))
                if i == 2:
                    b1 = g0 + g1 * ONE_THIRD
                    b2 = b1 + (g1 + g2) * ONE_THIRD
                    if f0j + min(b1, b2) < min(lo, min_load[c, j]) or f0j + max(b1, b2) > max(
                        hi, max_load[c, j]
                    ):
                        glo, ghi = cubic_extremes(g0, g1, g2, g3)
                        lo = min(lo, f0j + glo)
                        hi = max(hi, f0j + ghi)
            if a > force[c, j, i]:
                force[c, j, i] = a
            if b > defl[c, j, i]:
                defl[c, j, i] = b
            if slot >= 0:
                h_force = O.h_force
                h_force[slot, step, j, i] = F1
            last_defl[c, j, i, 0] = dl
            last_defl[c, j, i, 1] = dd
            last_force[c, j, i] = F1
        if lo < min_load[c, j]:
            min_load[c, j] = lo
        if hi > max_load[c, j]:
            max_load[c, j] = hi
    for i in range(3):
        last_floor[c, i, 0] = xf[i]
        last_floor[c, i, 1] = vf[i]
    last_t[c] = t
    return True


@njit(cache=True, inline="always")
def _slot_share(zO, c, r, x, value, rate):
    """``value`` (m) and ``rate`` (m/s) of output ``r`` (a point's or a mount's axis, ``Params.zO``) with
    the extra linear states ``x[12:]`` added."""
    for k in range(zO.shape[2]):
        zk = x[12 + k]
        value += zO[c, 0, k, r] * zk
        rate += zO[c, 1, k, r] * zk
    return value, rate


@njit(cache=True, inline="always")
def _slot_force(zF, c, r, x, force):
    """``force`` (N) of mount axis ``r`` with what the extra linear states ``x[12:]`` add to it
    (``Params.zF``; states that add nothing, a flexible base's modes, leave it as it is, bit for bit)."""
    for k in range(zF.shape[1]):
        w = zF[c, k, r]
        if w != 0.0:
            force += w * x[12 + k]
    return force


@njit(cache=True, inline="always")
def _arm_rate(level, w0, w1, w2, r0, r1, r2, d0, d1, d2):
    """Velocity (m/s) of a material point at ``d`` (m, from the c.g.) relative to the c.g., the base
    turning at ``w`` (rad/s, floor frame): ``w x (R d)`` (nonlinear; ``R d = d + r``), ``w x d`` (linear)."""
    if level == NONLINEAR:
        return cross(w0, w1, w2, d0 + r0, d1 + r1, d2 + r2)
    return cross(w0, w1, w2, d0, d1, d2)
