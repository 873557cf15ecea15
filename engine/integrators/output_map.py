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

Layout of the output vector: ``[mount deflections (n, 3), u (3), theta (3), points (p, 3)]``: the mounts
first, so the loops over their forces start at 0 as the loops over every output do (a loop starting at a
run-time index does not vectorise).
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
    observer (``engine.kernels.peaks.observe``), whose forces follow the mounts' tensors, and so is a case
    whose extra linear states add to its mounts' forces (``P.zF``)."""
    famp = np.asarray(P.famp)
    still = ~np.any(famp != 0.0, axis=1)
    # a case whose extra linear states push through its mounts (a relaxation branch, a levelling valve)
    # reports those forces too: the full observer adds them (``Params.zF``)
    still &= ~np.any(np.asarray(P.zF) != 0.0, axis=(1, 2))
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
            _arm_rows(d).reshape(C, -1, 6),
            np.broadcast_to(np.eye(6), (C, 6, 6)),
            # a relative point (or a following error) does not move with the base (``Params.pr``)
            np.where(np.asarray(P.pr, dtype=bool)[..., None, None], _arm_rows(pts), 0.0).reshape(C, -1, 6),
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
        p3, nf = 3 * pts.shape[1], 3 * d.shape[1]
        zO = np.asarray(P.zO)  # (C, 2, nz, 3 p + 3 n): the points', then the mounts'
        GZ[..., :nf] = zO[..., p3:]
        GZ[..., nf + 6 :] = zO[..., :p3]
        if slot_target is not None:
            tgt = tgt + np.einsum("czm,cz->cm", GZ[:, 0], slot_target)
        if slot_rest_target is not None:
            rtgt = rtgt + np.einsum("czm,ckz->ckm", GZ[:, 0], slot_rest_target)
    return Map(G, KF, np.ascontiguousarray(tgt), np.ascontiguousarray(rtgt), GZ)


CAPACITY = 1024
"""The most outputs (``m``) a case observed through the map may have (the scene's limits give at most 966),
a multiple of 8; a case with more is observed by the general observer."""
STRIDE = CAPACITY + 8
"""Elements between two rows of the observer's scratch: a fixed number, so every row is a known distance
from the others and the compiler may vectorise a loop that reads some rows and writes others (rows of a
2-D array are a run-time stride apart, which it would have to check at run time, and gives up on); the 8
more than ``CAPACITY`` start each row on another cache set."""
_G = 0  # 6 rows: the case's map G (positions to outputs)
_PEAK = 6 * STRIDE  # each output's running peak
_PREV = 7 * STRIDE  # its value at the previous output time
_PREV_RATE = 8 * STRIDE  # and its rate there
_FPEAK = 9 * STRIDE  # each mount axis' force peak
_FPREV = 10 * STRIDE  # its force at the previous output time, then (updated in place) now
_LO = 11 * STRIDE  # each mount's smallest load (n)
_HI = 12 * STRIDE  # and its largest
_FLAG = 13 * STRIDE  # how far an output's inner Bernstein control points reach past its peak
_VIOL = 14 * STRIDE  # each point's last output time outside its settling band (p)
_SETTLE = 15 * STRIDE  # and its worst settling time (p)
_VAL = 16 * STRIDE  # each output's value now
_RATE = 17 * STRIDE  # and its rate
_CUBIC = 18 * STRIDE  # 4 rows: the force's cubic over the last output interval (3 n)
_BERN = 22 * STRIDE  # 2 rows: its inner Bernstein control points (3 n)
_KF = 24 * STRIDE  # 2 rows: each mount axis' stiffness and damping, the case's ``KF`` (3 n)
SCRATCH = 26 * STRIDE
"""Length of the observer's scratch (:func:`start`, :func:`observe`)."""


