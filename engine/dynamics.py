"""Equations of motion of a rigid machine base on isolators, shaken by its own stages.

Numba functions shared by the integrators. A case's parameters come in a ``Params`` named tuple of arrays
(case dimension first, see ``engine.model.params``); ``c`` is the case index. The state of the linear
levels is ``x = [u(3), theta(3), v(3), w(3)]``: c.g. displacement (m), small rotation about X, Y, Z (rad),
their rates (m/s, rad/s). The nonlinear level uses ``x = [u(3), q(4), v(3), w_b(3)]`` with a unit
quaternion ``q`` (body to floor) and the body-frame angular velocity ``w_b``.

Translation is written in the floor frame, rotation about the machine c.g. in the body frame. Stages are
point masses moving along axes fixed in the machine; their reaction on the machine is ``m g - m a_abs``.
Isolator forces are ``-K delta - C delta_dot`` per floor axis about the preloaded reference state; the
preload is vertical and balances every weight with the stages at home (at the nonlinear level it may turn
with the base instead, ``Params.pbase``). Active mounts may add actuator forces that feed the stages'
inertial wrench forward (:func:`feedforward_forces`), a known function of time like the stages' own.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit
from numba.core import types
from numba.experimental import structref

LTI, LTV, NONLINEAR = 0, 1, 2
FIDELITIES = {"lti": LTI, "ltv": LTV, "nonlinear": NONLINEAR}

Params = namedtuple(
    "Params",
    [
        "mass",
        "mtot",
        "inertia",
        "d",
        "k",
        "cd",
        "sky",
        "f0",
        "sm",
        "rho_h",
        "e",
        "parent",
        "pt",
        "ps",
        "pv",
        "pa",
        "pj",
        "pts",
        "famp",
        "fomega",
        "fphase",
        "ft",
        "fd",
        "a21",
        "a22",
        "minv",
        "g",
        "gstiff",
        "ffon",
        "ffg",
        "ffw",
        "fflim",
        "ffD",
        "fftb",
        "ffA",
        "ffwt",
        "pbase",
    ],
)


class _Fields(types.StructRef):
    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


@structref.register
class ParamsType(_Fields):
    pass


@structref.register
class WorkType(_Fields):
    pass


@structref.register
class PeaksType(_Fields):
    pass


class KernelParams(structref.StructRefProxy):
    """``Params`` as the kernels take it: passed by reference, so a call costs one pointer, not a copy of
    every array's descriptor."""


class KernelWork(structref.StructRefProxy):
    """``engine.model.Work`` as the kernels take it."""


class KernelPeaks(structref.StructRefProxy):
    """``engine.peaks.Peaks`` as the kernels take it (its fields, the running peaks and the rest-interval
    settling state, are those of the ``Peaks`` named tuple: ``structref.define_proxy`` there)."""


structref.define_proxy(KernelParams, ParamsType, list(Params._fields))


def kernel_struct(nt):
    """The kernel view of a ``Params``, ``Work`` or ``Peaks`` named tuple (arrays shared, not copied)."""
    proxy = {"Params": KernelParams, "Work": KernelWork, "Peaks": KernelPeaks}[type(nt).__name__]
    return proxy(*nt)


