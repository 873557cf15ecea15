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


@njit(cache=True)
def solve_spd(A, b, n):
    """Solve ``A x = b`` in place (``b`` becomes ``x``) for a symmetric positive definite ``A`` (n, n).

    Cholesky without pivoting; ``A`` is overwritten by its factor. Returns False when ``A`` is not
    positive definite.
    """
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= A[j, k] * A[j, k]
        if not s > 0.0:
            return False
        ljj = np.sqrt(s)
        A[j, j] = ljj
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= A[i, k] * A[j, k]
            A[i, j] = s / ljj
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= A[i, k] * b[k]
        b[i] = s / A[i, i]
    for i in range(n - 1, -1, -1):
        s = b[i]
        for k in range(i + 1, n):
            s -= A[k, i] * b[k]
        b[i] = s / A[i, i]
    return True


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
    for i in range(P.sm.shape[1]):
        k = idx[i]
        if k < 0:
            j = 0.0
            a = 0.0
            v = 0.0
            s = P.ps[c, i, 0]
        else:
            tau = t - P.pt[c, i, k]
            j = P.pj[c, i, k]
            a = P.pa[c, i, k] + j * tau
            v = P.pv[c, i, k] + (P.pa[c, i, k] + 0.5 * j * tau) * tau
            s = P.ps[c, i, k] + (P.pv[c, i, k] + (0.5 * P.pa[c, i, k] + j * tau / 6.0) * tau) * tau
        p = P.parent[i]
        for dd in range(3):
            ed = P.e[c, i, dd]
            rho[i, dd] = P.rho_h[c, i, dd] + s * ed
            vr[i, dd] = v * ed
            ar[i, dd] = a * ed
            jr[i, dd] = j * ed
            if p >= 0:
                rho[i, dd] += rho[p, dd] - P.rho_h[c, p, dd]
                vr[i, dd] += vr[p, dd]
                ar[i, dd] += ar[p, dd]
                jr[i, dd] += jr[p, dd]


@njit(cache=True)
def recorded_floor(P, c, t, xf, vf):
    """Add the recorded floor displacement (m) and velocity (m/s) at ``t`` (s) to ``xf``, ``vf`` (3,).

    Linear interpolation between samples; zero before the first sample, held after the last.
    """
    nf = P.ft.shape[0]
    if nf > 0 and t >= P.ft[0]:
        lo, hi = 0, nf  # last sample at or before t: P.ft[lo] <= t < P.ft[hi]
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if P.ft[mid] <= t:
                lo = mid
            else:
                hi = mid
        i = lo
        if i >= nf - 1:
            for dd in range(3):
                xf[dd] += P.fd[c, dd, nf - 1]
        else:
            dt = P.ft[i + 1] - P.ft[i]
            for dd in range(3):
                slope = (P.fd[c, dd, i + 1] - P.fd[c, dd, i]) / dt
                xf[dd] += P.fd[c, dd, i] + slope * (t - P.ft[i])
                vf[dd] += slope