@njit(cache=True)
def start(O, c, G, KF, B, Q):
    """Load case ``c``'s map ``G`` (C, 6, m) and ``KF`` (C, 2, 3 n) and its running state from the
    accumulators ``O`` into the scratch ``B`` (:data:`SCRATCH`,) and ``Q`` (15,) (see :func:`observe`)."""
    p = O.poi.shape[1]
    n = O.force.shape[1]
    m = 6 + 3 * p + 3 * n
    nf = 3 * n
    for i in range(6):
        for r in range(m):
            B[_G + i * STRIDE + r] = G[c, i, r]
    for i in range(2):
        for r in range(3 * n):
            B[_KF + i * STRIDE + r] = KF[c, i, r]
    for i in range(3):
        B[_PEAK + nf + i] = O.u[c, i]
        B[_PEAK + nf + 3 + i] = O.th[c, i]
        for q in range(p):
            B[_PEAK + nf + 6 + 3 * q + i] = O.poi[c, q, i]
        for j in range(n):
            B[_PEAK + 3 * j + i] = O.defl[c, j, i]
            B[_FPEAK + 3 * j + i] = O.force[c, j, i]
        Q[8 + i] = O.sumsq[c, i]
    for j in range(n):
        B[_LO + j] = O.min_load[c, j]
        B[_HI + j] = O.max_load[c, j]
    for r in range(m):
        B[_PREV + r] = 0.0
        B[_PREV_RATE + r] = 0.0
        B[_FLAG + r] = 0.0
    for q in range(p):
        B[_VIOL + q] = O.p_viol[c, q]
        B[_SETTLE + q] = O.p_settle[c, q]
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
    k = O.rest_k[c]
    Q[13] = O.rest[c, k, 1] + 1e-12 if k < O.rest_n[c] else np.inf
    Q[14] = O.rest[c, k, 0] - 1e-12 if k < O.rest_n[c] else np.inf


@njit(cache=True)
def finish(O, c, B, Q):
    """Write case ``c``'s running state from the scratch ``B``, ``Q`` back into the accumulators ``O``."""
    p = O.poi.shape[1]
    n = O.force.shape[1]
    nf = 3 * n
    for i in range(3):
        O.u[c, i] = B[_PEAK + nf + i]
        O.th[c, i] = B[_PEAK + nf + 3 + i]
        for q in range(p):
            O.poi[c, q, i] = B[_PEAK + nf + 6 + 3 * q + i]
        for j in range(n):
            O.defl[c, j, i] = B[_PEAK + 3 * j + i]
            O.force[c, j, i] = B[_FPEAK + 3 * j + i]
        O.sumsq[c, i] = Q[8 + i]
    for j in range(n):
        O.min_load[c, j] = B[_LO + j]
        O.max_load[c, j] = B[_HI + j]
    for q in range(p):
        O.p_viol[c, q] = B[_VIOL + q]
        O.p_settle[c, q] = B[_SETTLE + q]
    O.last_t[c] = Q[3]
    O.rest_k[c] = int(Q[4])
    O.rest_tprev[c] = Q[6]
    O.last_viol[c] = Q[7]
    O.nobs[c] = Q[11]
    O.diverged[c] = Q[12]


