"""The terms the accelerations read, kept in the workspace: per case and per time.

The equations of motion (``engine.kernels.dynamics``) evaluate each level's accelerations from terms packed
into the workspace ``W`` (``engine.kernels.params.Work``): the case's parameters and the LTV level's mount
operator, kept while the case runs (:func:`pack_case`), and what depends on time only, kept under a key of
case, level, time and profile pieces (:func:`time_terms`). The layout of those arrays is below.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from isolab.engine.kernels.excitation import floor_motion, lti_forcing, recorded_floor, stage_state
from isolab.engine.kernels.feedforward import feedforward_forces
from isolab.engine.kernels.mounts import linear_mounts
from isolab.engine.kernels.params import LTI, LTV
from isolab.engine.kernels.rotations import cross

# The accelerations are evaluated from three kinds of terms kept in the workspace ``W``, so that a step reads
# a handful of arrays (an array read from ``P`` or ``W`` counts a reference each time, which costs more than
# the arithmetic here):
# - per case (``W.cc``, ``W.cs``, ``W.cm``, ``W.cK``, keyed on the case in ``W.cc[0]``): the parameters of
#   case ``c`` packed from ``P`` and the LTV level's mount operator;
# - per time (``W.tc``, keyed in ``W.key`` on the case, level, exact time and pieces): what depends on time
#   only (the stages' kinematics, the floor, the feedforward forces, and from them the mass matrix and the
#   stages' sums). The two middle slopes of an RK4 step share them, and the last slope of a step is the
#   first of the next. Any call order is safe (an adaptive integrator asks at arbitrary times): a
#   different key recomputes;
# - the state.
# ``W.cc``: case, m_tot (kg), 1/m_tot, inertia (9, kg m^2), floor amplitude (3, m), angular frequency
# (3, rad/s), phase (3, rad), number of recorded floor samples, and ``V = sum f0_j d_j - g sum m rho_h``
# (3, N m): the preloads' and the home weights' first moment, whose moment ``V x R^T e_z`` the balanced
# preload convention (``Params.pbase`` 2) takes out.
CC_MT, CC_IMT, CC_IN, CC_FA, CC_FW, CC_FP, CC_NF, CC_V = 1, 2, 3, 12, 15, 18, 21, 22
CC_SIZE = 25
# ``W.cs`` (m, 8 + 5 K): per stage mass (kg), parent, axis (3), home (3, m), then its pieces' start times
# (K, s), positions (m), velocities (m/s), accelerations (m/s^2) and jerks (m/s^3).
CS_E, CS_H, CS_P = 2, 5, 8
# ``W.cm`` (n, 11): per mount lever arm (3, m), stiffness (3, N/m), damping (3, N s/m), sky-hook, preload (N).
CM_D, CM_K, CM_C, CM_SKY, CM_F0 = 0, 3, 6, 9, 10
CM_WIDTH = 11
"""Columns of ``W.cm`` for mounts along the floor's axes."""
CM_Q = 11
"""Where a mount's own axes (``Params.qm``, 9 values, row-major) start in ``W.cm``, when some mount has
them."""
# Rows of ``W.tc`` (20, 3): the stages' sums at the time of ``W.key``.
TC_SR, TC_SV, TC_SA, TC_TA, TC_WM, TC_SFA, TC_DFA, TC_XF, TC_VF, TC_BT, TC_BR = range(11)
"""``sum m rho`` (kg m), ``sum m v_rel`` (kg m/s), ``sum m a_rel`` (N), ``sum m rho x a_rel`` (N m), the
stages' weight moment about home ``sum m (rho - rho_h) x g`` (N m, linear levels), the feedforward forces
``sum f_j`` (N) and moments ``sum d_j x f_j`` (N m), the floor displacement (m) and velocity (m/s), the known
part of the generalised force (N, N m; the LTI level: of the accelerations, m/s^2, rad/s^2)."""
TC_GW, TC_JT, TC_SI = 11, 14, 17
"""First rows of the (3, 3) blocks of ``W.tc``: ``sum m ((rho . v_rel) 1 - v_rel rho^T)`` (kg m^2/s), the
rotary mass of base and stages ``J`` (kg m^2) and the inverse of the mass matrix's Schur complement
``S = J - [SR]x^T [SR]x / m_tot`` (1/(kg m^2))."""