@njit(cache=True)
def floor_motion(P, c, t, xf, vf):
    """Floor displacement ``xf`` (3,) m and velocity ``vf`` (3,) m/s under the isolators at ``t`` (s)."""
    for dd in range(3):
        amp = P.famp[c, dd]
        if amp == 0.0:
            xf[dd] = 0.0
            vf[dd] = 0.0
            continue
        w = P.fomega[c, dd]
        arg = w * t + P.fphase[c, dd]
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
    n = P.d.shape[1]
    if level == NONLINEAR:
        off = 7
    else:
        off = 6
    u0, u1, u2 = x[0], x[1], x[2]
    v0, v1, v2 = x[off], x[off + 1], x[off + 2]
    w0, w1, w2 = x[off + 3], x[off + 4], x[off + 5]
    for j in range(n):
        d0, d1, d2 = P.d[c, j, 0], P.d[c, j, 1], P.d[c, j, 2]
        r0, r1, r2 = mount_offset(level, x, R, d0, d1, d2)
        if level == NONLINEAR:
            b0, b1, b2 = _cross(w0, w1, w2, d0, d1, d2)
            q0 = R[0, 0] * b0 + R[0, 1] * b1 + R[0, 2] * b2
            q1 = R[1, 0] * b0 + R[1, 1] * b1 + R[1, 2] * b2
            q2 = R[2, 0] * b0 + R[2, 1] * b1 + R[2, 2] * b2
        else:
            q0, q1, q2 = _cross(w0, w1, w2, d0, d1, d2)
        rel = 1.0 - P.sky[c, j]
        F[j, 0] = -P.k[c, j, 0] * (u0 + r0 - xf[0]) - P.cd[c, j, 0] * (v0 + q0 - rel * vf[0])
        F[j, 1] = -P.k[c, j, 1] * (u1 + r1 - xf[1]) - P.cd[c, j, 1] * (v1 + q1 - rel * vf[1])
        F[j, 2] = -P.k[c, j, 2] * (u2 + r2 - xf[2]) - P.cd[c, j, 2] * (v2 + q2 - rel * vf[2])


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


@njit(cache=True)
def _rigid_mass(P, c, M, acc):
    """Start the mass matrix ``M`` (6, 6) from the machine's own mass and inertia (c.g. frame) and clear
    the accelerations ``acc`` (6,)."""
    mt = P.mtot[c]
    for i in range(6):
        acc[i] = 0.0
        for j in range(6):
            M[i, j] = 0.0
    for i in range(3):
        M[i, i] = mt
        for j in range(3):
            M[3 + i, 3 + j] = P.inertia[c, i, j]


@njit(cache=True)
def _stage_rotary_mass(M, m, r0, r1, r2):
    """Add a point mass ``m`` (kg) at ``r`` (m) to the rotation-rotation block of ``M``:
    ``m [rho]x^T [rho]x = m (|rho|^2 1 - rho rho^T)``."""
    rr = r0 * r0 + r1 * r1 + r2 * r2
    M[3, 3] += m * (rr - r0 * r0)
    M[4, 4] += m * (rr - r1 * r1)
    M[5, 5] += m * (rr - r2 * r2)
    M[3, 4] -= m * r0 * r1
    M[4, 3] -= m * r0 * r1
    M[3, 5] -= m * r0 * r2
    M[5, 3] -= m * r0 * r2
    M[4, 5] -= m * r1 * r2
    M[5, 4] -= m * r1 * r2


@njit(cache=True, inline="always")
def accel_lti(P, c, x, W):
    """Accelerations ``W.acc`` (6,) of the LTI level: ``A21 x + A22 v + M^-1 f`` with the stages and the
    floor as known inputs (``W`` holds their state at the current time). Always True."""
    lti_forcing(P, c, W.rho, W.ar, W.xf, W.vf, W.f)
    if P.ffon:  # the feedforward actuators (W.Fa, filled by accel): a known input too
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
            s += P.a21[c, i, j] * x[j] + P.a22[c, i, j] * x[6 + j] + P.minv[c, i, j] * W.f[j]
        W.acc[i] = s
    return True


