"""Peaks of the linear levels through a precomputed linear output map.

At the ``lti`` and ``ltv`` levels every peaked quantity is linear in the base's state (small rotations):
the c.g. displacement ``u``, the rotation ``theta``, each point's displacement ``u + theta x d`` and each
mount's deflection (the same with the mount's arm, minus the floor's motion). One matrix ``G`` (6, m) per
case maps the positions ``x[:6]`` to those ``m = 6 + 3 p + 3 n`` values and the velocities ``x[6:]`` to
their rates; the isolator forces follow from the deflections, ``-k delta - c delta'``. :func:`observe`
does what ``engine.kernels.peaks.observe`` does for a case without floor motion (the floor still under the
mounts), with every output in one contiguous vector, so its loops run over the outputs and vectorise, and
the closed-form solve for an extremum between output times runs only for the outputs whose Bernstein
control points flag one. The running peaks are kept in per-case scratch (:func:`start`) and written back
to the ``engine.kernels.peaks.Peaks`` accumulators when the case ends (:func:`finish`).

Layout of the output vector: ``[u (3), theta (3), points (p, 3), mount deflections (n, 3)]``.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit

from isolab.engine.kernels.between_steps import ONE_THIRD, cubic_extremes, hermite
from isolab.engine.kernels.params import Params
from isolab.engine.kernels.peaks import DIVERGED_DISPLACEMENT, DIVERGED_ROTATION

Map = namedtuple("Map", ["G", "KF", "target", "rest_target", "GZ"])
"""``G`` (C, 6, m): positions (m, rad) to outputs (m); ``KF`` (C, 2, 3 n) each mount's stiffness (N/m) and
damping (N s/m) per axis; ``target`` (C, m) the outputs at the final static state; ``rest_target``
(C, K, m) at the static state of each rest interval; ``GZ`` (C, 2, nz, m) what the extra linear states
``z = x[12:]`` add to the outputs (row 0) and to their rates (row 1) (``Params.zO``; nz = 0 without)."""


def still_floor(P: Params) -> np.ndarray:
    """Per case (C,), True where the floor does not move in time under it (no sine, no recorded floor
    motion): where the output map observes it. Decided per case, so a case's results do not depend on
    the batch it runs in. A batch with mounts on their own axes (``P.orient``) is observed by the full
    observer (``engine.kernels.peaks.observe``), whose forces follow the mounts' tensors."""
    famp = np.asarray(P.famp)
    still = ~np.any(famp != 0.0, axis=1)
    if P.orient:
        still[:] = False
    if np.asarray(P.ft).shape[0]:
        still &= ~np.any(np.asarray(P.fd) != 0.0, axis=(1, 2))
    return np.ascontiguousarray(still)


def _arm_rows(d: np.ndarray) -> np.ndarray:
    """Rows (C, k, 3, 6) mapping ``[u, theta]`` to ``u + theta x d`` for arms ``d`` (C, k, 3), m."""
    C, k = d.shape[:2]
    out = np.zeros((C, k, 3, 6))
    for i in range(3):
        out[:, :, i, i] = 1.0
    d0, d1, d2 = d[..., 0], d[..., 1], d[..., 2]
    # theta x d = (th1 d2 - th2 d1, th2 d0 - th0 d2, th0 d1 - th1 d0)
    out[:, :, 0, 4], out[:, :, 0, 5] = d2, -d1
    out[:, :, 1, 5], out[:, :, 1, 3] = d0, -d2
    out[:, :, 2, 3], out[:, :, 2, 4] = d1, -d0
    return out


