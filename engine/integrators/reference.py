"""Adaptive reference: scipy ``solve_ivp`` (DOP853) at tight tolerance, restarted at every breakpoint.

Slow, and meant for tests, benchmarks and the error estimate of every stored study: it tells how much the
fixed-step integrators lose. Between breakpoints of the stage profiles (and samples of a recorded floor
motion) the right-hand side is smooth, so restarting there keeps the adaptive method at its full accuracy.

``solve_ivp`` calls the right-hand side from Python, about sixteen times per step. A kernel call from
Python types every argument, and a struct's type is looked up in Python: the kernels' ``Params``, ``Work``
and ``Peaks`` structs with the case, its level and its stages' pieces cost 2.5 us a call, the kernel itself
0.35 us. The right-hand side (:func:`slope`) therefore takes one struct of its own, :class:`ReferenceCase`,
and returns a new array (``solve_ivp`` keeps the slope it is given, so a slope written into one array
would change under it). Each segment's samples are observed in one kernel call (:func:`observe_samples`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import partial
from typing import Any

import numpy as np
from numba import njit, typeof
from numba.core import types
from numba.experimental import structref

from isolab.engine.kernels.dynamics import derivative
from isolab.engine.kernels.excitation import advance_pieces
from isolab.engine.kernels.params import NONLINEAR, Params, Work
from isolab.engine.kernels.peaks import Peaks, observe, observe_nonlinear
from isolab.engine.kernels.structs import kernel_struct
from isolab.engine.results import FAILED, OK, UNSTABLE

NAME = "reference"
LEVELS = ("lti", "ltv", "nonlinear")
ORDER = None
"""Adaptive: its error follows the tolerances, not a step."""
EXACT = False
GUARDED = False
RTOL = 1e-10
ATOL = 1e-13


@structref.register
class ReferenceCaseType(types.StructRef):
    """The numba type of a :class:`ReferenceCase`."""


class ReferenceCase(structref.StructRefProxy):
    """One case as the reference's kernels take it, as one reference: the kernels' structs ``P``, ``W``
    and ``O`` (``Params``, ``Work``, ``Peaks``), the case ``c``, its fidelity ``level`` and ``idx``, each
    stage's current profile piece (an array the segments advance in place)."""


structref.define_proxy(ReferenceCase, ReferenceCaseType, ["P", "W", "O", "c", "level", "idx"])


@njit(cache=True, fastmath=False)
def reference_case(P, W, O, c, level, idx):
    """The :class:`ReferenceCase` of case ``c`` (built in a cached kernel: numba compiles a struct's own
    constructor anew in every process)."""
    return ReferenceCase(P, W, O, c, level, idx)


@njit(cache=True, fastmath=False)
def slope(case, t, y):
    """The state's time derivative (a new array) of ``case`` (a :class:`ReferenceCase`) at ``t`` (s) and
    state ``y``: ``engine.kernels.dynamics.derivative``; ``solve_ivp`` calls it through
    :func:`case_slope`."""
    dx = np.zeros(y.shape[0])
    derivative(case.P, case.c, case.level, t, y, case.idx, case.W, dx)
    return dx


@njit(cache=True, fastmath=False)
def normalise_quaternion(y):
    """Scale the nonlinear state's attitude quaternion ``y[3:7]`` to unit length in place, dividing by
    its norm summed in order (``sqrt(q . q)``: what ``np.linalg.norm`` gives, to within round-off where its
    BLAS dot sums in another order)."""
    s = 0.0
    for i in range(3, 7):
        s += y[i] * y[i]
    n = math.sqrt(s)
    for i in range(3, 7):
        y[i] /= n


@njit(cache=True, fastmath=False)
def observe_samples(case, times, states, step):
    """Observe ``case`` (a :class:`ReferenceCase`) at the ``times`` (k,), s, in the states ``states``
    (nx, k) (the nonlinear level's quaternion normalised first), output samples ``step`` onwards. Returns
    how many were observed before one diverged (``k`` when none did)."""
    y = np.empty(states.shape[0])
    for j in range(times.shape[0]):
        for i in range(states.shape[0]):
            y[i] = states[i, j]
        if case.level == NONLINEAR:
            normalise_quaternion(y)
            ok = observe_nonlinear(case.P, case.c, times[j], y, case.W, case.O, step + j)
        else:
            ok = observe(case.P, case.c, times[j], y, case.W, case.O, step + j)
        if not ok:
            return j
    return times.shape[0]