@njit(cache=True, inline="always")
def observe(c, t, x, step, F0, tgt, rtgt, rest, ptol, B, Q, GZ):
    """Update case ``c``'s peaks with the linear-level state ``x`` (12 + nz,) at time ``t`` (s), output
    sample ``step``, the floor at rest, as ``engine.kernels.peaks.observe`` does.

    ``tgt``, ``rtgt``, ``GZ`` are the output map (:func:`build`; its ``G`` and ``KF`` are in ``B``), ``F0``
    (C, n) the static loads (N), ``rest`` (C, K, 2) the rest intervals (s) and ``ptol`` (C, p) the points'
    settling tolerances (m) of ``engine.kernels.peaks.Peaks``. The case's map and running state live in
    rows of the flat scratch ``B`` (:data:`SCRATCH`,), each :data:`STRIDE` long (``_G`` ... ``_BERN``
    above: the peaks, the previous values and rates, the force peaks and forces (3 n, the previous output
    time's until the mount loop replaces them), the smallest and largest loads (n), a flag, each point's
    last violation and worst settling time (p), and this output time's values, rates and force cubics);
    ``Q`` (15,) holds the last move's end, the settling tolerance, the longest interpolated interval, the
    last output time, the rest-interval cursor and count, the last output time inside a rest interval, the
    last violation, the sums of squares (3), the number of outputs, the divergence time, and the cursor's
    interval's end and start (s, +inf past the last), so a step inside or between rest intervals checks
    one number each. (:func:`start` and :func:`finish` move them in and out of the accumulators.) The
    loops over the outputs read and write rows a fixed distance apart, so they run as vector loops; the
    closed-form solve between output times runs only where a screen flagged an output. Returns False (and
    keeps ``t`` as the divergence time) when the state is not finite or has left any physically possible
    range.
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
    nf = 3 * n
    # the loops over the outputs and the mount axes run to the next multiple of 8 (a vector's width):
    # no scalar remainder; the entries past m and nf read zero rows of ``G`` and ``KF`` (the same m for
    # every case of a batch) and keep zero, and the mounts' loop past nf computes zero forces
    m8 = (m + 7) // 8 * 8
    nf8 = (nf + 7) // 8 * 8
    settle = t >= Q[0] - 1e-12
    # the rest interval after a stage move that t falls in (time only increases: a cursor moves on)
    k = int(Q[4])
    nk = int(Q[5])
    while t > Q[13]:  # past the end of the interval k (+inf when none is left)
        t0 = rest[c, k, 0]
        for q in range(n_pts):
            v = B[_VIOL + q]
            if v > -np.inf:
                if v == Q[6]:
                    v = rest[c, k, 1]  # still outside at the interval's last output: its length
                if v - t0 > B[_SETTLE + q]:
                    B[_SETTLE + q] = v - t0
                B[_VIOL + q] = -np.inf
        k += 1
        Q[4] = k
        Q[13] = rest[c, k, 1] + 1e-12 if k < nk else np.inf
        Q[14] = rest[c, k, 0] - 1e-12 if k < nk else np.inf
    in_rest = t >= Q[14]
    if in_rest:
        Q[6] = t
    h = t - Q[3]
    between = step > 0 and h > 0.0 and h <= Q[2]
    x0, x1, x2, x3, x4, x5 = x[0], x[1], x[2], x[3], x[4], x[5]
    v0, v1, v2, v3, v4, v5 = x[6], x[7], x[8], x[9], x[10], x[11]
    # values and rates of every output
    for r in range(m8):
        g0, g1, g2 = B[_G + r], B[_G + STRIDE + r], B[_G + 2 * STRIDE + r]
        g3, g4, g5 = B[_G + 3 * STRIDE + r], B[_G + 4 * STRIDE + r], B[_G + 5 * STRIDE + r]
        B[_VAL + r] = g0 * x0 + g1 * x1 + g2 * x2 + g3 * x3 + g4 * x4 + g5 * x5
        B[_RATE + r] = g0 * v0 + g1 * v1 + g2 * v2 + g3 * v3 + g4 * v4 + g5 * v5
    for j in range(GZ.shape[2]):  # the extra linear states (a flexible base's modes ...)
        zj = x[12 + j]
        for r in range(m):
            B[_VAL + r] += GZ[c, 0, j, r] * zj
            B[_RATE + r] += GZ[c, 1, j, r] * zj
    # peaks at the output times, and a flag on the outputs whose cubic's inner Bernstein control points
    # reach past them (the cubic stays in their hull: only those can peak between the output times)
    hth = h * ONE_THIRD
    flagged = 0
    for r in range(m8):
        val = B[_VAL + r]
        a = max(abs(val), B[_PEAK + r])
        B[_PEAK + r] = a
        b1 = B[_PREV + r] + hth * B[_PREV_RATE + r]
        b2 = val - hth * B[_RATE + r]
        reach = max(abs(b1), abs(b2)) - a
        B[_FLAG + r] = reach
        if reach > 0.0:
            flagged += 1
    # isolator forces -k delta - c delta' and their cubics: the deflection's Hermite cubic through the force
    # law, shifted linearly to meet the forces at both ends (as engine.kernels.peaks.observe)
    inv_h = 1.0 / h if between else 0.0
    forces_flagged = 0
    for q in range(nf8):
        kk = B[_KF + q]
        cr = B[_KF + STRIDE + q]
        cc = cr * inv_h
        p0 = B[_PREV + q]
        m0 = B[_PREV_RATE + q]
        p1 = B[_VAL + q]
        m1 = B[_RATE + q]
        f = -kk * p1 - cr * m1
        c1 = h * m0
        c2 = 3.0 * (p1 - p0) - h * (2.0 * m0 + m1)
        c3 = 2.0 * (p0 - p1) + h * (m0 + m1)
        a0 = -kk * p0 - cc * c1
        a1 = -kk * c1 - cc * (2.0 * c2)
        a2 = -kk * c2 - cc * (3.0 * c3)
        a3 = -kk * c3
        e0 = B[_FPREV + q] - a0
        B[_FPREV + q] = f  # the force now: the next output time's previous one
        e1 = f - (a0 + a1 + a2 + a3)
        a0 += e0
        a1 += e1 - e0
        B[_CUBIC + q] = a0
        B[_CUBIC + STRIDE + q] = a1
        B[_CUBIC + 2 * STRIDE + q] = a2
        B[_CUBIC + 3 * STRIDE + q] = a3
        b1 = a0 + a1 * ONE_THIRD
        b2 = b1 + (a1 + a2) * ONE_THIRD
        B[_BERN + q] = b1
        B[_BERN + STRIDE + q] = b2
        peak = max(abs(f), B[_FPEAK + q])
        B[_FPEAK + q] = peak
        if max(abs(b1), abs(b2)) > peak:
            forces_flagged += 1
    if between and flagged > 0:
        for r in range(m):
            if B[_FLAG + r] > 0.0:
                c0, c1, c2, c3 = hermite(B[_PREV + r], B[_PREV_RATE + r], B[_VAL + r], B[_RATE + r], h)
                lo, hi = cubic_extremes(c0, c1, c2, c3)
                if hi >= lo:
                    B[_PEAK + r] = max(B[_PEAK + r], abs(lo), abs(hi))
    if between and forces_flagged > 0:
        for r in range(nf):
            if max(abs(B[_BERN + r]), abs(B[_BERN + STRIDE + r])) > B[_FPEAK + r]:
                lo, hi = _force_extremes(B, r)
                if hi >= lo:
                    B[_FPEAK + r] = max(B[_FPEAK + r], abs(lo), abs(hi))
    # the loads on the mounts: static plus the vertical force, their extremes between output times too
    for j in range(n):
        r = 3 * j + 2
        f0j = F0[c, j]
        load = f0j + B[_FPREV + r]
        lo = min(B[_LO + j], load)
        hi = max(B[_HI + j], load)
        b1, b2 = B[_BERN + r], B[_BERN + STRIDE + r]
        if between and (f0j + min(b1, b2) < lo or f0j + max(b1, b2) > hi):
            glo, ghi = _force_extremes(B, r)
            lo = min(lo, f0j + glo)
            hi = max(hi, f0j + ghi)
        B[_LO + j] = lo
        B[_HI + j] = hi
    for r in range(m8):
        B[_PREV + r] = B[_VAL + r]
        B[_PREV_RATE + r] = B[_RATE + r]
    # RMS of the c.g. displacement, settling of the c.g. and the points after the last move
    for i in range(3):
        Q[8 + i] += x[i] * x[i]
    Q[11] += 1.0
    if settle:
        tol = Q[1]
        outside = 0  # outputs beyond the settling band: a count, so the loops run as vector loops
        for r in range(nf, nf + 3):
            if abs(B[_VAL + r] - tgt[c, r]) > tol:
                outside += 1
        for r in range(nf + 6, m):
            if abs(B[_VAL + r] - tgt[c, r]) > tol:
                outside += 1
        if outside > 0:
            Q[7] = t
    if in_rest:
        for q in range(n_pts):
            e = 0.0
            for i in range(3):
                r = nf + 6 + 3 * q + i
                e = max(e, abs(B[_VAL + r] - rtgt[c, k, r]))
            if e > ptol[c, q]:
                B[_VIOL + q] = t
    Q[3] = t
    return True


@njit(cache=True, inline="always")
def _force_extremes(B, r):
    """The extremes of mount axis ``r``'s force cubic strictly inside the last output interval (N)."""
    return cubic_extremes(
        B[_CUBIC + r], B[_CUBIC + STRIDE + r], B[_CUBIC + 2 * STRIDE + r], B[_CUBIC + 3 * STRIDE + r]
    )
