"""Classical fourth-order Runge-Kutta at a fixed step.

The driver (``engine.integrators.stepping``) splits a step that contains breakpoints of the stage profiles
into sub-steps, each on one polynomial piece: the forcing is smooth inside every sub-step, so the method
keeps fourth order, and a jerk phase shorter than the step is integrated over the time it lasts instead of
being sampled. Stable for an undamped mode while ``w dt < 2 sqrt(2)`` (the sub-steps are shorter, so no
less stable).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from isolab.engine.kernels.cached_terms import (
    extra_inputs,
    key_holds,
    moving_terms,
    pack_case,
    recorded_and_feedforward,
    set_key,
    stages_and_floor,
    stages_unchanged,
    terms_at_rest,
)
from isolab.engine.kernels.dynamics import derivative, ltv_acc, nonlinear_acc, rates, slot_rates
from isolab.engine.kernels.params import LTI, LTV, NONLINEAR, borrowed

NAME = "rk4"
LEVELS = ("lti", "ltv", "nonlinear")
ORDER = 4
EXACT = False
GUARDED = True
"""An explicit fixed-step method: the stability guard sizes its step."""
SCRATCH_ROWS = 5
"""State-sized rows of scratch a step needs: the stage state and the four slopes."""


@njit(cache=True, fastmath=False)
def step(P, c, level, t, h, x, S, idx, W):
    """One RK4 step of ``h`` s from ``t`` (s) on the pieces ``idx``, ``x`` in place; ``S`` (5, nx)
    scratch. Returns False when a mass matrix is singular.

    At the time-varying levels the terms that depend on time only are evaluated at ``t``, ``t + h/2`` and
    ``t + h`` (``engine.kernels.cached_terms.time_terms``; those at ``t`` are usually still there from the
    previous step's end), and the slopes read them through arrays bound once per step. The time-varying
    levels only: :func:`step_lti` steps the LTI level, and :func:`step_nonlinear` the nonlinear level for a
    case without recorded floor motion or feedforward actuators (:func:`lean_nonlinear`; the driver calls
    the one that applies, so numba compiles only those of its level)."""
    nx = x.shape[0]
    xs = S[0]
    # The workspace's arrays bound once, and only functions that call no other (whose own references
    # numba leaves out) called on the way: an array read from ``P`` or ``W``, or handed to a function that
    # calls others, counts a reference (an atomic add) each time, which costs more than the arithmetic.
    key, tc, cc, cs, cm, sw, K, R, F, acc = W.key, W.tc, W.cc, W.cs, W.cm, W.sw, W.cK, W.R, W.F, W.acc
    g, ffon, gstiff, pbase = P.g, P.ffon, P.gstiff, P.pbase
    pack_case(P, c, W, cc)
    extra = extra_inputs(ffon, cc)
    for i in range(nx):
        xs[i] = x[i]
    ok = True
    for s in range(4):
        # the slope at t (from x), t + h/2 (twice) and t + h, each at the stage state xs
        ts = t if s == 0 else (t + h if s == 3 else t + 0.5 * h)
        if s != 2 and not key_holds(c, level, ts, idx, key):
            stages_and_floor(ts, idx, cc, cs, sw, tc)
            if extra:
                recorded_and_feedforward(P, c, ts, idx, W, cm, tc)
            set_key(c, level, ts, moving_terms(level, g, cc, cs, cm, sw, tc), idx, key)
        ok &= key[3] != 0.0
        k = S[1 + s]
        if level == LTV:
            ltv_acc(xs, tc, K, cc, g, ffon, gstiff, acc)
        else:
            nonlinear_acc(xs, tc, cc, cm, R, F, acc, g, pbase)
        rates(level, xs, acc, k)
        if level == LTV and nx > 12:
            slot_rates(P, c, ts, xs, idx, acc, k)
        if s < 3:
            a = h if s == 2 else 0.5 * h
            for i in range(nx):
                xs[i] = x[i] + a * k[i]
    if not ok:
        return False
    _combine(level, h, x, S[1], S[2], S[3], S[4])
    return True


@njit(cache=True, inline="always")
def lean_nonlinear(P, c):
    """Whether case ``c`` of the batch ``P`` steps at the nonlinear level through :func:`step_nonlinear`: no
    floor motion recorded for it and no feedforward actuator of its own (a recorded floor of zeros and
    actuators without gain are none; the others take :func:`step`). Chosen per case, so that a case's
    results do not depend on the other cases of its batch: the lean step fuses its multiply-adds, so it
    equals the general step to round-off, not bit for bit."""
    if P.ffon:
        ffg = P.ffg
        for j in range(ffg.shape[1]):
            if ffg[c, j] != 0.0:
                return False
    fd = P.fd
    for dd in range(fd.shape[1]):
        for i in range(fd.shape[2]):
            if fd[c, dd, i] != 0.0:
                return False
    return True


@njit(cache=True, inline="always")
def nonlinear_views(P, c, W, x, S, idx, swt):
    """Case ``c``'s terms packed into the workspace ``W`` (``engine.kernels.cached_terms.pack_case``) and the
    arrays :func:`step_nonlinear` reads, as views without owner (``engine.kernels.params.borrowed``): the
    state ``x``, the scratch ``S``, the pieces ``idx``, the workspace's arrays and ``swt`` (m, 9), where a
    slope puts the stages' state at its time before it replaces ``W.sw``. Made once per case by the driver,
    in its own body (the function is inlined), so no step counts a reference to them."""
    pack_case(P, c, W, W.cc)
    b = borrowed
    return (
        b(x),
        b(S),
        b(idx),
        b(W.key),
        b(W.tc),
        b(W.cc),
        b(W.cs),
        b(W.cm),
        b(W.sw),
        b(swt),
        b(W.R),
        b(W.F),
    )


@njit(cache=True, inline="always")
def step_nonlinear(c, t, h, V, g, pbase):
    """:func:`step` at the nonlinear level for a case without recorded floor motion or feedforward
    actuators: the same arithmetic with no array reference counted inside the step.

    ``V`` are the case's arrays as views without owner (:func:`nonlinear_views`), ``g`` gravity (m/s^2) and
    ``pbase`` the preload convention (``Params.pbase``). Numba counts a reference (an atomic add and
    subtract, dearer than the arithmetic here) for every array bound, sliced or passed on, and for the
    structs a kernel takes; on views made once per case a step counts none. The driver inlines the step: a
    called step counts its arguments' references at every call, which costs what the views save."""
    x, S, idx, key, tc, cc, cs, cm, sw, swt, R, F = V
    nx = x.shape[0]
    for i in range(nx):
        S[0, i] = x[i]
    ok = True
    for s in range(4):  # one slope in the loop's body: the slope's code compiled once, not four times
        ts = t if s == 0 else (t + h if s == 3 else t + 0.5 * h)
        k = S[1 + s]
        ok &= _nonlinear_slope(c, ts, s != 2, S[0], k, idx, key, tc, cc, cs, cm, sw, swt, R, F, g, pbase)
        if s < 3:
            a = h if s == 2 else 0.5 * h
            for i in range(nx):
                S[0, i] = x[i] + a * k[i]
    if not ok:
        return False
    _combine(NONLINEAR, h, x, S[1], S[2], S[3], S[4])
    return True


@njit(cache=True, inline="always")
def _nonlinear_slope(c, ts, check, xs, k, idx, key, tc, cc, cs, cm, sw, swt, R, F, g, pbase):
    """One slope ``k`` of the nonlinear level at ``ts`` (s) and the stage state ``xs``; the time-only terms
    made those of ``ts`` first where ``check`` (the middle slopes share them). Returns whether the mass
    matrix is positive definite.

    Where every stage stands still on the pieces the terms were evaluated on, and no floor sine moves, the
    terms are kept without evaluating the stages (``engine.kernels.cached_terms.terms_at_rest``); where the
    stages' state at ``ts`` is bit for bit the one the terms in ``tc`` were evaluated from, they are kept
    too (``engine.kernels.cached_terms.stages_unchanged``): the floor's rows are made those of ``ts``, and
    :func:`moving_terms` would give the same values again."""
    if check and not key_holds(c, NONLINEAR, ts, idx, key):
        if terms_at_rest(c, NONLINEAR, idx, key, cc, cs):
            key[2] = ts  # every stage stands still on the same pieces: the terms are those of ts
        else:
            stages_and_floor(ts, idx, cc, cs, swt, tc)
            if stages_unchanged(c, NONLINEAR, key, swt, sw):
                set_key(c, NONLINEAR, ts, key[3] != 0.0, idx, key)
            else:
                for i in range(sw.shape[0]):
                    for q in range(sw.shape[1]):
                        sw[i, q] = swt[i, q]
                set_key(c, NONLINEAR, ts, moving_terms(NONLINEAR, g, cc, cs, cm, sw, tc), idx, key)
    nonlinear_acc(xs, tc, cc, cm, R, F, k[7:], g, pbase)  # the accelerations straight into the slope
    q0, q1, q2, q3 = xs[3], xs[4], xs[5], xs[6]
    w0, w1, w2 = xs[10], xs[11], xs[12]
    k[0], k[1], k[2] = xs[7], xs[8], xs[9]
    k[3] = 0.5 * (-q1 * w0 - q2 * w1 - q3 * w2)
    k[4] = 0.5 * (q0 * w0 + q2 * w2 - q3 * w1)
    k[5] = 0.5 * (q0 * w1 - q1 * w2 + q3 * w0)
    k[6] = 0.5 * (q0 * w2 + q1 * w1 - q2 * w0)
    return key[3] != 0.0


@njit(cache=True, fastmath=False)
def step_lti(P, c, t, h, x, S, idx, W):
    """:func:`step` at the LTI level (each slope through ``engine.kernels.dynamics.derivative``)."""
    nx = x.shape[0]
    xs, k1, k2, k3, k4 = S[0], S[1], S[2], S[3], S[4]
    ok = derivative(P, c, LTI, t, x, idx, W, k1)
    for i in range(nx):
        xs[i] = x[i] + 0.5 * h * k1[i]
    ok &= derivative(P, c, LTI, t + 0.5 * h, xs, idx, W, k2)
    for i in range(nx):
        xs[i] = x[i] + 0.5 * h * k2[i]
    ok &= derivative(P, c, LTI, t + 0.5 * h, xs, idx, W, k3)
    for i in range(nx):
        xs[i] = x[i] + h * k3[i]
    ok &= derivative(P, c, LTI, t + h, xs, idx, W, k4)
    if not ok:
        return False
    _combine(LTI, h, x, k1, k2, k3, k4)
    return True


@njit(cache=True, inline="always")
def _combine(level, h, x, k1, k2, k3, k4):
    """The RK4 update of ``x`` from the four slopes (and the quaternion back to unit length)."""
    for i in range(x.shape[0]):
        x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
    if level == NONLINEAR:
        r = 1.0 / np.sqrt(x[3] ** 2 + x[4] ** 2 + x[5] ** 2 + x[6] ** 2)
        for i in range(3, 7):
            x[i] *= r


def step_matrix(A: np.ndarray, h: np.ndarray) -> np.ndarray:
    """One-step map (C, n, n) of classical RK4 on ``x' = A x``; ``A`` (C, n, n) 1/s, steps ``h`` (C,) s:
    the degree-4 Taylor polynomial of ``expm(A h)``."""
    h = np.asarray(h, dtype=float)[:, None, None]
    Z = h * A
    Z2 = Z @ Z
    return np.eye(A.shape[-1]) + Z + Z2 / 2 + Z2 @ Z / 6 + Z2 @ Z2 / 24
