"""Equations of motion of a rigid machine base on isolators, shaken by its own stages: each fidelity level's
accelerations and the state's time derivative.

Numba functions shared by the integrators. A case's parameters come in a ``Params`` named tuple of arrays
(case dimension first, ``engine.kernels.params``; ``engine.model.params`` fills it); ``c`` is the case index.
The state of the linear levels is ``x = [u(3), theta(3), v(3), w(3)]``: c.g. displacement (m), small
rotation about X, Y, Z (rad), their rates (m/s, rad/s). The nonlinear level uses ``x = [u(3), q(4), v(3),
w_b(3)]`` with a unit quaternion ``q`` (body to floor) and the body-frame angular velocity ``w_b``.

Translation is written in the floor frame, rotation about the machine c.g. in the body frame. Stages are
point masses moving along axes fixed in the machine (``excitation``); their reaction on the machine is
``m g - m a_abs``. Isolator forces are ``-K delta - C delta_dot`` per floor axis about the preloaded reference
state (``mounts``); the preload is vertical and balances every weight with the stages at home (at the
nonlinear level it may turn with the base instead, ``Params.pbase``). Active mounts may add actuator forces
that feed the stages' inertial wrench forward (``feedforward``), a known function of time like the stages'
own. The terms that depend on the case or on time only are kept in the workspace (``cached_terms``); the
modules named are those of ``engine.kernels``.
"""

from __future__ import annotations

from numba import njit

from isolab.engine.kernels.cached_terms import (
    CC_IMT,
    CC_V,
    CM_C,
    CM_D,
    CM_F0,
    CM_K,
    CM_Q,
    CM_SKY,
    TC_BR,
    TC_BT,
    TC_DFA,
    TC_GW,
    TC_JT,
    TC_SA,
    TC_SFA,
    TC_SI,
    TC_SR,
    TC_SV,
    TC_TA,
    TC_VF,
    TC_XF,
    time_terms,
)
from isolab.engine.kernels.params import LTI, LTV, NONLINEAR
from isolab.engine.kernels.rotations import cross, direction_matrix


@njit(cache=True, fastmath=False)
def _solve_schur(tc, q0, q1, q2):
    """``S^-1 q`` with the inverse of the Schur complement ``S`` in ``tc`` (rows ``TC_SI``)."""
    z0 = tc[TC_SI, 0] * q0 + tc[TC_SI, 1] * q1 + tc[TC_SI, 2] * q2
    z1 = tc[TC_SI + 1, 0] * q0 + tc[TC_SI + 1, 1] * q1 + tc[TC_SI + 1, 2] * q2
    z2 = tc[TC_SI + 2, 0] * q0 + tc[TC_SI + 2, 1] * q1 + tc[TC_SI + 2, 2] * q2
    return z0, z1, z2