@njit(cache=True, inline="always")
def accel_ltv(P, c, x, W):
    """Accelerations ``W.acc`` (6,) of the LTV level: small rotations, mass matrix and weight moments
    following the stages' travel, Coriolis terms of the stages. False on a singular mass matrix."""
    g = P.g
    w0, w1, w2 = x[9], x[10], x[11]
    isolator_forces(P, c, LTV, x, W.R, W.xf, W.vf, W.F)
    _rigid_mass(P, c, W.M, W.acc)
    for j in range(P.d.shape[1]):
        F0, F1, F2 = W.F[j, 0], W.F[j, 1], W.F[j, 2]
        W.acc[0] += F0
        W.acc[1] += F1
        W.acc[2] += F2
        d0, d1, d2 = P.d[c, j, 0], P.d[c, j, 1], P.d[c, j, 2]
        m0, m1, m2 = _cross(d0, d1, d2, F0, F1, F2)
        if P.gstiff:
            # d x (-theta x F0) with F0 = (0, 0, f0)
            tf0, tf1, tf2 = _cross(x[3], x[4], x[5], 0.0, 0.0, P.f0[c, j])
            n0, n1, n2 = _cross(d0, d1, d2, -tf0, -tf1, -tf2)
            m0 += n0
            m1 += n1
            m2 += n2
        W.acc[3] += m0
        W.acc[4] += m1
        W.acc[5] += m2
    if P.ffon:
        # feedforward actuators (machine axes, W.Fa): they turn with the base as the stages' drive does
        for j in range(P.d.shape[1]):
            f0, f1, f2 = W.Fa[j, 0], W.Fa[j, 1], W.Fa[j, 2]
            t0, t1, t2 = _cross(x[3], x[4], x[5], f0, f1, f2)
            W.acc[0] += f0 + t0
            W.acc[1] += f1 + t1
            W.acc[2] += f2 + t2
            m0, m1, m2 = _cross(P.d[c, j, 0], P.d[c, j, 1], P.d[c, j, 2], f0, f1, f2)
            W.acc[3] += m0
            W.acc[4] += m1
            W.acc[5] += m2
    for i in range(P.sm.shape[1]):
        m = P.sm[c, i]
        r0, r1, r2 = W.rho[i, 0], W.rho[i, 1], W.rho[i, 2]
        a0, a1, a2 = W.ar[i, 0], W.ar[i, 1], W.ar[i, 2]
        c0, c1, c2 = _cross(w0, w1, w2, W.vr[i, 0], W.vr[i, 1], W.vr[i, 2])
        # translation: -m (a_rel + theta x a_rel + 2 w x v_rel)
        ta0, ta1, ta2 = _cross(x[3], x[4], x[5], a0, a1, a2)
        W.acc[0] -= m * (a0 + ta0 + 2.0 * c0)
        W.acc[1] -= m * (a1 + ta1 + 2.0 * c1)
        W.acc[2] -= m * (a2 + ta2 + 2.0 * c2)
        # rotation: -m rho x (a_rel + 2 w x v_rel) + m (rho - rho_h) x g + m rho x (-theta x g)
        h0, h1, h2 = _cross(r0, r1, r2, a0 + 2.0 * c0, a1 + 2.0 * c1, a2 + 2.0 * c2)
        s0 = r0 - P.rho_h[c, i, 0]
        s1 = r1 - P.rho_h[c, i, 1]
        W.acc[3] += -m * h0 - m * s1 * g
        W.acc[4] += -m * h1 + m * s0 * g
        W.acc[5] += -m * h2
        if P.gstiff:
            # -theta x g = theta x (0, 0, g)
            tg0, tg1, tg2 = _cross(x[3], x[4], x[5], 0.0, 0.0, g)
            n0, n1, n2 = _cross(r0, r1, r2, tg0, tg1, tg2)
            W.acc[3] += m * n0
            W.acc[4] += m * n1
            W.acc[5] += m * n2
        # mass matrix coupling: translation row -m [rho]x, rotation row m [rho]x
        for col in range(3):
            e0 = 1.0 if col == 0 else 0.0
            e1 = 1.0 if col == 1 else 0.0
            e2 = 1.0 if col == 2 else 0.0
            x0, x1, x2 = _cross(e0, e1, e2, r0, r1, r2)  # column col of -[rho]x
            W.M[0, 3 + col] += m * x0
            W.M[1, 3 + col] += m * x1
            W.M[2, 3 + col] += m * x2
            W.M[3 + col, 0] += m * x0
            W.M[3 + col, 1] += m * x1
            W.M[3 + col, 2] += m * x2
        _stage_rotary_mass(W.M, m, r0, r1, r2)
    return solve_spd(W.M, W.acc, 6)