@njit(cache=True, fastmath=False)
def _pack_case(P, c, W):
    """Pack case ``c``'s parameters into ``W.cc``, ``W.cs``, ``W.cm`` and its LTV mount operator into
    ``W.cK`` (12, 6): row ``k`` is the generalised force of :func:`linear_mounts` for the unit state
    ``x = e_k`` without floor motion."""
    cc, cs, cm = W.cc, W.cs, W.cm
    cc[CC_MT] = P.mtot[c]
    cc[CC_IMT] = 1.0 / P.mtot[c]
    for a in range(3):
        for b in range(3):
            cc[CC_IN + 3 * a + b] = P.inertia[c, a, b]
        cc[CC_FA + a] = P.famp[c, a]
        cc[CC_FW + a] = P.fomega[c, a]
        cc[CC_FP + a] = P.fphase[c, a]
    cc[CC_NF] = P.ft.shape[0]
    K = P.pt.shape[2]
    for i in range(P.sm.shape[1]):
        cs[i, 0] = P.sm[c, i]
        cs[i, 1] = P.parent[i]
        for a in range(3):
            cs[i, CS_E + a] = P.e[c, i, a]
            cs[i, CS_H + a] = P.rho_h[c, i, a]
        for k in range(K):
            cs[i, CS_P + k] = P.pt[c, i, k]
            cs[i, CS_P + K + k] = P.ps[c, i, k]
            cs[i, CS_P + 2 * K + k] = P.pv[c, i, k]
            cs[i, CS_P + 3 * K + k] = P.pa[c, i, k]
            cs[i, CS_P + 4 * K + k] = P.pj[c, i, k]
    for j in range(P.d.shape[1]):
        for a in range(3):
            cm[j, CM_D + a] = P.d[c, j, a]
            cm[j, CM_K + a] = P.k[c, j, a]
            cm[j, CM_C + a] = P.cd[c, j, a]
        cm[j, CM_SKY] = P.sky[c, j]
        cm[j, CM_F0] = P.f0[c, j]
        if cm.shape[1] > CM_Q:
            for a in range(3):
                for b in range(3):
                    cm[j, CM_Q + 3 * a + b] = P.qm[c, j, a, b]
    for a in range(3):
        v = 0.0
        for j in range(P.d.shape[1]):
            v += P.f0[c, j] * P.d[c, j, a]
        for i in range(P.sm.shape[1]):
            v -= P.g * P.sm[c, i] * P.rho_h[c, i, a]
        cc[CC_V + a] = v
    x = np.zeros(12)
    z = np.zeros(3)
    out = np.zeros(6)
    for k in range(12):
        x[k] = 1.0
        linear_mounts(P, c, x, z, z, W.R, W.F, out)
        for q in range(6):
            W.cK[k, q] = out[q]
        x[k] = 0.0
    for k in range(P.zG.shape[2]):  # the extra linear states' generalised force (``Params.zG``)
        for q in range(6):
            W.cK[12 + k, q] = P.zG[c, q, k]
    cc[0] = c