def build(
    P: Params,
    target: np.ndarray,
    rest_target: np.ndarray,
    slot_target: np.ndarray | None = None,
    slot_rest_target: np.ndarray | None = None,
) -> Map:
    """The output map of a batch (see the module's docstring) from its kernel parameters ``P``, the final
    static offset ``target`` (C, 6) (m, rad) and each rest interval's ``rest_target`` (C, K, 6); with
    extra linear states, their static values ``slot_target`` (C, nz) and ``slot_rest_target`` (C, K, nz)."""
    pts = np.asarray(P.pts, dtype=float)
    d = np.asarray(P.d, dtype=float)
    C = d.shape[0]
    rows = np.concatenate(
        [
            np.broadcast_to(np.eye(6), (C, 6, 6)),
            # a relative point (or a following error) does not move with the base (``Params.pr``)
            np.where(np.asarray(P.pr, dtype=bool)[..., None, None], _arm_rows(pts), 0.0).reshape(C, -1, 6),
            _arm_rows(d).reshape(C, -1, 6),
        ],
        axis=1,
    )  # (C, m, 6)
    G = np.ascontiguousarray(np.swapaxes(rows, 1, 2))
    tgt = np.einsum("cmj,cj->cm", rows, np.asarray(target, dtype=float))
    rtgt = np.einsum("cmj,ckj->ckm", rows, np.asarray(rest_target, dtype=float))
    KF = np.ascontiguousarray(
        np.stack([np.asarray(P.k).reshape(C, -1), np.asarray(P.cd).reshape(C, -1)], axis=1)
    )
    nz = P.zA.shape[1]
    GZ = np.zeros((C, 2, nz, G.shape[2]))
    if nz:
        GZ[..., 6:] = P.zO
        if slot_target is not None:
            tgt = tgt + np.einsum("czm,cz->cm", GZ[:, 0], slot_target)
        if slot_rest_target is not None:
            rtgt = rtgt + np.einsum("czm,ckz->ckm", GZ[:, 0], slot_rest_target)
    return Map(G, KF, np.ascontiguousarray(tgt), np.ascontiguousarray(rtgt), GZ)


@njit(cache=True)
def start(O, c, S, Q):
    """Load case ``c``'s running state from the accumulators ``O`` into the scratch ``S`` (10, m) and
    ``Q`` (13,) (see :func:`observe`)."""
    p = O.poi.shape[1]
    n = O.force.shape[1]
    m = 6 + 3 * p + 3 * n
    for i in range(3):
        S[0, i] = O.u[c, i]
        S[0, 3 + i] = O.th[c, i]
        for q in range(p):
            S[0, 6 + 3 * q + i] = O.poi[c, q, i]
        for j in range(n):
            S[0, 6 + 3 * p + 3 * j + i] = O.defl[c, j, i]
            S[3, 3 * j + i] = O.force[c, j, i]
        Q[8 + i] = O.sumsq[c, i]
    for j in range(n):
        S[5, j] = O.min_load[c, j]
        S[6, j] = O.max_load[c, j]
    for r in range(m):
        S[1, r] = 0.0
        S[2, r] = 0.0
        S[7, r] = 0.0
    for q in range(p):
        S[8, q] = O.p_viol[c, q]
        S[9, q] = O.p_settle[c, q]
    Q[0] = O.t_last[c]
    Q[1] = O.tol[c]
    Q[2] = O.h_interp[c]
    Q[3] = O.last_t[c]
    Q[4] = O.rest_k[c]
    Q[5] = O.rest_n[c]
    Q[6] = O.rest_tprev[c]
    Q[7] = O.last_viol[c]
    Q[11] = O.nobs[c]
    Q[12] = O.diverged[c]


@njit(cache=True)
def finish(O, c, S, Q):
    """Write case ``c``'s running state from the scratch ``S``, ``Q`` back into the accumulators ``O``."""
    p = O.poi.shape[1]
    n = O.force.shape[1]
    for i in range(3):
        O.u[c, i] = S[0, i]
        O.th[c, i] = S[0, 3 + i]
        for q in range(p):
            O.poi[c, q, i] = S[0, 6 + 3 * q + i]
        for j in range(n):
            O.defl[c, j, i] = S[0, 6 + 3 * p + 3 * j + i]
            O.force[c, j, i] = S[3, 3 * j + i]
        O.sumsq[c, i] = Q[8 + i]
    for j in range(n):
        O.min_load[c, j] = S[5, j]
        O.max_load[c, j] = S[6, j]
    for q in range(p):
        O.p_viol[c, q] = S[8, q]
        O.p_settle[c, q] = S[9, q]
    O.last_t[c] = Q[3]
    O.rest_k[c] = int(Q[4])
    O.rest_tprev[c] = Q[6]
    O.last_viol[c] = Q[7]
    O.nobs[c] = Q[11]
    O.diverged[c] = Q[12]