@njit(cache=True, inline="always")
def accel_nonlinear(P, c, x, W):
    """Accelerations ``W.acc`` (6,) of the nonlinear level: finite rotation (quaternion), the preload
    turning with the base, the gyroscopic term and the stages' full relative kinematics. False on a
    singular mass matrix."""
    g = P.g
    quat_to_matrix(x[3:7], W.R)
    R = W.R
    w0, w1, w2 = x[10], x[11], x[12]
    isolator_forces(P, c, NONLINEAR, x, R, W.xf, W.vf, W.F)
    _rigid_mass(P, c, W.M, W.acc)
    # isolators: force (floor frame) and moment (body frame) with the vertical preload
    for j in range(P.d.shape[1]):
        F0, F1, F2 = W.F[j, 0], W.F[j, 1], W.F[j, 2]
        W.acc[0] += F0
        W.acc[1] += F1
        W.acc[2] += F2
        if P.pbase:
            # the preload turns with the base: (0, 0, f0) in the body, R (0, 0, f0) in the floor frame
            f0 = P.f0[c, j]
            W.acc[0] += f0 * R[0, 2]
            W.acc[1] += f0 * R[1, 2]
            W.acc[2] += f0 * (R[2, 2] - 1.0)
            G0 = R[0, 0] * F0 + R[1, 0] * F1 + R[2, 0] * F2
            G1 = R[0, 1] * F0 + R[1, 1] * F1 + R[2, 1] * F2
            G2 = R[0, 2] * F0 + R[1, 2] * F1 + R[2, 2] * F2 + f0
        else:
            T2 = F2 + P.f0[c, j]
            G0 = R[0, 0] * F0 + R[1, 0] * F1 + R[2, 0] * T2
            G1 = R[0, 1] * F0 + R[1, 1] * F1 + R[2, 1] * T2
            G2 = R[0, 2] * F0 + R[1, 2] * F1 + R[2, 2] * T2
        m0, m1, m2 = _cross(P.d[c, j, 0], P.d[c, j, 1], P.d[c, j, 2], G0, G1, G2)
        W.acc[3] += m0
        W.acc[4] += m1
        W.acc[5] += m2
    if P.ffon:
        # feedforward actuators, fixed in the machine (W.Fa, body axes)
        for j in range(P.d.shape[1]):
            f0, f1, f2 = W.Fa[j, 0], W.Fa[j, 1], W.Fa[j, 2]
            W.acc[0] += R[0, 0] * f0 + R[0, 1] * f1 + R[0, 2] * f2
            W.acc[1] += R[1, 0] * f0 + R[1, 1] * f1 + R[1, 2] * f2
            W.acc[2] += R[2, 0] * f0 + R[2, 1] * f1 + R[2, 2] * f2
            m0, m1, m2 = _cross(P.d[c, j, 0], P.d[c, j, 1], P.d[c, j, 2], f0, f1, f2)
            W.acc[3] += m0
            W.acc[4] += m1
            W.acc[5] += m2
    # gyroscopic term
    I0 = P.inertia[c, 0, 0] * w0 + P.inertia[c, 0, 1] * w1 + P.inertia[c, 0, 2] * w2
    I1 = P.inertia[c, 1, 0] * w0 + P.inertia[c, 1, 1] * w1 + P.inertia[c, 1, 2] * w2
    I2 = P.inertia[c, 2, 0] * w0 + P.inertia[c, 2, 1] * w1 + P.inertia[c, 2, 2] * w2
    y0, y1, y2 = _cross(w0, w1, w2, I0, I1, I2)
    W.acc[3] -= y0
    W.acc[4] -= y1
    W.acc[5] -= y2
    # the machine's own weight acts at its c.g.: no moment; stage weights below
    gb0, gb1, gb2 = -g * R[2, 0], -g * R[2, 1], -g * R[2, 2]  # R^T (0, 0, -g)
    for i in range(P.sm.shape[1]):
        m = P.sm[c, i]
        r0, r1, r2 = W.rho[i, 0], W.rho[i, 1], W.rho[i, 2]
        a0, a1, a2 = W.ar[i, 0], W.ar[i, 1], W.ar[i, 2]
        c0, c1, c2 = _cross(w0, w1, w2, W.vr[i, 0], W.vr[i, 1], W.vr[i, 2])
        # body-frame acceleration terms that do not depend on the unknown accelerations
        o0, o1, o2 = _cross(w0, w1, w2, r0, r1, r2)
        z0, z1, z2 = _cross(w0, w1, w2, o0, o1, o2)
        k0 = z0 + 2.0 * c0 + a0
        k1 = z1 + 2.0 * c1 + a1
        k2 = z2 + 2.0 * c2 + a2
        # translation (floor frame): -m R k
        W.acc[0] -= m * (R[0, 0] * k0 + R[0, 1] * k1 + R[0, 2] * k2)
        W.acc[1] -= m * (R[1, 0] * k0 + R[1, 1] * k1 + R[1, 2] * k2)
        W.acc[2] -= m * (R[2, 0] * k0 + R[2, 1] * k1 + R[2, 2] * k2)
        # rotation (body frame): rho x (m R^T g - m k)
        h0, h1, h2 = _cross(r0, r1, r2, m * gb0 - m * k0, m * gb1 - m * k1, m * gb2 - m * k2)
        W.acc[3] += h0
        W.acc[4] += h1
        W.acc[5] += h2
        # mass matrix coupling: translation row -m R [rho]x, rotation row m [rho]x R^T
        for col in range(3):
            e0 = 1.0 if col == 0 else 0.0
            e1 = 1.0 if col == 1 else 0.0
            e2 = 1.0 if col == 2 else 0.0
            x0, x1, x2 = _cross(e0, e1, e2, r0, r1, r2)  # column col of -[rho]x
            for row in range(3):
                W.M[row, 3 + col] += m * (R[row, 0] * x0 + R[row, 1] * x1 + R[row, 2] * x2)
                W.M[3 + col, row] += m * (R[row, 0] * x0 + R[row, 1] * x1 + R[row, 2] * x2)
        _stage_rotary_mass(W.M, m, r0, r1, r2)
    return solve_spd(W.M, W.acc, 6)