@njit(cache=True, fastmath=False)
def moving_terms(level, g, cc, cs, cm, sw, tc):
    """The time-only terms of the LTV and nonlinear levels in ``tc`` from the stages' state ``sw`` and the
    floor (rows ``TC_XF``, ``TC_VF``) and feedforward (``TC_SFA``, ``TC_DFA``) rows already in ``tc``. Returns
    False when the mass matrix is not positive definite."""
    # the stages' sums, each in a register through the loop (the same sums, in the same order, as into
    # ``tc``: the rows of ``tc`` may alias the stages' arrays for all the compiler knows, so each sum
    # would be a load and a store)
    sr0 = sr1 = sr2 = sv0 = sv1 = sv2 = sa0 = sa1 = sa2 = ta0 = ta1 = ta2 = wm0 = wm1 = 0.0
    gw00 = gw01 = gw02 = gw10 = gw11 = gw12 = gw20 = gw21 = gw22 = 0.0
    j00, j01, j02 = cc[CC_IN], cc[CC_IN + 1], cc[CC_IN + 2]
    j10, j11, j12 = cc[CC_IN + 3], cc[CC_IN + 4], cc[CC_IN + 5]
    j20, j21, j22 = cc[CC_IN + 6], cc[CC_IN + 7], cc[CC_IN + 8]
    for i in range(cs.shape[0]):
        m = cs[i, 0]
        r0, r1, r2 = sw[i, 0], sw[i, 1], sw[i, 2]
        v0, v1, v2 = sw[i, 3], sw[i, 4], sw[i, 5]
        a0, a1, a2 = sw[i, 6], sw[i, 7], sw[i, 8]
        sr0 += m * r0
        sr1 += m * r1
        sr2 += m * r2
        sv0 += m * v0
        sv1 += m * v1
        sv2 += m * v2
        sa0 += m * a0
        sa1 += m * a1
        sa2 += m * a2
        h0, h1, h2 = cross(r0, r1, r2, a0, a1, a2)
        ta0 += m * h0
        ta1 += m * h1
        ta2 += m * h2
        # (rho - rho_h) x (0, 0, -g)
        wm0 -= m * (r1 - cs[i, CS_H + 1]) * g
        wm1 += m * (r0 - cs[i, CS_H]) * g
        # G_w += m ((rho . v) 1 - v rho^T); J += m (|rho|^2 1 - rho rho^T)
        rv = m * (r0 * v0 + r1 * v1 + r2 * v2)
        gw00 += rv - m * v0 * r0
        gw01 -= m * v0 * r1
        gw02 -= m * v0 * r2
        gw10 -= m * v1 * r0
        gw11 += rv - m * v1 * r1
        gw12 -= m * v1 * r2
        gw20 -= m * v2 * r0
        gw21 -= m * v2 * r1
        gw22 += rv - m * v2 * r2
        j00 += m * (r1 * r1 + r2 * r2)
        j11 += m * (r0 * r0 + r2 * r2)
        j22 += m * (r0 * r0 + r1 * r1)
        j01 -= m * r0 * r1
        j10 -= m * r0 * r1
        j02 -= m * r0 * r2
        j20 -= m * r0 * r2
        j12 -= m * r1 * r2
        j21 -= m * r1 * r2
    tc[TC_SR, 0], tc[TC_SR, 1], tc[TC_SR, 2] = sr0, sr1, sr2
    tc[TC_SV, 0], tc[TC_SV, 1], tc[TC_SV, 2] = sv0, sv1, sv2
    tc[TC_SA, 0], tc[TC_SA, 1], tc[TC_SA, 2] = sa0, sa1, sa2
    tc[TC_TA, 0], tc[TC_TA, 1], tc[TC_TA, 2] = ta0, ta1, ta2
    tc[TC_WM, 0], tc[TC_WM, 1], tc[TC_WM, 2] = wm0, wm1, 0.0
    for r in range(TC_BT, TC_GW):
        for q in range(3):
            tc[r, q] = 0.0
    tc[TC_GW, 0], tc[TC_GW, 1], tc[TC_GW, 2] = gw00, gw01, gw02
    tc[TC_GW + 1, 0], tc[TC_GW + 1, 1], tc[TC_GW + 1, 2] = gw10, gw11, gw12
    tc[TC_GW + 2, 0], tc[TC_GW + 2, 1], tc[TC_GW + 2, 2] = gw20, gw21, gw22
    tc[TC_JT, 0], tc[TC_JT, 1], tc[TC_JT, 2] = j00, j01, j02
    tc[TC_JT + 1, 0], tc[TC_JT + 1, 1], tc[TC_JT + 1, 2] = j10, j11, j12
    tc[TC_JT + 2, 0], tc[TC_JT + 2, 1], tc[TC_JT + 2, 2] = j20, j21, j22
    # Schur complement of the translation block: S = J - X^T X / m_tot with X = -[SR]x,
    # X^T X = |SR|^2 1 - SR SR^T; positive definite when its leading minors are (Sylvester), and its inverse
    # from its cofactors: one division, where a Cholesky factor took three square roots and three divisions
    # one after the other, and every solve with it two triangular sweeps
    if not cc[CC_MT] > 0.0:
        return False
    imt = cc[CC_IMT]
    s0, s1, s2 = tc[TC_SR, 0], tc[TC_SR, 1], tc[TC_SR, 2]
    a00 = j00 - (s1 * s1 + s2 * s2) * imt
    a11 = j11 - (s0 * s0 + s2 * s2) * imt
    a22 = j22 - (s0 * s0 + s1 * s1) * imt
    a01 = j10 + s1 * s0 * imt
    a02 = j20 + s2 * s0 * imt
    a12 = j21 + s2 * s1 * imt
    i00 = a11 * a22 - a12 * a12
    i01 = a02 * a12 - a01 * a22
    i02 = a01 * a12 - a02 * a11
    i11 = a00 * a22 - a02 * a02
    i12 = a01 * a02 - a00 * a12
    i22 = a00 * a11 - a01 * a01
    det = a00 * i00 + a01 * i01 + a02 * i02
    if not (a00 > 0.0 and i22 > 0.0 and det > 0.0):
        return False
    r = 1.0 / det
    tc[TC_SI, 0], tc[TC_SI, 1], tc[TC_SI, 2] = i00 * r, i01 * r, i02 * r
    tc[TC_SI + 1, 0], tc[TC_SI + 1, 1], tc[TC_SI + 1, 2] = i01 * r, i11 * r, i12 * r
    tc[TC_SI + 2, 0], tc[TC_SI + 2, 1], tc[TC_SI + 2, 2] = i02 * r, i12 * r, i22 * r
    if level == LTV:
        # the known part of the generalised force: floor through the mounts, stages, feedforward
        x0, x1, x2 = tc[TC_XF, 0], tc[TC_XF, 1], tc[TC_XF, 2]
        y0, y1, y2 = tc[TC_VF, 0], tc[TC_VF, 1], tc[TC_VF, 2]
        if x0 != 0.0 or x1 != 0.0 or x2 != 0.0 or y0 != 0.0 or y1 != 0.0 or y2 != 0.0:
            for j in range(cm.shape[0]):
                rel = 1.0 - cm[j, CM_SKY]
                p0 = cm[j, CM_K] * x0 + rel * cm[j, CM_C] * y0
                p1 = cm[j, CM_K + 1] * x1 + rel * cm[j, CM_C + 1] * y1
                p2 = cm[j, CM_K + 2] * x2 + rel * cm[j, CM_C + 2] * y2
                m0, m1, m2 = cross(cm[j, CM_D], cm[j, CM_D + 1], cm[j, CM_D + 2], p0, p1, p2)
                tc[TC_BT, 0] += p0
                tc[TC_BT, 1] += p1
                tc[TC_BT, 2] += p2
                tc[TC_BR, 0] += m0
                tc[TC_BR, 1] += m1
                tc[TC_BR, 2] += m2
        for q in range(3):
            tc[TC_BT, q] += tc[TC_SFA, q] - tc[TC_SA, q]
            tc[TC_BR, q] += tc[TC_DFA, q] + tc[TC_WM, q] - tc[TC_TA, q]
    return True