@njit(cache=True, fastmath=False)
def accel_lti(P, c, x, W):
    """Accelerations ``W.acc`` (6,) of the LTI level: ``A21 x + A22 v + M^-1 f`` with the stages and the
    floor as known inputs (``M^-1 f`` from :func:`time_terms`). Always True."""
    tc, a21, a22 = W.tc, P.a21, P.a22
    for i in range(6):
        s = tc[TC_BT + i // 3, i % 3]
        for j in range(6):
            s += a21[c, i, j] * x[j] + a22[c, i, j] * x[6 + j]
        W.acc[i] = s
    return True


@njit(cache=True, fastmath=False)
def accel_ltv(P, c, x, W):
    """Accelerations ``W.acc`` (6,) of the LTV level: small rotations, mass matrix and weight moments
    following the stages' travel, Coriolis terms of the stages (time-only terms from
    :func:`time_terms`). The generalised force is linear in the state: the mounts' operator ``W.cK``,
    the known part, and the stages' terms that multiply the rotation or its rate. Always True (the mass
    matrix was checked with the time-only terms)."""
    ltv_acc(x, W.tc, W.cK, W.cc, P.g, P.ffon, P.gstiff, W.acc)
    return True


@njit(cache=True, inline="always")
def ltv_acc(x, tc, K, cc, g, ffon, gstiff, acc):
    """:func:`accel_ltv` on the workspace's arrays: ``acc`` (6,) from the time-only terms ``tc``, the
    mount operator ``K`` (12, 6), the packed case ``cc`` and gravity ``g`` (m/s^2)."""
    f0, f1, f2 = tc[TC_BT, 0], tc[TC_BT, 1], tc[TC_BT, 2]
    r0, r1, r2 = tc[TC_BR, 0], tc[TC_BR, 1], tc[TC_BR, 2]
    for k in range(K.shape[0]):  # the base's 12 rows, then the extra linear states' (``Params.zG``)
        xk = x[k]
        f0 += K[k, 0] * xk
        f1 += K[k, 1] * xk
        f2 += K[k, 2] * xk
        r0 += K[k, 3] * xk
        r1 += K[k, 4] * xk
        r2 += K[k, 5] * xk
    t0, t1, t2 = x[3], x[4], x[5]
    w0, w1, w2 = x[9], x[10], x[11]
    # translation: -sum m (theta x a_rel + 2 w x v_rel) (+ theta x sum f_j, the actuators turn with the base)
    p0, p1, p2 = cross(tc[TC_SA, 0], tc[TC_SA, 1], tc[TC_SA, 2], t0, t1, t2)
    q0, q1, q2 = cross(w0, w1, w2, tc[TC_SV, 0], tc[TC_SV, 1], tc[TC_SV, 2])
    f0 += p0 - 2.0 * q0
    f1 += p1 - 2.0 * q1
    f2 += p2 - 2.0 * q2
    if ffon:
        p0, p1, p2 = cross(t0, t1, t2, tc[TC_SFA, 0], tc[TC_SFA, 1], tc[TC_SFA, 2])
        f0 += p0
        f1 += p1
        f2 += p2
    # rotation: -2 sum m rho x (w x v_rel) = -2 G_w w
    r0 -= 2.0 * (tc[TC_GW, 0] * w0 + tc[TC_GW, 1] * w1 + tc[TC_GW, 2] * w2)
    r1 -= 2.0 * (tc[TC_GW + 1, 0] * w0 + tc[TC_GW + 1, 1] * w1 + tc[TC_GW + 1, 2] * w2)
    r2 -= 2.0 * (tc[TC_GW + 2, 0] * w0 + tc[TC_GW + 2, 1] * w1 + tc[TC_GW + 2, 2] * w2)
    s0, s1, s2 = tc[TC_SR, 0], tc[TC_SR, 1], tc[TC_SR, 2]
    if gstiff:
        # sum m rho x (theta x (0, 0, g)) = g (SR_z theta - e_z (SR . theta))
        r0 += g * s2 * t0
        r1 += g * s2 * t1
        r2 -= g * (s0 * t0 + s1 * t1)
    # M = [[m_tot 1, X], [X^T, J]], X = -[SR]x: the rotation from the Schur complement
    # (J - X^T X / m_tot) alpha = f_r - X^T f_t / m_tot, then m_tot a = f_t - X alpha
    imt = cc[CC_IMT]
    c0, c1, c2 = cross(s0, s1, s2, f0, f1, f2)
    a0, a1, a2 = _solve_schur(tc, r0 - c0 * imt, r1 - c1 * imt, r2 - c2 * imt)
    u0, u1, u2 = cross(s0, s1, s2, a0, a1, a2)
    acc[0] = (f0 + u0) * imt
    acc[1] = (f1 + u1) * imt
    acc[2] = (f2 + u2) * imt
    acc[3] = a0
    acc[4] = a1
    acc[5] = a2


@njit(cache=True, fastmath=False)
def accel_nonlinear(P, c, x, W):
    """Accelerations ``W.acc`` (6,) of the nonlinear level: finite rotation (quaternion), the preload
    turning with the base, the gyroscopic term and the stages' full relative kinematics (time-only terms
    from :func:`time_terms`). Always True (the mass matrix was checked with the time-only terms)."""
    nonlinear_acc(x, W.tc, W.cc, W.cm, W.R, W.F, W.acc, P.g, P.pbase)
    return True


@njit(cache=True, inline="always")
def nonlinear_acc(x, tc, cc, cm, R, F, acc, g, pbase):
    """:func:`accel_nonlinear` on the workspace's arrays (``R`` (3, 3), ``F`` (n, 3) scratch; the packed
    case ``cc``, ``cm``)."""
    # the rotation of the quaternion's direction: an RK4 stage state's quaternion is off unit length by
    # about (h |w| / 2)^2, and R orthogonal keeps every transpose below an inverse
    direction_matrix(x[3], x[4], x[5], x[6], R)
    u0, u1, u2 = x[0], x[1], x[2]
    v0, v1, v2 = x[7], x[8], x[9]
    w0, w1, w2 = x[10], x[11], x[12]
    x0, x1, x2 = tc[TC_XF, 0], tc[TC_XF, 1], tc[TC_XF, 2]
    y0, y1, y2 = tc[TC_VF, 0], tc[TC_VF, 1], tc[TC_VF, 2]
    # the base's rate turned to the floor frame: a point's velocity about the c.g. R (w x d) is (R w) x (R d)
    W0 = R[0, 0] * w0 + R[0, 1] * w1 + R[0, 2] * w2
    W1 = R[1, 0] * w0 + R[1, 1] * w1 + R[1, 2] * w2
    W2 = R[2, 0] * w0 + R[2, 1] * w1 + R[2, 2] * w2
    f0 = f1 = f2 = 0.0
    r0 = r1 = r2 = 0.0
    M0 = M1 = M2 = 0.0  # the mounts' moment about the c.g. in the floor frame, turned to the body below
    # isolators (``isolator_forces``): force (floor frame) and moment (body frame) with the vertical preload
    for j in range(cm.shape[0]):
        d0, d1, d2 = cm[j, CM_D], cm[j, CM_D + 1], cm[j, CM_D + 2]
        # the mount's arm R d in the floor frame, and ``mount_offset``'s (R - I) d
        a0 = R[0, 0] * d0 + R[0, 1] * d1 + R[0, 2] * d2
        a1 = R[1, 0] * d0 + R[1, 1] * d1 + R[1, 2] * d2
        a2 = R[2, 0] * d0 + R[2, 1] * d1 + R[2, 2] * d2
        o0, o1, o2 = a0 - d0, a1 - d1, a2 - d2
        q0, q1, q2 = cross(W0, W1, W2, a0, a1, a2)
        rel = 1.0 - cm[j, CM_SKY]
        if cm.shape[1] > CM_Q:  # the mount's own axes (``engine.kernels.mounts.oriented_force``)
            e0, e1, e2 = u0 + o0 - x0, u1 + o1 - x1, u2 + o2 - x2
            s0, s1, s2 = v0 + q0 - rel * y0, v1 + q1 - rel * y1, v2 + q2 - rel * y2
            Q = cm[j, CM_Q : CM_Q + 9]
            n0 = Q[0] * e0 + Q[3] * e1 + Q[6] * e2
            n1 = Q[1] * e0 + Q[4] * e1 + Q[7] * e2
            n2 = Q[2] * e0 + Q[5] * e1 + Q[8] * e2
            p0 = Q[0] * s0 + Q[3] * s1 + Q[6] * s2
            p1 = Q[1] * s0 + Q[4] * s1 + Q[7] * s2
            p2 = Q[2] * s0 + Q[5] * s1 + Q[8] * s2
            g0 = -cm[j, CM_K] * n0 - cm[j, CM_C] * p0
            g1 = -cm[j, CM_K + 1] * n1 - cm[j, CM_C + 1] * p1
            g2 = -cm[j, CM_K + 2] * n2 - cm[j, CM_C + 2] * p2
            F0 = Q[0] * g0 + Q[1] * g1 + Q[2] * g2
            F1 = Q[3] * g0 + Q[4] * g1 + Q[5] * g2
            F2 = Q[6] * g0 + Q[7] * g1 + Q[8] * g2
        else:
            F0 = -cm[j, CM_K] * (u0 + o0 - x0) - cm[j, CM_C] * (v0 + q0 - rel * y0)
            F1 = -cm[j, CM_K + 1] * (u1 + o1 - x1) - cm[j, CM_C + 1] * (v1 + q1 - rel * y1)
            F2 = -cm[j, CM_K + 2] * (u2 + o2 - x2) - cm[j, CM_C + 2] * (v2 + q2 - rel * y2)
        f0 += F0
        f1 += F1
        f2 += F2
        p = cm[j, CM_F0]
        # the moment d x R^T T of the mount's force T in the body is R^T ((R d) x T)
        if pbase == 1:
            # the preload turns with the base: (0, 0, p) in the body, R (0, 0, p) in the floor frame;
            # its moment d x (0, 0, p) stays in the body
            f0 += p * R[0, 2]
            f1 += p * R[1, 2]
            f2 += p * (R[2, 2] - 1.0)
            r0 += p * d1
            r1 -= p * d0
            T2 = F2
        else:
            T2 = F2 + p
        m0, m1, m2 = cross(a0, a1, a2, F0, F1, T2)
        M0 += m0
        M1 += m1
        M2 += m2
    r0 += R[0, 0] * M0 + R[1, 0] * M1 + R[2, 0] * M2
    r1 += R[0, 1] * M0 + R[1, 1] * M1 + R[2, 1] * M2
    r2 += R[0, 2] * M0 + R[1, 2] * M1 + R[2, 2] * M2
    if pbase == 2:
        # balanced: the preloads and the home weights cancel in every attitude; take out their moment
        # V x R^T e_z (what is left of the weights is the stages' travel, in the weight moment below)
        m0, m1, m2 = cross(cc[CC_V], cc[CC_V + 1], cc[CC_V + 2], R[2, 0], R[2, 1], R[2, 2])
        r0 -= m0
        r1 -= m1
        r2 -= m2
    s0, s1, s2 = tc[TC_SR, 0], tc[TC_SR, 1], tc[TC_SR, 2]
    # body-frame forces: feedforward actuators (fixed in the machine) and the stages'
    # -sum m (w x (w x rho) + 2 w x v_rel + a_rel), turned to the floor frame
    o0, o1, o2 = cross(w0, w1, w2, s0, s1, s2)
    z0, z1, z2 = cross(w0, w1, w2, o0, o1, o2)
    c0, c1, c2 = cross(w0, w1, w2, tc[TC_SV, 0], tc[TC_SV, 1], tc[TC_SV, 2])
    k0 = tc[TC_SFA, 0] - z0 - 2.0 * c0 - tc[TC_SA, 0]
    k1 = tc[TC_SFA, 1] - z1 - 2.0 * c1 - tc[TC_SA, 1]
    k2 = tc[TC_SFA, 2] - z2 - 2.0 * c2 - tc[TC_SA, 2]
    f0 += R[0, 0] * k0 + R[0, 1] * k1 + R[0, 2] * k2
    f1 += R[1, 0] * k0 + R[1, 1] * k1 + R[1, 2] * k2
    f2 += R[2, 0] * k0 + R[2, 1] * k1 + R[2, 2] * k2
    # gyroscopic term of base and stages -w x (J w) (the stages' share is sum m rho x (w x (w x rho))),
    # the stages' -sum m rho x (a_rel + 2 w x v_rel) and weight moment SR x R^T (0, 0, -g)
    I0 = tc[TC_JT, 0] * w0 + tc[TC_JT, 1] * w1 + tc[TC_JT, 2] * w2
    I1 = tc[TC_JT + 1, 0] * w0 + tc[TC_JT + 1, 1] * w1 + tc[TC_JT + 1, 2] * w2
    I2 = tc[TC_JT + 2, 0] * w0 + tc[TC_JT + 2, 1] * w1 + tc[TC_JT + 2, 2] * w2
    y0, y1, y2 = cross(w0, w1, w2, I0, I1, I2)
    h0, h1, h2 = cross(s0, s1, s2, -g * R[2, 0], -g * R[2, 1], -g * R[2, 2])
    g0 = tc[TC_GW, 0] * w0 + tc[TC_GW, 1] * w1 + tc[TC_GW, 2] * w2
    g1 = tc[TC_GW + 1, 0] * w0 + tc[TC_GW + 1, 1] * w1 + tc[TC_GW + 1, 2] * w2
    g2 = tc[TC_GW + 2, 0] * w0 + tc[TC_GW + 2, 1] * w1 + tc[TC_GW + 2, 2] * w2
    r0 += tc[TC_DFA, 0] - y0 - tc[TC_TA, 0] - 2.0 * g0 + h0
    r1 += tc[TC_DFA, 1] - y1 - tc[TC_TA, 1] - 2.0 * g1 + h1
    r2 += tc[TC_DFA, 2] - y2 - tc[TC_TA, 2] - 2.0 * g2 + h2
    # M = [[m_tot 1, R X], [X^T R^T, J]], X = -[SR]x: with b = R^T f_t and R^T R = 1 the rotation solves
    # (J - X^T X / m_tot) alpha = f_r - X^T b / m_tot, the Schur complement of the time-only terms
    imt = cc[CC_IMT]
    b0 = R[0, 0] * f0 + R[1, 0] * f1 + R[2, 0] * f2
    b1 = R[0, 1] * f0 + R[1, 1] * f1 + R[2, 1] * f2
    b2 = R[0, 2] * f0 + R[1, 2] * f1 + R[2, 2] * f2
    c0, c1, c2 = cross(s0, s1, s2, b0, b1, b2)
    a0, a1, a2 = _solve_schur(tc, r0 - c0 * imt, r1 - c1 * imt, r2 - c2 * imt)
    # translation (floor frame): m_tot a = f_t - R X alpha = f_t + R (SR x alpha)
    u0, u1, u2 = cross(s0, s1, s2, a0, a1, a2)
    acc[0] = (f0 + R[0, 0] * u0 + R[0, 1] * u1 + R[0, 2] * u2) * imt
    acc[1] = (f1 + R[1, 0] * u0 + R[1, 1] * u1 + R[1, 2] * u2) * imt
    acc[2] = (f2 + R[2, 0] * u0 + R[2, 1] * u1 + R[2, 2] * u2) * imt
    acc[3] = a0
    acc[4] = a1
    acc[5] = a2


@njit(cache=True, fastmath=False)
def accel(P, c, level, t, x, idx, W):
    """Accelerations of the base at time ``t`` (s) and state ``x``, written to ``W.acc`` (6,).

    ``acc = [d2u/dt2 (m/s^2), dw/dt (rad/s^2)]``. ``W`` is the case's scratch space
    (``engine.kernels.params.Work``). Makes the time-only terms those of ``t`` (:func:`time_terms`: the
    stages, the floor and the feedforward actuators at ``t``), then evaluates the level's own equations
    (:func:`accel_lti`, :func:`accel_ltv`, :func:`accel_nonlinear`). Returns False when the level's mass
    matrix is not positive definite.
    """
    if not time_terms(P, c, level, t, idx, W):
        return False
    if level == LTI:
        ok = accel_lti(P, c, x, W)
        if x.shape[0] > 12:
            slot_forces(P, c, t, x, idx, W.acc)
        return ok
    if level == LTV:
        return accel_ltv(P, c, x, W)
    return accel_nonlinear(P, c, x, W)


@njit(cache=True, fastmath=False)
def rates(level, x, acc, dx):
    """The state's time derivative ``dx`` from the state ``x`` and the accelerations ``acc`` (6,)."""
    if level == NONLINEAR:
        q0, q1, q2, q3 = x[3], x[4], x[5], x[6]
        w0, w1, w2 = x[10], x[11], x[12]
        dx[0], dx[1], dx[2] = x[7], x[8], x[9]
        dx[3] = 0.5 * (-q1 * w0 - q2 * w1 - q3 * w2)
        dx[4] = 0.5 * (q0 * w0 + q2 * w2 - q3 * w1)
        dx[5] = 0.5 * (q0 * w1 - q1 * w2 + q3 * w0)
        dx[6] = 0.5 * (q0 * w2 + q1 * w1 - q2 * w0)
        for i in range(6):
            dx[7 + i] = acc[i]
    else:
        for i in range(6):
            dx[i] = x[6 + i]
            dx[6 + i] = acc[i]


@njit(cache=True, fastmath=False)
def derivative(P, c, level, t, x, idx, W, dx):
    """Time derivative ``dx`` of the state ``x`` at ``t`` (s). Returns False on a singular mass matrix."""
    okm = accel(P, c, level, t, x, idx, W)
    rates(level, x, W.acc, dx)
    if level != NONLINEAR and x.shape[0] > 12:
        slot_rates(P, c, t, x, idx, W.acc, dx)
    return okm


@njit(cache=True, inline="always")
def stage_acceleration(P, c, q, t, idx):
    """Stage ``q``'s acceleration along its own axis at ``t`` (s) on its piece ``idx[q]``, m/s^2 (0 before
    its profile starts)."""
    k = idx[q]
    if k < 0:
        return 0.0
    return P.pa[c, q, k] + P.pj[c, q, k] * (t - P.pt[c, q, k])


@njit(cache=True, fastmath=False)
def slot_forces(P, c, t, x, idx, acc):
    """What the extra linear states ``z = x[12:]`` add to the LTI level's accelerations ``acc`` (6,):
    ``zM z``, and ``sM s''`` where a model takes a stage's inertia off the base (``Params.sM``)."""
    nz = x.shape[0] - 12
    zM, sM = P.zM, P.sM
    for i in range(6):
        s = 0.0
        for j in range(nz):
            s += zM[c, i, j] * x[12 + j]
        for q in range(sM.shape[2]):
            s += sM[c, i, q] * stage_acceleration(P, c, q, t, idx)
        acc[i] += s


@njit(cache=True, fastmath=False)
def slot_rates(P, c, t, x, idx, acc, dx):
    """The extra linear states' rates ``dx[12:] = zA z + zX x + zQ acc + zS s''`` at ``t`` (s): ``x`` the
    state ``[base (12), z (nz)]``, ``acc`` (6,) the base's accelerations just computed, ``s''`` each stage's
    acceleration along its axis on its piece ``idx`` (``engine.kernels.params.Params``); a row with a dead
    band (``Params.zdb`` > 0, a levelling valve's) loses it from its rate, ``sign(r) max(|r| - zdb, 0)``."""
    nz = x.shape[0] - 12
    zA, zX, zQ, zS = P.zA, P.zX, P.zQ, P.zS
    for i in range(nz):
        s = 0.0
        for j in range(nz):
            s += zA[c, i, j] * x[12 + j]
        for j in range(12):
            s += zX[c, i, j] * x[j]
        for j in range(6):
            s += zQ[c, i, j] * acc[j]
        for q in range(zS.shape[2]):
            s += zS[c, i, q] * stage_acceleration(P, c, q, t, idx)
        band = P.zdb[c, i]
        if band > 0.0:  # a dead band on the row's rate: sign(s) max(|s| - band, 0)
            s = s - band if s > band else (s + band if s < -band else 0.0)
        dx[12 + i] = s