@njit(cache=True)
def accel(P, c, level, t, x, idx, W):
    """Accelerations of the base at time ``t`` (s) and state ``x``, written to ``W.acc`` (6,).

    ``acc = [d2u/dt2 (m/s^2), dw/dt (rad/s^2)]``. ``W`` is the case's scratch space
    (``engine.model.Work``). Evaluates the stages and the floor at ``t``, then the level's own equations
    (:func:`accel_lti`, :func:`accel_ltv`, :func:`accel_nonlinear`). Returns False when the level's mass
    matrix is not positive definite.
    """
    stage_state(P, c, t, idx, W.rho, W.vr, W.ar, W.jr)
    floor_motion(P, c, t, W.xf, W.vf)
    if P.ffon:
        feedforward_forces(P, c, t, idx, W)
    if level == LTI:
        return accel_lti(P, c, x, W)
    if level == LTV:
        return accel_ltv(P, c, x, W)
    return accel_nonlinear(P, c, x, W)


@njit(cache=True)
def derivative(P, c, level, t, x, idx, W, dx):
    """Time derivative ``dx`` of the state ``x`` at ``t`` (s). Returns False on a singular mass matrix."""
    okm = accel(P, c, level, t, x, idx, W)
    if level == NONLINEAR:
        q0, q1, q2, q3 = x[3], x[4], x[5], x[6]
        w0, w1, w2 = x[10], x[11], x[12]
        dx[0], dx[1], dx[2] = x[7], x[8], x[9]
        dx[3] = 0.5 * (-q1 * w0 - q2 * w1 - q3 * w2)
        dx[4] = 0.5 * (q0 * w0 + q2 * w2 - q3 * w1)
        dx[5] = 0.5 * (q0 * w1 - q1 * w2 + q3 * w0)
        dx[6] = 0.5 * (q0 * w2 + q1 * w1 - q2 * w0)
        for i in range(6):
            dx[7 + i] = W.acc[i]
    else:
        for i in range(6):
            dx[i] = x[6 + i]
            dx[6 + i] = W.acc[i]
    return okm