# ----------------------------------------------------------------------------------------------- vectors
@njit(cache=True, inline="always")
def _cross(a0, a1, a2, b0, b1, b2):
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(cache=True)
def quat_to_matrix(q, R):
    """Rotation matrix (body to floor) of the unit quaternion ``q = (w, x, y, z)`` into ``R`` (3, 3)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    R[0, 0] = 1 - 2 * (y * y + z * z)
    R[0, 1] = 2 * (x * y - w * z)
    R[0, 2] = 2 * (x * z + w * y)
    R[1, 0] = 2 * (x * y + w * z)
    R[1, 1] = 1 - 2 * (x * x + z * z)
    R[1, 2] = 2 * (y * z - w * x)
    R[2, 0] = 2 * (x * z - w * y)
    R[2, 1] = 2 * (y * z + w * x)
    R[2, 2] = 1 - 2 * (x * x + y * y)


@njit(cache=True)
def quat_to_rotvec(q, out):
    """Rotation vector (axis times angle, rad) of the unit quaternion ``q`` into ``out`` (3,)."""
    w = q[0]
    s = np.sqrt(q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    if w < 0.0:
        w = -w
        sign = -1.0
    else:
        sign = 1.0
    if s < 1e-12:
        f = 2.0 * sign
    else:
        f = sign * 2.0 * np.arctan2(s, w) / s
    out[0] = f * q[1]
    out[1] = f * q[2]
    out[2] = f * q[3]


@njit(cache=True)
def quat_step(q, w0, w1, w2, h):
    """Advance ``q`` in place by a constant body rate ``w`` (rad/s) over ``h`` s (exact increment)."""
    wn = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    half = 0.5 * wn * h
    if wn * h < 1e-12:
        dw, dx, dy, dz = 1.0, 0.5 * w0 * h, 0.5 * w1 * h, 0.5 * w2 * h
    else:
        s = np.sin(half) / wn
        dw, dx, dy, dz = np.cos(half), s * w0, s * w1, s * w2
    a0, a1, a2, a3 = q[0], q[1], q[2], q[3]
    q[0] = a0 * dw - a1 * dx - a2 * dy - a3 * dz
    q[1] = a0 * dx + a1 * dw + a2 * dz - a3 * dy
    q[2] = a0 * dy - a1 * dz + a2 * dw + a3 * dx
    q[3] = a0 * dz + a1 * dy - a2 * dx + a3 * dw
    n = np.sqrt(q[0] ** 2 + q[1] ** 2 + q[2] ** 2 + q[3] ** 2)
    for i in range(4):
        q[i] /= n


# ------------------------------------------------------------------------------------------- kinematics
@njit(cache=True)
def advance_pieces(P, c, t, idx, tol):
    """Move each stage's current piece index ``idx`` (m,) forward to the piece holding time ``t`` (s).

    A piece that starts within ``tol`` s after ``t`` counts as started, so steps that land on a
    breakpoint use the piece that begins there. An index of -1 means "before the first piece": the stage
    rests at its start position until its profile begins.
    """
    K = P.pt.shape[2]
    for i in range(P.pt.shape[1]):
        while idx[i] + 1 < K and P.pt[c, i, idx[i] + 1] <= t + tol:
            idx[i] += 1


@njit(cache=True)
def next_breakpoint(P, c, idx, t_end, tol):
    """End of the current pieces ``idx`` (m,): the earliest start of a next piece, s; ``t_end`` when none
    starts before ``t_end - tol``. Fixed-step integrators end a sub-step there, so each sub-step sees one
    polynomial piece of every profile (a jerk phase shorter than a step is integrated, not sampled)."""
    nb = t_end
    K = P.pt.shape[2]
    for i in range(P.pt.shape[1]):
        if idx[i] + 1 < K and P.pt[c, i, idx[i] + 1] < nb:
            nb = P.pt[c, i, idx[i] + 1]
    return t_end if nb >= t_end - tol else nb


@njit(cache=True)
def stage_state(P, c, t, idx, rho, vr, ar, jr):
    """Stage positions relative to the machine c.g. in the machine frame at time ``t`` (s).

    Fills ``rho`` (m, 3) m, and the relative velocity ``vr`` m/s, acceleration ``ar`` m/s^2 and jerk
    ``jr`` m/s^3 (m, 3), each stage evaluated on its piece ``idx[i]`` (extrapolated past its end, as a
    one-step method that holds the piece of the step's start does). A stage that rides on another adds
    its parent's travel.
    """
    # the arrays bound once: an attribute read inside the loop would count a reference each time
    ps, pt, pv, pa, pj, parent, e, rho_h = P.ps, P.pt, P.pv, P.pa, P.pj, P.parent, P.e, P.rho_h
    for i in range(P.sm.shape[1]):
        k = idx[i]
        if k < 0:
            j = 0.0
            a = 0.0
            v = 0.0
            s = ps[c, i, 0]
        else:
            tau = t - pt[c, i, k]
            j = pj[c, i, k]
            a = pa[c, i, k] + j * tau
            v = pv[c, i, k] + (pa[c, i, k] + 0.5 * j * tau) * tau
            s = ps[c, i, k] + (pv[c, i, k] + (0.5 * pa[c, i, k] + j * tau / 6.0) * tau) * tau
        p = parent[i]
        for dd in range(3):
            ed = e[c, i, dd]
            rho[i, dd] = rho_h[c, i, dd] + s * ed
            vr[i, dd] = v * ed
            ar[i, dd] = a * ed
            jr[i, dd] = j * ed
            if p >= 0:
                rho[i, dd] += rho[p, dd] - rho_h[c, p, dd]
                vr[i, dd] += vr[p, dd]
                ar[i, dd] += ar[p, dd]
                jr[i, dd] += jr[p, dd]


@njit(cache=True)
def recorded_floor(P, c, t, xf, vf):
    """Add the recorded floor displacement (m) and velocity (m/s) at ``t`` (s) to ``xf``, ``vf`` (3,).

    Linear interpolation between samples; zero before the first sample, held after the last.
    """
    ft = P.ft
    nf = ft.shape[0]
    if nf > 0 and t >= ft[0]:
        fd = P.fd
        lo, hi = 0, nf  # last sample at or before t: P.ft[lo] <= t < P.ft[hi]
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if ft[mid] <= t:
                lo = mid
            else:
                hi = mid
        i = lo
        if i >= nf - 1:
            for dd in range(3):
                xf[dd] += fd[c, dd, nf - 1]
        else:
            dt = ft[i + 1] - ft[i]
            for dd in range(3):
                slope = (fd[c, dd, i + 1] - fd[c, dd, i]) / dt
                xf[dd] += fd[c, dd, i] + slope * (t - ft[i])
                vf[dd] += slope


@njit(cache=True)
def floor_motion(P, c, t, xf, vf):
    """Floor displacement ``xf`` (3,) m and velocity ``vf`` (3,) m/s under the isolators at ``t`` (s)."""
    famp, fomega, fphase = P.famp, P.fomega, P.fphase
    for dd in range(3):
        amp = famp[c, dd]
        if amp == 0.0:
            xf[dd] = 0.0
            vf[dd] = 0.0
            continue
        w = fomega[c, dd]
        arg = w * t + fphase[c, dd]
        xf[dd] = amp * np.sin(arg)
        vf[dd] = amp * w * np.cos(arg)
    recorded_floor(P, c, t, xf, vf)


# ----------------------------------------------------------------------------------------------- forces
@njit(cache=True, inline="always")
def mount_offset(level, x, R, d0, d1, d2):
    """Displacement (m) of a material point at ``d`` (m, from the c.g.) due to the base's rotation:
    ``(R - I) d`` at the nonlinear level (``R`` body to floor), ``theta x d`` at the linear ones. Adding
    the c.g. displacement ``u`` gives the point's displacement; minus the floor's, a mount's deflection."""
    if level == NONLINEAR:
        r0 = R[0, 0] * d0 + R[0, 1] * d1 + R[0, 2] * d2 - d0
        r1 = R[1, 0] * d0 + R[1, 1] * d1 + R[1, 2] * d2 - d1
        r2 = R[2, 0] * d0 + R[2, 1] * d1 + R[2, 2] * d2 - d2
        return r0, r1, r2
    return _cross(x[3], x[4], x[5], d0, d1, d2)


@njit(cache=True)
def isolator_forces(P, c, level, x, R, xf, vf, F):
    """Dynamic isolator forces on the machine ``F`` (n, 3) N, floor frame, at state ``x``.

    ``delta = u + (R - I) d - x_floor`` (:func:`mount_offset`); the damper acts on ``delta_dot`` or, for
    a sky-hook mount, on the absolute velocity of the mount point. Linear levels use ``theta x d`` for
    ``(R - I) d``.
    """
    D, k, cd, sky = P.d, P.k, P.cd, P.sky  # bound once: an attribute read counts a reference each time
    n = D.shape[1]
    if level == NONLINEAR:
        off = 7
    else:
        off = 6
    u0, u1, u2 = x[0], x[1], x[2]
    v0, v1, v2 = x[off], x[off + 1], x[off + 2]
    w0, w1, w2 = x[off + 3], x[off + 4], x[off + 5]
    for j in range(n):
        d0, d1, d2 = D[c, j, 0], D[c, j, 1], D[c, j, 2]
        r0, r1, r2 = mount_offset(level, x, R, d0, d1, d2)
        if level == NONLINEAR:
            b0, b1, b2 = _cross(w0, w1, w2, d0, d1, d2)
            q0 = R[0, 0] * b0 + R[0, 1] * b1 + R[0, 2] * b2
            q1 = R[1, 0] * b0 + R[1, 1] * b1 + R[1, 2] * b2
            q2 = R[2, 0] * b0 + R[2, 1] * b1 + R[2, 2] * b2
        else:
            q0, q1, q2 = _cross(w0, w1, w2, d0, d1, d2)
        rel = 1.0 - sky[c, j]
        F[j, 0] = -k[c, j, 0] * (u0 + r0 - xf[0]) - cd[c, j, 0] * (v0 + q0 - rel * vf[0])
        F[j, 1] = -k[c, j, 1] * (u1 + r1 - xf[1]) - cd[c, j, 1] * (v1 + q1 - rel * vf[1])
        F[j, 2] = -k[c, j, 2] * (u2 + r2 - xf[2]) - cd[c, j, 2] * (v2 + q2 - rel * vf[2])


# ---------------------------------------------------------------------------------------- feedforward
@njit(cache=True)
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
        p0, p1, p2 = _cross(r0, r1, r2, a0, a1, a2)
        X[0, 3] += m * p0
        X[0, 4] += m * p1
        X[0, 5] += m * p2
        # d/dt (rho x a) = v x a + rho x j; then 2 v x j; then 2 a x j
        p0, p1, p2 = _cross(v0, v1, v2, a0, a1, a2)
        q0, q1, q2 = _cross(r0, r1, r2, j0, j1, j2)
        X[1, 3] += m * (p0 + q0)
        X[1, 4] += m * (p1 + q1)
        X[1, 5] += m * (p2 + q2)
        p0, p1, p2 = _cross(v0, v1, v2, j0, j1, j2)
        X[2, 3] += 2.0 * m * p0
        X[2, 4] += 2.0 * m * p1
        X[2, 5] += 2.0 * m * p2
        p0, p1, p2 = _cross(a0, a1, a2, j0, j1, j2)
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


@njit(cache=True)
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


@njit(cache=True)
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


@njit(cache=True)
def feedforward_generalised(P, c, t, idx, W, out, o):
    """Write the LTI level's generalised force of the feedforward actuators at ``t`` (s) to
    ``out[o:o + 6]`` (N, N m): ``[sum f_j, sum d_j x f_j]``. Evaluates the stages at ``t`` into ``W``."""
    stage_state(P, c, t, idx, W.rho, W.vr, W.ar, W.jr)
    feedforward_forces(P, c, t, idx, W)
    for q in range(6):
        out[o + q] = 0.0
    for j in range(P.d.shape[1]):
        f0, f1, f2 = W.Fa[j, 0], W.Fa[j, 1], W.Fa[j, 2]
        m0, m1, m2 = _cross(P.d[c, j, 0], P.d[c, j, 1], P.d[c, j, 2], f0, f1, f2)
        out[o] += f0
        out[o + 1] += f1
        out[o + 2] += f2
        out[o + 3] += m0
        out[o + 4] += m1
        out[o + 5] += m2


@njit(cache=True)
def lti_forcing(P, c, rho, ar, xf, vf, f):
    """Generalised force ``f`` (6,) N and N m of the LTI level: stages and floor as known inputs.

    ``f_t = -sum m a_rel + sum (K x_f + C' v_f)``; ``f_r = -sum m rho x a_rel + sum m (rho - rho_home) x g
    + sum d x (K x_f + C' v_f)`` with ``C' = 0`` for sky-hook mounts.
    """
    for i in range(6):
        f[i] = 0.0
    g = P.g
    for i in range(P.sm.shape[1]):
        m = P.sm[c, i]
        a0, a1, a2 = ar[i, 0], ar[i, 1], ar[i, 2]
        f[0] -= m * a0
        f[1] -= m * a1
        f[2] -= m * a2
        t0, t1, t2 = _cross(rho[i, 0], rho[i, 1], rho[i, 2], a0, a1, a2)
        # (rho - rho_h) x (0, 0, -g)
        s0 = rho[i, 0] - P.rho_h[c, i, 0]
        s1 = rho[i, 1] - P.rho_h[c, i, 1]
        f[3] += -m * t0 - m * s1 * g
        f[4] += -m * t1 + m * s0 * g
        f[5] += -m * t2
    for j in range(P.d.shape[1]):
        rel = 1.0 - P.sky[c, j]
        p0 = P.k[c, j, 0] * xf[0] + rel * P.cd[c, j, 0] * vf[0]
        p1 = P.k[c, j, 1] * xf[1] + rel * P.cd[c, j, 1] * vf[1]
        p2 = P.k[c, j, 2] * xf[2] + rel * P.cd[c, j, 2] * vf[2]
        if p0 == 0.0 and p1 == 0.0 and p2 == 0.0:
            continue
        f[0] += p0
        f[1] += p1
        f[2] += p2
        m0, m1, m2 = _cross(P.d[c, j, 0], P.d[c, j, 1], P.d[c, j, 2], p0, p1, p2)
        f[3] += m0
        f[4] += m1
        f[5] += m2


# ------------------------------------------------------------------------------- accelerations, cached
# The accelerations are evaluated from three kinds of terms kept in the workspace ``W`` (``engine.model.
# Work``), so that a step reads a handful of arrays (an array read from ``P`` or ``W`` counts a reference
# each time, which costs more than the arithmetic here):
# - per case (``W.cc``, ``W.cs``, ``W.cm``, ``W.cK``, keyed on the case in ``W.cc[0]``): the parameters of
#   case ``c`` packed from ``P`` and the LTV level's mount operator;
# - per time (``W.tc``, keyed in ``W.key`` on the case, level, exact time and pieces): what depends on time
#   only (the stages' kinematics, the floor, the feedforward forces, and from them the mass matrix and the
#   stages' sums). The two middle slopes of an RK4 step share them, and the last slope of a step is the
#   first of the next. Any call order is safe (an adaptive integrator asks at arbitrary times): a
#   different key recomputes;
# - the state.
# ``W.cc``: case, m_tot (kg), 1/m_tot, inertia (9, kg m^2), floor amplitude (3, m), angular frequency
# (3, rad/s), phase (3, rad), number of recorded floor samples.
_CC_MT, _CC_IMT, _CC_IN, _CC_FA, _CC_FW, _CC_FP, _CC_NF = 1, 2, 3, 12, 15, 18, 21
_CC_SIZE = 22
# ``W.cs`` (m, 8 + 5 K): per stage mass (kg), parent, axis (3), home (3, m), then its pieces' start times
# (K, s), positions (m), velocities (m/s), accelerations (m/s^2) and jerks (m/s^3).
_CS_E, _CS_H, _CS_P = 2, 5, 8
# ``W.cm`` (n, 11): per mount lever arm (3, m), stiffness (3, N/m), damping (3, N s/m), sky-hook, preload (N).
_CM_D, _CM_K, _CM_C, _CM_SKY, _CM_F0 = 0, 3, 6, 9, 10
# Rows of ``W.tc`` (21, 3): the stages' sums at the time of ``W.key``.
_SR, _SV, _SA, _TA, _WM, _SFA, _DFA, _XF, _VF, _LD, _BT, _BR = range(12)
"""``sum m rho`` (kg m), ``sum m v_rel`` (kg m/s), ``sum m a_rel`` (N), ``sum m rho x a_rel`` (N m), the
stages' weight moment about home ``sum m (rho - rho_h) x g`` (N m, linear levels), the feedforward forces
``sum f_j`` (N) and moments ``sum d_j x f_j`` (N m), the floor displacement (m) and velocity (m/s), the
reciprocal diagonal of the Schur factor ``_LS`` (1/sqrt(kg m^2)), the known part of the generalised force
(N, N m; the LTI level: of the accelerations, m/s^2, rad/s^2)."""
_GW, _JT, _LS = 12, 15, 18
"""First rows of the (3, 3) blocks of ``W.tc``: ``sum m ((rho . v_rel) 1 - v_rel rho^T)`` (kg m^2/s), the
rotary mass of base and stages ``J`` (kg m^2) and the Cholesky factor (lower) of the mass matrix's Schur
complement ``J - [SR]x^T [SR]x / m_tot`` (sqrt(kg) m)."""


@njit(cache=True)
def _linear_mounts(P, c, x, xf, vf, R, F, out):
    """Generalised force ``out`` (6,) N, N m of the isolators at the linear levels (and the rocking moment
    of their preloads that tilt with the base, ``P.gstiff``) at state ``x`` and floor motion ``xf``, ``vf``
    (3,): linear in ``(x, xf, vf)``. ``F`` (n, 3) scratch; ``R`` unused."""
    isolator_forces(P, c, LTV, x, R, xf, vf, F)
    for q in range(6):
        out[q] = 0.0
    for j in range(P.d.shape[1]):
        F0, F1, F2 = F[j, 0], F[j, 1], F[j, 2]
        out[0] += F0
        out[1] += F1
        out[2] += F2
        d0, d1, d2 = P.d[c, j, 0], P.d[c, j, 1], P.d[c, j, 2]
        m0, m1, m2 = _cross(d0, d1, d2, F0, F1, F2)
        if P.gstiff:
            # d x (-theta x F0) with F0 = (0, 0, f0)
            tf0, tf1, tf2 = _cross(x[3], x[4], x[5], 0.0, 0.0, P.f0[c, j])
            n0, n1, n2 = _cross(d0, d1, d2, -tf0, -tf1, -tf2)
            m0 += n0
            m1 += n1
            m2 += n2
        out[3] += m0
        out[4] += m1
        out[5] += m2


@njit(cache=True)
def _pack_case(P, c, W):
    """Pack case ``c``'s parameters into ``W.cc``, ``W.cs``, ``W.cm`` and its LTV mount operator into
    ``W.cK`` (12, 6): row ``k`` is the generalised force of :func:`_linear_mounts` for the unit state
    ``x = e_k`` without floor motion."""
    cc, cs, cm = W.cc, W.cs, W.cm
    cc[_CC_MT] = P.mtot[c]
    cc[_CC_IMT] = 1.0 / P.mtot[c]
    for a in range(3):
        for b in range(3):
            cc[_CC_IN + 3 * a + b] = P.inertia[c, a, b]
        cc[_CC_FA + a] = P.famp[c, a]
        cc[_CC_FW + a] = P.fomega[c, a]
        cc[_CC_FP + a] = P.fphase[c, a]
    cc[_CC_NF] = P.ft.shape[0]
    K = P.pt.shape[2]
    for i in range(P.sm.shape[1]):
        cs[i, 0] = P.sm[c, i]
        cs[i, 1] = P.parent[i]
        for a in range(3):
            cs[i, _CS_E + a] = P.e[c, i, a]
            cs[i, _CS_H + a] = P.rho_h[c, i, a]
        for k in range(K):
            cs[i, _CS_P + k] = P.pt[c, i, k]
            cs[i, _CS_P + K + k] = P.ps[c, i, k]
            cs[i, _CS_P + 2 * K + k] = P.pv[c, i, k]
            cs[i, _CS_P + 3 * K + k] = P.pa[c, i, k]
            cs[i, _CS_P + 4 * K + k] = P.pj[c, i, k]
    for j in range(P.d.shape[1]):
        for a in range(3):
            cm[j, _CM_D + a] = P.d[c, j, a]
            cm[j, _CM_K + a] = P.k[c, j, a]
            cm[j, _CM_C + a] = P.cd[c, j, a]
        cm[j, _CM_SKY] = P.sky[c, j]
        cm[j, _CM_F0] = P.f0[c, j]
    x = np.zeros(12)
    z = np.zeros(3)
    out = np.zeros(6)
    for k in range(12):
        x[k] = 1.0
        _linear_mounts(P, c, x, z, z, W.R, W.F, out)
        for q in range(6):
            W.cK[k, q] = out[q]
        x[k] = 0.0
    cc[0] = c


@njit(cache=True)
def moving_terms(level, g, cc, cs, cm, sw, tc):
    """The time-only terms of the LTV and nonlinear levels in ``tc`` from the stages' state ``sw`` and the
    floor (rows ``_XF``, ``_VF``) and feedforward (``_SFA``, ``_DFA``) rows already in ``tc``. Returns
    False when the mass matrix is not positive definite."""
    for r in range(_XF):
        if r == _SFA or r == _DFA:
            continue
        for q in range(3):
            tc[r, q] = 0.0
    for r in range(_LD, _GW + 3):
        for q in range(3):
            tc[r, q] = 0.0
    for a in range(3):
        for b in range(3):
            tc[_JT + a, b] = cc[_CC_IN + 3 * a + b]
    for i in range(cs.shape[0]):
        m = cs[i, 0]
        r0, r1, r2 = sw[i, 0], sw[i, 1], sw[i, 2]
        v0, v1, v2 = sw[i, 3], sw[i, 4], sw[i, 5]
        a0, a1, a2 = sw[i, 6], sw[i, 7], sw[i, 8]
        tc[_SR, 0] += m * r0
        tc[_SR, 1] += m * r1
        tc[_SR, 2] += m * r2
        tc[_SV, 0] += m * v0
        tc[_SV, 1] += m * v1
        tc[_SV, 2] += m * v2
        tc[_SA, 0] += m * a0
        tc[_SA, 1] += m * a1
        tc[_SA, 2] += m * a2
        h0, h1, h2 = _cross(r0, r1, r2, a0, a1, a2)
        tc[_TA, 0] += m * h0
        tc[_TA, 1] += m * h1
        tc[_TA, 2] += m * h2
        # (rho - rho_h) x (0, 0, -g)
        tc[_WM, 0] -= m * (r1 - cs[i, _CS_H + 1]) * g
        tc[_WM, 1] += m * (r0 - cs[i, _CS_H]) * g
        # G_w += m ((rho . v) 1 - v rho^T); J += m (|rho|^2 1 - rho rho^T)
        rv = m * (r0 * v0 + r1 * v1 + r2 * v2)
        tc[_GW, 0] += rv - m * v0 * r0
        tc[_GW, 1] -= m * v0 * r1
        tc[_GW, 2] -= m * v0 * r2
        tc[_GW + 1, 0] -= m * v1 * r0
        tc[_GW + 1, 1] += rv - m * v1 * r1
        tc[_GW + 1, 2] -= m * v1 * r2
        tc[_GW + 2, 0] -= m * v2 * r0
        tc[_GW + 2, 1] -= m * v2 * r1
        tc[_GW + 2, 2] += rv - m * v2 * r2
        tc[_JT, 0] += m * (r1 * r1 + r2 * r2)
        tc[_JT + 1, 1] += m * (r0 * r0 + r2 * r2)
        tc[_JT + 2, 2] += m * (r0 * r0 + r1 * r1)
        tc[_JT, 1] -= m * r0 * r1
        tc[_JT + 1, 0] -= m * r0 * r1
        tc[_JT, 2] -= m * r0 * r2
        tc[_JT + 2, 0] -= m * r0 * r2
        tc[_JT + 1, 2] -= m * r1 * r2
        tc[_JT + 2, 1] -= m * r1 * r2
    # Schur complement of the translation block: S = J - X^T X / m_tot with X = -[SR]x,
    # X^T X = |SR|^2 1 - SR SR^T
    if not cc[_CC_MT] > 0.0:
        return False
    imt = cc[_CC_IMT]
    s0, s1, s2 = tc[_SR, 0], tc[_SR, 1], tc[_SR, 2]
    tc[_LS, 0] = tc[_JT, 0] - (s1 * s1 + s2 * s2) * imt
    tc[_LS + 1, 1] = tc[_JT + 1, 1] - (s0 * s0 + s2 * s2) * imt
    tc[_LS + 2, 2] = tc[_JT + 2, 2] - (s0 * s0 + s1 * s1) * imt
    tc[_LS + 1, 0] = tc[_JT + 1, 0] + s1 * s0 * imt
    tc[_LS + 2, 0] = tc[_JT + 2, 0] + s2 * s0 * imt
    tc[_LS + 2, 1] = tc[_JT + 2, 1] + s2 * s1 * imt
    for j in range(3):
        s = tc[_LS + j, j]
        for k in range(j):
            s -= tc[_LS + j, k] * tc[_LS + j, k]
        if not s > 0.0:
            return False
        ljj = np.sqrt(s)
        rl = 1.0 / ljj
        tc[_LS + j, j] = ljj
        tc[_LD, j] = rl
        for i in range(j + 1, 3):
            s = tc[_LS + i, j]
            for k in range(j):
                s -= tc[_LS + i, k] * tc[_LS + j, k]
            tc[_LS + i, j] = s * rl
    if level == LTV:
        # the known part of the generalised force: floor through the mounts, stages, feedforward
        x0, x1, x2 = tc[_XF, 0], tc[_XF, 1], tc[_XF, 2]
        y0, y1, y2 = tc[_VF, 0], tc[_VF, 1], tc[_VF, 2]
        if x0 != 0.0 or x1 != 0.0 or x2 != 0.0 or y0 != 0.0 or y1 != 0.0 or y2 != 0.0:
            for j in range(cm.shape[0]):
                rel = 1.0 - cm[j, _CM_SKY]
                p0 = cm[j, _CM_K] * x0 + rel * cm[j, _CM_C] * y0
                p1 = cm[j, _CM_K + 1] * x1 + rel * cm[j, _CM_C + 1] * y1
                p2 = cm[j, _CM_K + 2] * x2 + rel * cm[j, _CM_C + 2] * y2
                m0, m1, m2 = _cross(cm[j, _CM_D], cm[j, _CM_D + 1], cm[j, _CM_D + 2], p0, p1, p2)
                tc[_BT, 0] += p0
                tc[_BT, 1] += p1
                tc[_BT, 2] += p2
                tc[_BR, 0] += m0
                tc[_BR, 1] += m1
                tc[_BR, 2] += m2
        for q in range(3):
            tc[_BT, q] += tc[_SFA, q] - tc[_SA, q]
            tc[_BR, q] += tc[_DFA, q] + tc[_WM, q] - tc[_TA, q]
    return True


@njit(cache=True)
def _lti_terms(P, c, W):
    """The LTI level's accelerations due to the known inputs, ``M^-1 f`` (m/s^2, rad/s^2), into the rows
    ``_BT``, ``_BR`` of ``W.tc``, from the stages, floor and feedforward state in ``W``."""
    lti_forcing(P, c, W.rho, W.ar, W.xf, W.vf, W.f)
    if P.ffon:  # the feedforward actuators (W.Fa): a known input too
        for j in range(P.d.shape[1]):
            f0, f1, f2 = W.Fa[j, 0], W.Fa[j, 1], W.Fa[j, 2]
            m0, m1, m2 = _cross(P.d[c, j, 0], P.d[c, j, 1], P.d[c, j, 2], f0, f1, f2)
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
        W.tc[_BT + i // 3, i % 3] = s


@njit(cache=True)
def stages_and_floor(t, idx, cc, cs, sw, tc):
    """First part of evaluating the time-only terms of the LTV and nonlinear levels at ``t`` (s) on the
    pieces ``idx`` (:func:`time_terms`): the stages' positions (m), velocities (m/s) and accelerations
    (m/s^2) relative to the c.g. into ``sw`` (m, 9), the floor's sine motion
    into the rows ``_XF``, ``_VF`` of ``tc``, the feedforward rows cleared. Then
    :func:`recorded_and_feedforward` when the case has either (:func:`extra_inputs`), and
    :func:`moving_terms`."""
    # the stages (as :func:`stage_state`, from the packed case ``cs``)
    m = cs.shape[0]
    K = (cs.shape[1] - _CS_P) // 5
    for i in range(m):
        k = idx[i]
        if k < 0:
            j = 0.0
            a = 0.0
            v = 0.0
            s = cs[i, _CS_P + K]
        else:
            tau = t - cs[i, _CS_P + k]
            j = cs[i, _CS_P + 4 * K + k]
            a0 = cs[i, _CS_P + 3 * K + k]
            a = a0 + j * tau
            v = cs[i, _CS_P + 2 * K + k] + (a0 + 0.5 * j * tau) * tau
            s = cs[i, _CS_P + K + k] + (cs[i, _CS_P + 2 * K + k] + (0.5 * a0 + j * tau / 6.0) * tau) * tau
        p = int(cs[i, 1])
        for dd in range(3):
            ed = cs[i, _CS_E + dd]
            sw[i, dd] = cs[i, _CS_H + dd] + s * ed
            sw[i, 3 + dd] = v * ed
            sw[i, 6 + dd] = a * ed
            if p >= 0:
                sw[i, dd] += sw[p, dd] - cs[p, _CS_H + dd]
                sw[i, 3 + dd] += sw[p, 3 + dd]
                sw[i, 6 + dd] += sw[p, 6 + dd]
    for dd in range(3):
        amp = cc[_CC_FA + dd]
        if amp == 0.0:
            tc[_XF, dd] = 0.0
            tc[_VF, dd] = 0.0
        else:
            w = cc[_CC_FW + dd]
            arg = w * t + cc[_CC_FP + dd]
            tc[_XF, dd] = amp * np.sin(arg)
            tc[_VF, dd] = amp * w * np.cos(arg)
        tc[_SFA, dd] = 0.0
        tc[_DFA, dd] = 0.0


@njit(cache=True, inline="always")
def extra_inputs(ffon, cc):
    """Whether the case has a recorded floor motion or feedforward actuators (packed case ``cc``)."""
    return ffon or cc[_CC_NF] > 0


@njit(cache=True)
def recorded_and_feedforward(P, c, t, idx, W, cm, tc):
    """Add the recorded floor motion and the feedforward actuators' forces and moments at ``t`` (s) to
    ``tc`` (after :func:`stages_and_floor`)."""
    if P.ft.shape[0] > 0:
        recorded_floor(P, c, t, tc[_XF], tc[_VF])
    if P.ffon:
        stage_state(P, c, t, idx, W.rho, W.vr, W.ar, W.jr)
        feedforward_forces(P, c, t, idx, W)
        Fa = W.Fa
        for j in range(cm.shape[0]):
            f0, f1, f2 = Fa[j, 0], Fa[j, 1], Fa[j, 2]
            m0, m1, m2 = _cross(cm[j, _CM_D], cm[j, _CM_D + 1], cm[j, _CM_D + 2], f0, f1, f2)
            tc[_SFA, 0] += f0
            tc[_SFA, 1] += f1
            tc[_SFA, 2] += f2
            tc[_DFA, 0] += m0
            tc[_DFA, 1] += m1
            tc[_DFA, 2] += m2


@njit(cache=True)
def key_holds(c, level, t, idx, key):
    """Whether the time-only terms with the key ``key`` (``W.key``) are those of case ``c`` and ``level``
    at ``t`` (s) on the pieces ``idx``."""
    if key[0] != c or key[1] != level or key[2] != t:
        return False
    for i in range(idx.shape[0]):
        if key[4 + i] != idx[i]:
            return False
    return True


@njit(cache=True)
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


@njit(cache=True)
def pack_case(P, c, W, cc):
    """Make the workspace's per-case terms (``W.cc`` bound as ``cc``, ``W.cs``, ``W.cm``, ``W.cK``) those
    of case ``c``."""
    if cc[0] != c:
        _pack_case(P, c, W)


@njit(cache=True)
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


@njit(cache=True)
def _solve_schur(tc, q0, q1, q2):
    """``S^-1 q`` with the Cholesky factor of the Schur complement ``S`` and its reciprocal diagonal in
    ``tc``."""
    y0 = q0 * tc[_LD, 0]
    y1 = (q1 - tc[_LS + 1, 0] * y0) * tc[_LD, 1]
    y2 = (q2 - tc[_LS + 2, 0] * y0 - tc[_LS + 2, 1] * y1) * tc[_LD, 2]
    z2 = y2 * tc[_LD, 2]
    z1 = (y1 - tc[_LS + 2, 1] * z2) * tc[_LD, 1]
    z0 = (y0 - tc[_LS + 1, 0] * z1 - tc[_LS + 2, 0] * z2) * tc[_LD, 0]
    return z0, z1, z2


@njit(cache=True)
def accel_lti(P, c, x, W):
    """Accelerations ``W.acc`` (6,) of the LTI level: ``A21 x + A22 v + M^-1 f`` with the stages and the
    floor as known inputs (``M^-1 f`` from :func:`time_terms`). Always True."""
    tc, a21, a22 = W.tc, P.a21, P.a22
    for i in range(6):
        s = tc[_BT + i // 3, i % 3]
        for j in range(6):
            s += a21[c, i, j] * x[j] + a22[c, i, j] * x[6 + j]
        W.acc[i] = s
    return True


@njit(cache=True)
def accel_ltv(P, c, x, W):
    """Accelerations ``W.acc`` (6,) of the LTV level: small rotations, mass matrix and weight moments
    following the stages' travel, Coriolis terms of the stages (time-only terms from
    :func:`time_terms`). The generalised force is linear in the state: the mounts' operator ``W.cK``,
    the known part, and the stages' terms that multiply the rotation or its rate. Always True (the mass
    matrix was checked with the time-only terms)."""
    ltv_acc(x, W.tc, W.cK, W.cc, P.g, P.ffon, P.gstiff, W.acc)
    return True


@njit(cache=True)
def ltv_acc(x, tc, K, cc, g, ffon, gstiff, acc):
    """:func:`accel_ltv` on the workspace's arrays: ``acc`` (6,) from the time-only terms ``tc``, the
    mount operator ``K`` (12, 6), the packed case ``cc`` and gravity ``g`` (m/s^2)."""
    f0, f1, f2 = tc[_BT, 0], tc[_BT, 1], tc[_BT, 2]
    r0, r1, r2 = tc[_BR, 0], tc[_BR, 1], tc[_BR, 2]
    for k in range(12):
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
    p0, p1, p2 = _cross(tc[_SA, 0], tc[_SA, 1], tc[_SA, 2], t0, t1, t2)
    q0, q1, q2 = _cross(w0, w1, w2, tc[_SV, 0], tc[_SV, 1], tc[_SV, 2])
    f0 += p0 - 2.0 * q0
    f1 += p1 - 2.0 * q1
    f2 += p2 - 2.0 * q2
    if ffon:
        p0, p1, p2 = _cross(t0, t1, t2, tc[_SFA, 0], tc[_SFA, 1], tc[_SFA, 2])
        f0 += p0
        f1 += p1
        f2 += p2
    # rotation: -2 sum m rho x (w x v_rel) = -2 G_w w
    r0 -= 2.0 * (tc[_GW, 0] * w0 + tc[_GW, 1] * w1 + tc[_GW, 2] * w2)
    r1 -= 2.0 * (tc[_GW + 1, 0] * w0 + tc[_GW + 1, 1] * w1 + tc[_GW + 1, 2] * w2)
    r2 -= 2.0 * (tc[_GW + 2, 0] * w0 + tc[_GW + 2, 1] * w1 + tc[_GW + 2, 2] * w2)
    s0, s1, s2 = tc[_SR, 0], tc[_SR, 1], tc[_SR, 2]
    if gstiff:
        # sum m rho x (theta x (0, 0, g)) = g (SR_z theta - e_z (SR . theta))
        r0 += g * s2 * t0
        r1 += g * s2 * t1
        r2 -= g * (s0 * t0 + s1 * t1)
    # M = [[m_tot 1, X], [X^T, J]], X = -[SR]x: the rotation from the Schur complement
    # (J - X^T X / m_tot) alpha = f_r - X^T f_t / m_tot, then m_tot a = f_t - X alpha
    imt = cc[_CC_IMT]
    c0, c1, c2 = _cross(s0, s1, s2, f0, f1, f2)
    a0, a1, a2 = _solve_schur(tc, r0 - c0 * imt, r1 - c1 * imt, r2 - c2 * imt)
    u0, u1, u2 = _cross(s0, s1, s2, a0, a1, a2)
    acc[0] = (f0 + u0) * imt
    acc[1] = (f1 + u1) * imt
    acc[2] = (f2 + u2) * imt
    acc[3] = a0
    acc[4] = a1
    acc[5] = a2


@njit(cache=True)
def accel_nonlinear(P, c, x, W):
    """Accelerations ``W.acc`` (6,) of the nonlinear level: finite rotation (quaternion), the preload
    turning with the base, the gyroscopic term and the stages' full relative kinematics (time-only terms
    from :func:`time_terms`). Always True (the mass matrix was checked with the time-only terms)."""
    nonlinear_acc(x, W.tc, W.cc, W.cm, W.R, W.F, W.acc, P.g, P.pbase)
    return True


@njit(cache=True)
def nonlinear_acc(x, tc, cc, cm, R, F, acc, g, pbase):
    """:func:`accel_nonlinear` on the workspace's arrays (``R`` (3, 3), ``F`` (n, 3) scratch; the packed
    case ``cc``, ``cm``)."""
    # quat_to_matrix(x[3:7], R), without the slice
    qw, qx, qy, qz = x[3], x[4], x[5], x[6]
    R[0, 0] = 1 - 2 * (qy * qy + qz * qz)
    R[0, 1] = 2 * (qx * qy - qw * qz)
    R[0, 2] = 2 * (qx * qz + qw * qy)
    R[1, 0] = 2 * (qx * qy + qw * qz)
    R[1, 1] = 1 - 2 * (qx * qx + qz * qz)
    R[1, 2] = 2 * (qy * qz - qw * qx)
    R[2, 0] = 2 * (qx * qz - qw * qy)
    R[2, 1] = 2 * (qy * qz + qw * qx)
    R[2, 2] = 1 - 2 * (qx * qx + qy * qy)
    u0, u1, u2 = x[0], x[1], x[2]
    v0, v1, v2 = x[7], x[8], x[9]
    w0, w1, w2 = x[10], x[11], x[12]
    x0, x1, x2 = tc[_XF, 0], tc[_XF, 1], tc[_XF, 2]
    y0, y1, y2 = tc[_VF, 0], tc[_VF, 1], tc[_VF, 2]
    f0 = f1 = f2 = 0.0
    r0 = r1 = r2 = 0.0
    # isolators (``isolator_forces``): force (floor frame) and moment (body frame) with the vertical preload
    for j in range(cm.shape[0]):
        d0, d1, d2 = cm[j, _CM_D], cm[j, _CM_D + 1], cm[j, _CM_D + 2]
        o0, o1, o2 = mount_offset(NONLINEAR, x, R, d0, d1, d2)
        b0, b1, b2 = _cross(w0, w1, w2, d0, d1, d2)
        q0 = R[0, 0] * b0 + R[0, 1] * b1 + R[0, 2] * b2
        q1 = R[1, 0] * b0 + R[1, 1] * b1 + R[1, 2] * b2
        q2 = R[2, 0] * b0 + R[2, 1] * b1 + R[2, 2] * b2
        rel = 1.0 - cm[j, _CM_SKY]
        F0 = -cm[j, _CM_K] * (u0 + o0 - x0) - cm[j, _CM_C] * (v0 + q0 - rel * y0)
        F1 = -cm[j, _CM_K + 1] * (u1 + o1 - x1) - cm[j, _CM_C + 1] * (v1 + q1 - rel * y1)
        F2 = -cm[j, _CM_K + 2] * (u2 + o2 - x2) - cm[j, _CM_C + 2] * (v2 + q2 - rel * y2)
        f0 += F0
        f1 += F1
        f2 += F2
        p = cm[j, _CM_F0]
        if pbase:
            # the preload turns with the base: (0, 0, p) in the body, R (0, 0, p) in the floor frame
            f0 += p * R[0, 2]
            f1 += p * R[1, 2]
            f2 += p * (R[2, 2] - 1.0)
            G0 = R[0, 0] * F0 + R[1, 0] * F1 + R[2, 0] * F2
            G1 = R[0, 1] * F0 + R[1, 1] * F1 + R[2, 1] * F2
            G2 = R[0, 2] * F0 + R[1, 2] * F1 + R[2, 2] * F2 + p
        else:
            T2 = F2 + p
            G0 = R[0, 0] * F0 + R[1, 0] * F1 + R[2, 0] * T2
            G1 = R[0, 1] * F0 + R[1, 1] * F1 + R[2, 1] * T2
            G2 = R[0, 2] * F0 + R[1, 2] * F1 + R[2, 2] * T2
        m0, m1, m2 = _cross(d0, d1, d2, G0, G1, G2)
        r0 += m0
        r1 += m1
        r2 += m2
    s0, s1, s2 = tc[_SR, 0], tc[_SR, 1], tc[_SR, 2]
    # body-frame forces: feedforward actuators (fixed in the machine) and the stages'
    # -sum m (w x (w x rho) + 2 w x v_rel + a_rel), turned to the floor frame
    o0, o1, o2 = _cross(w0, w1, w2, s0, s1, s2)
    z0, z1, z2 = _cross(w0, w1, w2, o0, o1, o2)
    c0, c1, c2 = _cross(w0, w1, w2, tc[_SV, 0], tc[_SV, 1], tc[_SV, 2])
    k0 = tc[_SFA, 0] - z0 - 2.0 * c0 - tc[_SA, 0]
    k1 = tc[_SFA, 1] - z1 - 2.0 * c1 - tc[_SA, 1]
    k2 = tc[_SFA, 2] - z2 - 2.0 * c2 - tc[_SA, 2]
    f0 += R[0, 0] * k0 + R[0, 1] * k1 + R[0, 2] * k2
    f1 += R[1, 0] * k0 + R[1, 1] * k1 + R[1, 2] * k2
    f2 += R[2, 0] * k0 + R[2, 1] * k1 + R[2, 2] * k2
    # gyroscopic term of base and stages -w x (J w) (the stages' share is sum m rho x (w x (w x rho))),
    # the stages' -sum m rho x (a_rel + 2 w x v_rel) and weight moment SR x R^T (0, 0, -g)
    I0 = tc[_JT, 0] * w0 + tc[_JT, 1] * w1 + tc[_JT, 2] * w2
    I1 = tc[_JT + 1, 0] * w0 + tc[_JT + 1, 1] * w1 + tc[_JT + 1, 2] * w2
    I2 = tc[_JT + 2, 0] * w0 + tc[_JT + 2, 1] * w1 + tc[_JT + 2, 2] * w2
    y0, y1, y2 = _cross(w0, w1, w2, I0, I1, I2)
    h0, h1, h2 = _cross(s0, s1, s2, -g * R[2, 0], -g * R[2, 1], -g * R[2, 2])
    g0 = tc[_GW, 0] * w0 + tc[_GW, 1] * w1 + tc[_GW, 2] * w2
    g1 = tc[_GW + 1, 0] * w0 + tc[_GW + 1, 1] * w1 + tc[_GW + 1, 2] * w2
    g2 = tc[_GW + 2, 0] * w0 + tc[_GW + 2, 1] * w1 + tc[_GW + 2, 2] * w2
    r0 += tc[_DFA, 0] - y0 - tc[_TA, 0] - 2.0 * g0 + h0
    r1 += tc[_DFA, 1] - y1 - tc[_TA, 1] - 2.0 * g1 + h1
    r2 += tc[_DFA, 2] - y2 - tc[_TA, 2] - 2.0 * g2 + h2
    # M = [[m_tot 1, R X], [X^T R^T, J]], X = -[SR]x: with b = R^T f_t the rotation solves
    # (J - X^T (R^T R) X / m_tot) alpha = f_r - X^T b / m_tot. R^T R = 1 + E, E of the order of the
    # quaternion's drift from unit length times the rotation squared: one correction of the solution with
    # the factor of J - X^T X / m_tot takes E in.
    imt = cc[_CC_IMT]
    b0 = R[0, 0] * f0 + R[1, 0] * f1 + R[2, 0] * f2
    b1 = R[0, 1] * f0 + R[1, 1] * f1 + R[2, 1] * f2
    b2 = R[0, 2] * f0 + R[1, 2] * f1 + R[2, 2] * f2
    c0, c1, c2 = _cross(s0, s1, s2, b0, b1, b2)
    a0, a1, a2 = _solve_schur(tc, r0 - c0 * imt, r1 - c1 * imt, r2 - c2 * imt)
    # E u with u = SR x alpha = -X alpha: the right-hand side gains X^T E X alpha / m_tot, i.e.
    # -SR x (E u) / m_tot
    u0, u1, u2 = _cross(s0, s1, s2, a0, a1, a2)
    v0 = R[0, 0] * u0 + R[0, 1] * u1 + R[0, 2] * u2
    v1 = R[1, 0] * u0 + R[1, 1] * u1 + R[1, 2] * u2
    v2 = R[2, 0] * u0 + R[2, 1] * u1 + R[2, 2] * u2
    e0 = R[0, 0] * v0 + R[1, 0] * v1 + R[2, 0] * v2 - u0
    e1 = R[0, 1] * v0 + R[1, 1] * v1 + R[2, 1] * v2 - u1
    e2 = R[0, 2] * v0 + R[1, 2] * v1 + R[2, 2] * v2 - u2
    d0, d1, d2 = _cross(s0, s1, s2, e0, e1, e2)
    n0, n1, n2 = _solve_schur(tc, -d0 * imt, -d1 * imt, -d2 * imt)
    a0 += n0
    a1 += n1
    a2 += n2
    # translation (floor frame): m_tot a = f_t - R X alpha = f_t + R (SR x alpha)
    u0, u1, u2 = _cross(s0, s1, s2, a0, a1, a2)
    acc[0] = (f0 + R[0, 0] * u0 + R[0, 1] * u1 + R[0, 2] * u2) * imt
    acc[1] = (f1 + R[1, 0] * u0 + R[1, 1] * u1 + R[1, 2] * u2) * imt
    acc[2] = (f2 + R[2, 0] * u0 + R[2, 1] * u1 + R[2, 2] * u2) * imt
    acc[3] = a0
    acc[4] = a1
    acc[5] = a2


@njit(cache=True)
def accel(P, c, level, t, x, idx, W):
    """Accelerations of the base at time ``t`` (s) and state ``x``, written to ``W.acc`` (6,).

    ``acc = [d2u/dt2 (m/s^2), dw/dt (rad/s^2)]``. ``W`` is the case's scratch space
    (``engine.model.Work``). Makes the time-only terms those of ``t`` (:func:`time_terms`: the stages, the
    floor and the feedforward actuators at ``t``), then evaluates the level's own equations
    (:func:`accel_lti`, :func:`accel_ltv`, :func:`accel_nonlinear`). Returns False when the level's mass
    matrix is not positive definite.
    """
    if not time_terms(P, c, level, t, idx, W):
        return False
    if level == LTI:
        return accel_lti(P, c, x, W)
    if level == LTV:
        return accel_ltv(P, c, x, W)
    return accel_nonlinear(P, c, x, W)


@njit(cache=True)
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


@njit(cache=True)
def derivative(P, c, level, t, x, idx, W, dx):
    """Time derivative ``dx`` of the state ``x`` at ``t`` (s). Returns False on a singular mass matrix."""
    okm = accel(P, c, level, t, x, idx, W)
    rates(level, x, W.acc, dx)
    return okm
