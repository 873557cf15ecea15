"""Active mounts that feed the stages' inertial wrench forward (docs/physics.md, "Active mounts with
feedforward").

Each feedforward mount's actuator applies its share of the stages' inertial wrench with its sign reversed
(and, where asked, of the change of their weight moment), low-passed at its corner frequency, times its
gain, clipped per axis to its force limit. The low-pass is solved in closed form on the
piecewise-polynomial profiles: a particular response that follows the wrench's polynomial, plus a free
response per stretch between breakpoints whose amplitudes :func:`feedforward_transients` prepares once per
case. Numba functions on case ``c`` of the kernel parameters ``P`` (``engine.kernels.params.Params``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from isolab.engine.kernels.excitation import advance_pieces, stage_state
from isolab.engine.kernels.rotations import cross


@njit(cache=True, fastmath=False)
def stage_wrench(P, c, rho, vr, ar, jr, X):
    """The stages' inertial wrench on the base with its sign reversed, and its time derivatives, from the
    stage kinematics of :func:`stage_state`: ``X[0] = [sum m a_rel, sum m rho x a_rel]`` (N, N m), ``X[k]``
    its k-th derivative (k = 1..3; the pieces' jerk is constant, so the fourth vanishes). ``X[4:8]``: the
    same for the change of the stages' weight moment, reversed: ``[0, -sum m (rho - rho_home) x g_vec]``.
    ``X`` (8, 6)."""
    g = P.g
    for k in range(8):
        for q in range(6):
            X[k, q] = 0.0
    for i in range(P.sm.shape[1]):
        m = P.sm[c, i]
        r0, r1, r2 = rho[i, 0], rho[i, 1], rho[i, 2]
        v0, v1, v2 = vr[i, 0], vr[i, 1], vr[i, 2]
        a0, a1, a2 = ar[i, 0], ar[i, 1], ar[i, 2]
        j0, j1, j2 = jr[i, 0], jr[i, 1], jr[i, 2]
        X[0, 0] += m * a0
        X[0, 1] += m * a1
        X[0, 2] += m * a2
        X[1, 0] += m * j0
        X[1, 1] += m * j1
        X[1, 2] += m * j2
        p0, p1, p2 = cross(r0, r1, r2, a0, a1, a2)
        X[0, 3] += m * p0
        X[0, 4] += m * p1
        X[0, 5] += m * p2
        # d/dt (rho x a) = v x a + rho x j; then 2 v x j; then 2 a x j
        p0, p1, p2 = cross(v0, v1, v2, a0, a1, a2)
        q0, q1, q2 = cross(r0, r1, r2, j0, j1, j2)
        X[1, 3] += m * (p0 + q0)
        X[1, 4] += m * (p1 + q1)
        X[1, 5] += m * (p2 + q2)
        p0, p1, p2 = cross(v0, v1, v2, j0, j1, j2)
        X[2, 3] += 2.0 * m * p0
        X[2, 4] += 2.0 * m * p1
        X[2, 5] += 2.0 * m * p2
        p0, p1, p2 = cross(a0, a1, a2, j0, j1, j2)
        X[3, 3] += 2.0 * m * p0
        X[3, 4] += 2.0 * m * p1
        X[3, 5] += 2.0 * m * p2
        # -(rho - rho_h) x (0, 0, -g) = g (s1, -s0, 0), and its derivatives
        mg = m * g
        X[4, 3] += mg * (r1 - P.rho_h[c, i, 1])
        X[4, 4] -= mg * (r0 - P.rho_h[c, i, 0])
        X[5, 3] += mg * v1
        X[5, 4] -= mg * v0
        X[6, 3] += mg * a1
        X[6, 4] -= mg * a0
        X[7, 3] += mg * j1
        X[7, 4] -= mg * j0


@njit(cache=True, inline="always")
def _follow(X, wc, q, wt):
    """The low-pass's particular response to the cubic input ``x = X[0, q] + wt X[4, q]`` (derivatives in
    the next rows, :func:`stage_wrench`; ``wt`` 1 adds the weight moment, 0 not):
    ``y_p = x - x_1/wc + x_2/wc^2 - x_3/wc^3`` solves ``y' = wc (x - y)``."""
    u = 1.0 / wc
    y = X[0, q] - u * (X[1, q] - u * (X[2, q] - u * X[3, q]))
    if wt != 0.0:
        y += wt * (X[4, q] - u * (X[5, q] - u * (X[6, q] - u * X[7, q])))
    return y


