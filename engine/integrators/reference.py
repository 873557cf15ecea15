"""Adaptive reference: scipy ``solve_ivp`` (DOP853) at tight tolerance, restarted at every breakpoint.

Slow, and meant for tests and benchmarks: it tells how much the fixed-step integrators lose. Between
breakpoints of the stage profiles (and samples of a recorded floor motion) the right-hand side is smooth,
so restarting there keeps the adaptive method at its full accuracy.
"""

from __future__ import annotations

from typing import Any

import numpy as np

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


def watch(P: Any, c: int, level: int, t: float, x: np.ndarray, W: Any, O: Any, step: int) -> bool:
    """``engine.kernels.peaks.observe`` of case ``c`` at ``t`` (s), the nonlinear level through its own
    observer as the stepped methods' driver calls it (the same outputs, bit for bit)."""
    if level == NONLINEAR:
        return observe_nonlinear(P, c, t, x, W, O, step)
    return observe(P, c, level, t, x, W, O, step)


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
        idx = np.full(m, -1, dtype=np.int64)
        bps = np.concatenate([P.pt[c].ravel(), P.ft])
        bps = np.unique(np.concatenate([[0.0, T], bps[(bps > 0) & (bps < T)]]))
        grid = np.arange(N + 1) * h
        watch(KP, c, level, 0.0, x, KW, KO, 0)
        dx = np.zeros(nx)
        k_next = 1
        failed = False
        for a, b in zip(bps[:-1], bps[1:], strict=True):
            if b - a <= 1e-12 * max(T, 1.0):
                continue
            idx_a = idx.copy()
            advance_pieces(KP, c, a, idx_a, 1e-9 * h)

            def rhs(
                t: float, y: np.ndarray, idx_a: np.ndarray = idx_a, c: int = c, dx: np.ndarray = dx
            ) -> np.ndarray:
                derivative(KP, c, level, t, y, idx_a, KW, dx)
                return dx.copy()

            sel = grid[(grid > a + 1e-12) & (grid <= b + 1e-12)]
            ends_on_grid = sel.size and abs(sel[-1] - b) <= 1e-12
            t_eval = np.clip(sel, a, b) if ends_on_grid else np.append(np.clip(sel, a, b), b)
            sol = solve_ivp(rhs, (a, b), x, method="DOP853", rtol=rtol, atol=atol, t_eval=t_eval)
            if not sol.success:
                status[c] = FAILED
                if messages is not None:
                    messages[c] = f"reference integration failed at t = {sol.t[-1]:.6g} s: {sol.message}"
                failed = True
                break
            for j in range(sel.size):
                y = sol.y[:, j].copy()
                if level == NONLINEAR:
                    y[3:7] /= np.linalg.norm(y[3:7])
                if not watch(KP, c, level, sel[j], y, KW, KO, k_next):
                    status[c] = UNSTABLE
                    failed = True
                    break
                k_next += 1
            if failed:
                break
            x = sol.y[:, -1].copy()
            if level == NONLINEAR:
                x[3:7] /= np.linalg.norm(x[3:7])
            idx = idx_a