@njit(cache=True, inline="always")
def observe(c, t, x, step, G, KF, F0, tgt, rtgt, rest, ptol, S, V, Q, GZ):
    """Update case ``c``'s peaks with the linear-level state ``x`` (12,) at time ``t`` (s), output sample
    ``step``, the floor at rest, as ``engine.kernels.peaks.observe`` does.

    ``G``, ``KF``, ``tgt``, ``rtgt``, ``GZ`` are the output map (:func:`build`), ``F0`` (C, n) the static
    loads (N), ``rest`` (C, K, 2) the rest intervals (s) and ``ptol`` (C, p) the points' settling tolerances
    (m) of ``engine.kernels.peaks.Peaks``. The case's running state lives in ``S`` (10, m): rows 0 the peaks,
    1 and 2 the previous values and rates, 3 the force peaks and 4 the previous forces (3 n), 5 and 6 the
    smallest and largest loads (n), 7 a flag, 8 and 9 each point's last violation and worst settling time (p);
    and ``Q`` (13,): the last move's end, the settling tolerance, the longest interpolated interval, the last
    output time, the rest-interval cursor and count, the last output time inside a rest interval, the last
    violation, the sums of squares (3), the number of outputs and the divergence time. (:func:`start` and
    :func:`finish` move them in and out of the accumulators.) ``V`` (9, m) is scratch. Rows are indexed, not
    sliced: a view per call costs more than the arithmetic. Returns False (and keeps ``t`` as the divergence
    time) when the state is not finite or has left any physically possible range.
    """
    ok = True
    for i in range(3):
        if not (abs(x[i]) < DIVERGED_DISPLACEMENT and abs(x[3 + i]) < DIVERGED_ROTATION):
            ok = False
    if not ok:
        Q[12] = t
        return False
    n_pts = ptol.shape[1]
    n = F0.shape[1]
    m = 6 + 3 * n_pts + 3 * n
    first_defl = 6 + 3 * n_pts
    settle = t >= Q[0] - 1e-12
    # the rest interval after a stage move that t falls in (time only increases: a cursor moves on)
    k = int(Q[4])
    nk = int(Q[5])
    while k < nk and t > rest[c, k, 1] + 1e-12:
        t0 = rest[c, k, 0]
        for q in range(n_pts):
            v = S[8, q]
            if v > -np.inf:
                if v == Q[6]:
                    v = rest[c, k, 1]  # still outside at the interval's last output: its length
                if v - t0 > S[9, q]:
                    S[9, q] = v - t0
                S[8, q] = -np.inf
        k += 1
        Q[4] = k
    in_rest = k < nk and t >= rest[c, k, 0] - 1e-12
    if in_rest:
        Q[6] = t
    h = t - Q[3]
    between = step > 0 and h > 0.0 and h <= Q[2]
    x0, x1, x2, x3, x4, x5 = x[0], x[1], x[2], x[3], x[4], x[5]
    v0, v1, v2, v3, v4, v5 = x[6], x[7], x[8], x[9], x[10], x[11]
    # values and rates of every output (vectorised over the outputs)
    for r in range(m):
        g0, g1, g2, g3, g4, g5 = G[c, 0, r], G[c, 1, r], G[c, 2, r], G[c, 3, r], G[c, 4, r], G[c, 5, r]
        V[0, r] = g0 * x0 + g1 * x1 + g2 * x2 + g3 * x3 + g4 * x4 + g5 * x5
        V[1, r] = g0 * v0 + g1 * v1 + g2 * v2 + g3 * v3 + g4 * v4 + g5 * v5
    for j in range(GZ.shape[2]):  # the extra linear states (a flexible base's modes ...)
        zj = x[12 + j]
        for r in range(m):
            V[0, r] += GZ[c, 0, j, r] * zj
            V[1, r] += GZ[c, 1, j, r] * zj
    # peaks at the output times, and a flag on the outputs whose cubic's inner Bernstein control points
    # reach past them (the cubic stays in their hull: only those can peak between the output times)
    hth = h * ONE_THIRD
    for r in range(m):
        a = max(abs(V[0, r]), S[0, r])
        S[0, r] = a
        b1 = S[1, r] + hth * S[2, r]
        b2 = V[0, r] - hth * V[1, r]
        S[7, r] = max(abs(b1), abs(b2)) - a
    # isolator forces -k delta - c delta' and their cubics: the deflection's Hermite cubic through the force
    # law, shifted linearly to meet the forces at both ends (as engine.kernels.peaks.observe)
    nf = 3 * n
    inv_h = 1.0 / h if between else 0.0
    for r in range(nf):
        q = first_defl + r
        kk = KF[c, 0, r]
        cc = KF[c, 1, r] * inv_h
        p0 = S[1, q]
        m0 = S[2, q]
        p1 = V[0, q]
        m1 = V[1, q]
        f = -kk * p1 - KF[c, 1, r] * m1
        V[2, r] = f
        c1 = h * m0
        c2 = 3.0 * (p1 - p0) - h * (2.0 * m0 + m1)
        c3 = 2.0 * (p0 - p1) + h * (m0 + m1)
        a0 = -kk * p0 - cc * c1
        a1 = -kk * c1 - cc * (2.0 * c2)
        a2 = -kk * c2 - cc * (3.0 * c3)
        a3 = -kk * c3
        e0 = S[4, r] - a0
        e1 = f - (a0 + a1 + a2 + a3)
        a0 += e0
        a1 += e1 - e0
        V[3, r] = a0
        V[4, r] = a1
        V[5, r] = a2
        V[6, r] = a3
        b1 = a0 + a1 * ONE_THIRD
        b2 = b1 + (a1 + a2) * ONE_THIRD
        V[7, r] = b1
        V[8, r] = b2
        S[3, r] = max(abs(f), S[3, r])
    if between:
        for r in range(m):
            if S[7, r] > 0.0:
                c0, c1, c2, c3 = hermite(S[1, r], S[2, r], V[0, r], V[1, r], h)
                lo, hi = cubic_extremes(c0, c1, c2, c3)
                if hi >= lo:
                    S[0, r] = max(S[0, r], abs(lo), abs(hi))
        for r in range(nf):
            if max(abs(V[7, r]), abs(V[8, r])) > S[3, r]:
                lo, hi = cubic_extremes(V[3, r], V[4, r], V[5, r], V[6, r])
                if hi >= lo:
                    S[3, r] = max(S[3, r], abs(lo), abs(hi))
    # the loads on the mounts: static plus the vertical force, their extremes between output times too
    for j in range(n):
        r = 3 * j + 2
        f0j = F0[c, j]
        load = f0j + V[2, r]
        lo = min(S[5, j], load)
        hi = max(S[6, j], load)
        if between and (f0j + min(V[7, r], V[8, r]) < lo or f0j + max(V[7, r], V[8, r]) > hi):
            glo, ghi = cubic_extremes(V[3, r], V[4, r], V[5, r], V[6, r])
            lo = min(lo, f0j + glo)
            hi = max(hi, f0j + ghi)
        S[5, j] = lo
        S[6, j] = hi
    for r in range(m):
        S[1, r] = V[0, r]
        S[2, r] = V[1, r]
    for r in range(nf):
        S[4, r] = V[2, r]
    # RMS of the c.g. displacement, settling of the c.g. and the points after the last move
    for i in range(3):
        Q[8 + i] += x[i] * x[i]
    Q[11] += 1.0
    if settle:
        err = 0.0
        for r in range(3):
            err = max(err, abs(V[0, r] - tgt[c, r]))
        for r in range(6, first_defl):
            err = max(err, abs(V[0, r] - tgt[c, r]))
        if err > Q[1]:
            Q[7] = t
    if in_rest:
        for q in range(n_pts):
            e = 0.0
            for i in range(3):
                r = 6 + 3 * q + i
                e = max(e, abs(V[0, r] - rtgt[c, k, r]))
            if e > ptol[c, q]:
                S[8, q] = t
    Q[3] = t
    return True