def case_slope(case: Any, y: np.ndarray) -> Callable[[float, np.ndarray], np.ndarray]:
    """:func:`slope` of ``case`` as ``solve_ivp`` calls a right-hand side, ``f(t, y)``, for states like
    ``y``: its compiled code bound to the case, called without numba's type dispatch (which looked up the
    struct's type on every call: 8 % of a reference run) nor a Python wrapper for the case argument."""
    entry = slope.compile((typeof(case), types.float64, typeof(y)))
    return partial(entry, case)


def watch(P: Any, c: int, level: int, t: float, x: np.ndarray, W: Any, O: Any, step: int) -> bool:
    """``engine.kernels.peaks.observe`` of case ``c`` at ``t`` (s), the nonlinear level through its own
    observer as the stepped methods' driver calls it (the same outputs, bit for bit)."""
    if level == NONLINEAR:
        return observe_nonlinear(P, c, t, x, W, O, step)
    return observe(P, c, t, x, W, O, step)


def run(
    P: Params,
    level: int,
    dt: np.ndarray,
    n_steps: np.ndarray,
    O: Peaks,
    W: Work,
    status: np.ndarray,
    rtol: float = RTOL,
    atol: float = ATOL,
    messages: list[str] | None = None,
) -> None:
    """Integrate every OK case, sampling the outputs every ``dt[c]`` s (``n_steps[c]`` of them); set
    ``status[c]`` (UNSTABLE when the base runs away, FAILED when ``solve_ivp`` fails, with the reason in
    ``messages[c]``). ``rtol`` and ``atol`` are ``solve_ivp``'s tolerances."""
    from scipy.integrate import solve_ivp  # on first use: most commands never load scipy

    C = dt.shape[0]
    m = P.sm.shape[1]
    KP, KO, KW = kernel_struct(P), kernel_struct(O), kernel_struct(W)
    nx = 13 if level == NONLINEAR else 12
    for c in range(C):
        if status[c] != OK:
            continue
        h = float(dt[c])
        N = int(n_steps[c])
        T = N * h
        x = np.zeros(nx)
        if level == NONLINEAR:
            x[3] = 1.0
        idx = np.full(m, -1, dtype=np.int64)  # each stage's piece, advanced to every segment's start
        case = reference_case(KP, KW, KO, c, level, idx)
        rhs = case_slope(case, x)
        bps = np.concatenate([P.pt[c].ravel(), P.ft])
        bps = np.unique(np.concatenate([[0.0, T], bps[(bps > 0) & (bps < T)]]))
        grid = np.arange(N + 1) * h
        watch(KP, c, level, 0.0, x, KW, KO, 0)
        k_next = 1
        for a, b in zip(bps[:-1], bps[1:], strict=True):
            if b - a <= 1e-12 * max(T, 1.0):
                continue
            advance_pieces(KP, c, a, idx, 1e-9 * h)
            sel = grid[(grid > a + 1e-12) & (grid <= b + 1e-12)]
            ends_on_grid = sel.size and abs(sel[-1] - b) <= 1e-12
            t_eval = np.clip(sel, a, b) if ends_on_grid else np.append(np.clip(sel, a, b), b)
            sol = solve_ivp(rhs, (a, b), x, method="DOP853", rtol=rtol, atol=atol, t_eval=t_eval)
            if not sol.success:
                status[c] = FAILED
                if messages is not None:
                    messages[c] = f"reference integration failed at t = {sol.t[-1]:.6g} s: {sol.message}"
                break
            if observe_samples(case, sel, np.ascontiguousarray(sol.y[:, : sel.size]), k_next) < sel.size:
                status[c] = UNSTABLE
                break
            k_next += sel.size
            x = sol.y[:, -1].copy()
            if level == NONLINEAR:
                normalise_quaternion(x)