@njit(cache=True, fastmath=False)
def _lti_terms(P, c, W):
    """The LTI level's accelerations due to the known inputs, ``M^-1 f`` (m/s^2, rad/s^2), into the rows
    ``TC_BT``, ``TC_BR`` of ``W.tc``, from the stages, floor and feedforward state in ``W``."""
    lti_forcing(P, c, W.rho, W.ar, W.xf, W.vf, W.f)
    if P.ffon:  # the feedforward actuators (W.Fa): a known input too
        for j in range(P.d.shape[1]):
            f0, f1, f2 = W.Fa[j, 0], W.Fa[j, 1], W.Fa[j, 2]
            m0, m1, m2 = cross(P.d[c, j, 0], P.d[c, j, 1], P.d[c, j, 2], f0, f1, f2)
            W.f[0] += f0
            W.f[1] += f1
            W.f[2] += f2
            W.f[3] += m0
            W.f[4] += m1
            W.f[5] += m2
    for i in range(6):
        s = 0.0
        for j in range(6):
            s += P.minv[c, i, j] * W.f[j]
        W.tc[TC_BT + i // 3, i % 3] = s


@njit(cache=True, fastmath=False)
def stages_and_floor(t, idx, cc, cs, sw, tc):
    """First part of evaluating the time-only terms of the LTV and nonlinear levels at ``t`` (s) on the
    pieces ``idx`` (:func:`time_terms`): the stages' positions (m), velocities (m/s) and accelerations
    (m/s^2) relative to the c.g. into ``sw`` (m, 9), the floor's sine motion
    into the rows ``TC_XF``, ``TC_VF`` of ``tc``, the feedforward rows cleared. Then
    :func:`recorded_and_feedforward` when the case has either (:func:`extra_inputs`), and
    :func:`moving_terms`."""
    # the stages (as :func:`stage_state`, from the packed case ``cs``)
    m = cs.shape[0]
    K = (cs.shape[1] - CS_P) // 5
    for i in range(m):
        k = idx[i]
        if k < 0:
            j = 0.0
            a = 0.0
            v = 0.0
            s = cs[i, CS_P + K]
        else:
            tau = t - cs[i, CS_P + k]
            j = cs[i, CS_P + 4 * K + k]
            a0 = cs[i, CS_P + 3 * K + k]
            a = a0 + j * tau
            v = cs[i, CS_P + 2 * K + k] + (a0 + 0.5 * j * tau) * tau
            s = cs[i, CS_P + K + k] + (cs[i, CS_P + 2 * K + k] + (0.5 * a0 + j * tau / 6.0) * tau) * tau
        p = int(cs[i, 1])
        for dd in range(3):
            ed = cs[i, CS_E + dd]
            sw[i, dd] = cs[i, CS_H + dd] + s * ed
            sw[i, 3 + dd] = v * ed
            sw[i, 6 + dd] = a * ed
            if p >= 0:
                sw[i, dd] += sw[p, dd] - cs[p, CS_H + dd]
                sw[i, 3 + dd] += sw[p, 3 + dd]
                sw[i, 6 + dd] += sw[p, 6 + dd]
    for dd in range(3):
        amp = cc[CC_FA + dd]
        if amp == 0.0:
            tc[TC_XF, dd] = 0.0
            tc[TC_VF, dd] = 0.0
        else:
            w = cc[CC_FW + dd]
            arg = w * t + cc[CC_FP + dd]
            tc[TC_XF, dd] = amp * np.sin(arg)
            tc[TC_VF, dd] = amp * w * np.cos(arg)
        tc[TC_SFA, dd] = 0.0
        tc[TC_DFA, dd] = 0.0


@njit(cache=True, inline="always")
def extra_inputs(ffon, cc):
    """Whether the case has a recorded floor motion or feedforward actuators (packed case ``cc``)."""
    return ffon or cc[CC_NF] > 0


@njit(cache=True, fastmath=False)
def recorded_and_feedforward(P, c, t, idx, W, cm, tc):
    """Add the recorded floor motion and the feedforward actuators' forces and moments at ``t`` (s) to
    ``tc`` (after :func:`stages_and_floor`)."""
    if P.ft.shape[0] > 0:
        recorded_floor(P, c, t, tc[TC_XF], tc[TC_VF])
    if P.ffon:
        stage_state(P, c, t, idx, W.rho, W.vr, W.ar, W.jr)
        feedforward_forces(P, c, t, idx, W)
        Fa = W.Fa
        for j in range(cm.shape[0]):
            f0, f1, f2 = Fa[j, 0], Fa[j, 1], Fa[j, 2]
            m0, m1, m2 = cross(cm[j, CM_D], cm[j, CM_D + 1], cm[j, CM_D + 2], f0, f1, f2)
            tc[TC_SFA, 0] += f0
            tc[TC_SFA, 1] += f1
            tc[TC_SFA, 2] += f2
            tc[TC_DFA, 0] += m0
            tc[TC_DFA, 1] += m1
            tc[TC_DFA, 2] += m2


@njit(cache=True, inline="always")
def stages_unchanged(c, level, key, swt, sw):
    """Whether the stages' state ``swt`` (m, 9) just evaluated (:func:`stages_and_floor`) is bit for bit
    ``sw``, the one the time-only terms keyed in ``key`` were evaluated from, for case ``c`` and ``level``:
    then :func:`moving_terms` (at the nonlinear level a function of the case and ``sw`` alone) would give
    the same terms again. Every evaluation of the terms writes ``sw`` just before them."""
    if key[0] != c or key[1] != level:
        return False
    for i in range(sw.shape[0]):
        for q in range(sw.shape[1]):
            a, b = swt[i, q], sw[i, q]
            if a != b or (a == 0.0 and np.copysign(1.0, a) != np.copysign(1.0, b)):
                return False
    return True


@njit(cache=True, inline="always")
def terms_at_rest(c, level, idx, key, cc, cs):
    """Whether the time-only terms keyed in ``key`` (``W.key``) hold at any time on the pieces ``idx`` of
    case ``c`` at ``level`` (packed in ``cc``, ``cs``; no recorded floor or feedforward): the same case,
    level and pieces, every stage on a piece where it stands still (no velocity, acceleration or jerk) and
    no floor sine. The stages' state there is its piece's start, bit for bit, at any time: so are the
    terms."""
    if key[0] != c or key[1] != level:
        return False
    for dd in range(3):
        if cc[CC_FA + dd] != 0.0:
            return False
    K = (cs.shape[1] - CS_P) // 5
    for i in range(idx.shape[0]):
        k = idx[i]
        if key[4 + i] != k:
            return False
        if k >= 0:
            if (
                cs[i, CS_P + 2 * K + k] != 0.0
                or cs[i, CS_P + 3 * K + k] != 0.0
                or cs[i, CS_P + 4 * K + k] != 0.0
            ):
                return False
    return True


@njit(cache=True, fastmath=False)
def key_holds(c, level, t, idx, key):
    """Whether the time-only terms with the key ``key`` (``W.key``) are those of case ``c`` and ``level``
    at ``t`` (s) on the pieces ``idx``."""
    if key[0] != c or key[1] != level or key[2] != t:
        return False
    for i in range(idx.shape[0]):
        if key[4 + i] != idx[i]:
            return False
    return True


@njit(cache=True, fastmath=False)
def set_key(c, level, t, ok, idx, key):
    """Key the time-only terms just evaluated (see :func:`key_holds`); ``ok``: their mass matrix is
    positive definite. Returns ``ok``."""
    key[0] = c
    key[1] = level
    key[2] = t
    key[3] = 1.0 if ok else 0.0
    for i in range(idx.shape[0]):
        key[4 + i] = idx[i]
    return ok


@njit(cache=True, fastmath=False)
def pack_case(P, c, W, cc):
    """Make the workspace's per-case terms (``W.cc`` bound as ``cc``, ``W.cs``, ``W.cm``, ``W.cK``) those
    of case ``c``."""
    if cc[0] != c:
        _pack_case(P, c, W)


@njit(cache=True, fastmath=False)
def time_terms(P, c, level, t, idx, W):
    """Make the workspace's time-only terms (``W.tc``) those of case ``c`` at ``t`` (s) on the pieces
    ``idx`` for ``level`` (and its per-case terms those of case ``c``): kept when its key says so, else
    evaluated. Returns False when the mass matrix is not positive definite."""
    key, cc, tc = W.key, W.cc, W.tc
    pack_case(P, c, W, cc)
    if key_holds(c, level, t, idx, key):
        return key[3] != 0.0
    if level == LTI:
        stage_state(P, c, t, idx, W.rho, W.vr, W.ar, W.jr)
        floor_motion(P, c, t, W.xf, W.vf)
        if P.ffon:
            feedforward_forces(P, c, t, idx, W)
        _lti_terms(P, c, W)
        return set_key(c, level, t, True, idx, key)
    cs, cm, sw = W.cs, W.cm, W.sw
    stages_and_floor(t, idx, cc, cs, sw, tc)
    if extra_inputs(P.ffon, cc):
        recorded_and_feedforward(P, c, t, idx, W, cm, tc)
    return set_key(c, level, t, moving_terms(level, P.g, cc, cs, cm, sw, tc), idx, key)