@njit(cache=True, fastmath=False)
def feedforward_transients(P, c, W):
    """Fill ``P.ffA[c]`` (n, B, 6): per mount and stretch between breakpoints ``P.fftb[c]``, the amplitude
    of the low-pass's free response ``e^(-wc (t - t_k))`` that joins its particular response
    (:func:`_follow`) to the filtered wrench at the stretch's start (the filter starts at rest)."""
    n = P.d.shape[1]
    idx = np.full(P.sm.shape[1], -1, dtype=np.int64)
    X = W.ffx
    y_end = np.zeros((n, 6))  # the filtered wrench where the current stretch begins
    B = P.fftb.shape[1]
    for k in range(B):
        tk = P.fftb[c, k]
        if not np.isfinite(tk):
            break
        advance_pieces(P, c, tk, idx, 0.0)
        stage_state(P, c, tk, idx, W.rho, W.vr, W.ar, W.jr)
        stage_wrench(P, c, W.rho, W.vr, W.ar, W.jr, X)
        for j in range(n):
            if P.ffg[c, j] == 0.0:
                continue
            for q in range(6):
                P.ffA[c, j, k, q] = y_end[j, q] - _follow(X, P.ffw[c, j], q, P.ffwt[c, j])
        if k + 1 < B and np.isfinite(P.fftb[c, k + 1]):
            tn = P.fftb[c, k + 1]
            stage_state(P, c, tn, idx, W.rho, W.vr, W.ar, W.jr)  # this stretch's pieces, at its end
            stage_wrench(P, c, W.rho, W.vr, W.ar, W.jr, X)
            for j in range(n):
                if P.ffg[c, j] == 0.0:
                    continue
                wc = P.ffw[c, j]
                e = np.exp(-wc * (tn - tk))
                for q in range(6):
                    y_end[j, q] = _follow(X, wc, q, P.ffwt[c, j]) + P.ffA[c, j, k, q] * e


@njit(cache=True, fastmath=False)
def feedforward_forces(P, c, t, idx, W):
    """Actuator forces ``W.Fa`` (n, 3) N, machine axes, of the feedforward mounts at ``t`` (s), from the
    stage kinematics already in ``W`` (:func:`stage_state` at ``t`` on the pieces ``idx``).

    Each mount applies its share ``D_j`` (least-norm distribution over the feedforward mounts) of the
    stages' inertial wrench with its sign reversed, low-passed at its corner ``wc`` (in closed form on the
    piecewise-polynomial profile), times its gain, clipped per axis to its force limit.
    """
    n = P.d.shape[1]
    X = W.ffx
    stage_wrench(P, c, W.rho, W.vr, W.ar, W.jr, X)
    # the stretch between breakpoints the pieces ``idx`` belong to: it starts at the latest piece start
    tseg = -np.inf
    for i in range(P.sm.shape[1]):
        if idx[i] >= 0 and P.pt[c, i, idx[i]] > tseg:
            tseg = P.pt[c, i, idx[i]]
    k = -1
    if tseg > -np.inf:
        lo, hi = 0, P.fftb.shape[1]
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if P.fftb[c, mid] <= tseg:
                lo = mid
            else:
                hi = mid
        k = lo
    y = W.ffy
    wc_y, wt_y = -1.0, -1.0  # the filter whose output ``y`` holds (mounts alike in it share it)
    for j in range(n):
        gj = P.ffg[c, j]
        if gj == 0.0:
            W.Fa[j, 0] = 0.0
            W.Fa[j, 1] = 0.0
            W.Fa[j, 2] = 0.0
            continue
        wc = P.ffw[c, j]
        wt = P.ffwt[c, j]
        if wc != wc_y or wt != wt_y:
            e = np.exp(-wc * (t - P.fftb[c, k])) if k >= 0 else 0.0
            for q in range(6):
                y[q] = _follow(X, wc, q, wt)
                if k >= 0:
                    y[q] += P.ffA[c, j, k, q] * e
            wc_y, wt_y = wc, wt
        lim = P.fflim[c, j]
        for a in range(3):
            f = 0.0
            for q in range(6):
                f += P.ffD[c, j, a, q] * y[q]
            f *= gj
            if f > lim:
                f = lim
            elif f < -lim:
                f = -lim
            W.Fa[j, a] = f


@njit(cache=True, fastmath=False)
def feedforward_generalised(P, c, t, idx, W, out, o):
    """Write the LTI level's generalised force of the feedforward actuators at ``t`` (s) to
    ``out[o:o + 6]`` (N, N m): ``[sum f_j, sum d_j x f_j]``. Evaluates the stages at ``t`` into ``W``."""
    stage_state(P, c, t, idx, W.rho, W.vr, W.ar, W.jr)
    feedforward_forces(P, c, t, idx, W)
    for q in range(6):
        out[o + q] = 0.0
    for j in range(P.d.shape[1]):
        f0, f1, f2 = W.Fa[j, 0], W.Fa[j, 1], W.Fa[j, 2]
        m0, m1, m2 = cross(P.d[c, j, 0], P.d[c, j, 1], P.d[c, j, 2], f0, f1, f2)
        out[o] += f0
        out[o + 1] += f1
        out[o + 2] += f2
        out[o + 3] += m0
        out[o + 4] += m1
        out[o + 5] += m2
