"""What shakes the base: the stages' motion along their profiles, the floor's motion under the mounts, and
the LTI level's generalised force of both.

Numba functions on case ``c`` of the kernel parameters ``P`` (``engine.kernels.params.Params``). A stage
travels along its axis on a piecewise-polynomial profile: piece start times ``P.pt`` (s), and at each start
the position (m), velocity (m/s) and acceleration (m/s^2), with a constant jerk (m/s^3) over the piece;
``idx`` (m,) holds the piece each stage is on (-1 before its first). The floor moves as a sine per axis
(amplitude ``P.famp`` m, ``P.fomega`` rad/s, ``P.fphase`` rad) plus a recorded displacement (samples
``P.fd`` m at ``P.ft`` s).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from isolab.engine.kernels.rotations import cross


@njit(cache=True, fastmath=False)
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


@njit(cache=True, fastmath=False)
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


@njit(cache=True, fastmath=False)
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


@njit(cache=True, fastmath=False)
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


@njit(cache=True, fastmath=False)
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


@njit(cache=True, fastmath=False)
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
        t0, t1, t2 = cross(rho[i, 0], rho[i, 1], rho[i, 2], a0, a1, a2)
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
        m0, m1, m2 = cross(P.d[c, j, 0], P.d[c, j, 1], P.d[c, j, 2], p0, p1, p2)
        f[3] += m0
        f[4] += m1
        f[5] += m2
