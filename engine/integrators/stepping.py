"""The one driver loop of the fixed-step integrators: cases, steps, breakpoints, peaks, status.

Like scipy's ``OdeSolver.step`` over each method's ``_step_impl``, the driver owns everything that is the
same for every method: the loop over cases and output steps, splitting a step where a stage enters a new
piece of its motion profile, observing the outputs after each step, and the status of each case. A method
supplies only its step (``euler.step``, ``rk4.step`` with ``rk4.step_lti`` and ``rk4.step_nonlinear``,
``exact.step``) and, for ``exact``, where its sub-steps end and the maps it prepared. The method is named
by a code (:data:`EULER`, :data:`RK4`, :data:`EXACT`).

Each (method, level) pair has a driver of its own (:func:`pair_driver`, in :data:`ENTRIES`): the method's
and the level's codes are constants of the driver's closure, so numba drops the branches of the other
methods and levels before it types the loop, and an empty kernel cache compiles the kernels of the pair a
run steps and no others. At the linear levels a pair has two, one per observer (:data:`MAPPED`,
:data:`GENERAL`): each case goes to the one that observes it, so a run whose every case the output map
observes (a still floor, no recorded case: most scenes) never compiles the general observer. Each driver
is cached (numba keys a closure's cache entry by its constants). A driver taking the step kernel as an
argument, or a closure over a kernel, would be compiled anew in every process (neither is cacheable);
codes passed as plain ints from Python would go through numba's literal dispatch on every call and leave
every branch to be compiled.

The adaptive ``reference`` method is not stepped here: scipy's ``solve_ivp`` owns its own loop between
breakpoints (``engine.integrators.reference``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit

from isolab.engine.integrators import euler, exact, output_map, rk4
from isolab.engine.kernels.excitation import advance_pieces, next_breakpoint
from isolab.engine.kernels.params import (
    FIDELITIES,
    LTI,
    NONLINEAR,
    Params,
    Work,
    borrowed,
    line_aligned_zeros,
    whole_lines,
)
from isolab.engine.kernels.peaks import (
    Peaks,
    observe,
    observe_nonlinear,
    observe_nonlinear_on,
    observer_views,
)
from isolab.engine.kernels.structs import kernel_struct
from isolab.engine.results import FAILED, OK, UNSTABLE

EULER, RK4, EXACT = 0, 1, 2
"""Codes of the stepped methods inside the driver."""
MAPPED, GENERAL = 0, 1
"""Codes of a driver's observer: the linear output map (``output_map.observe``: the linear levels, a case
whose floor stands still and that is not recorded), or the general one (``engine.kernels.peaks.observe``;
at the nonlinear level always its own, ``observe_nonlinear``)."""


def pair_driver(method: int, level: int, observer: int = GENERAL) -> Any:
    """The cached driver loop of ``method`` (:data:`EULER`, :data:`RK4`, :data:`EXACT`) at ``level``
    (``engine.kernels.params``) for the cases ``observer`` (:data:`MAPPED`, :data:`GENERAL`) observes: a
    numba kernel ``drive(P, dt, n_steps, O, W, status, full, ev, sub_b, sub_a, deg, osc, outmap)``."""

    # the nonlinear level's RK4 driver fuses each multiply with the add that takes it (LLVM's ``contract``:
    # one rounding instead of two, no reordering, NaN and infinity as they are) in its inlined step; every
    # kernel it calls without inlining states its own ``fastmath``, which numba would otherwise take from
    # the first caller that compiles it, and cache so
    fast = {"contract"} if method == RK4 and level == NONLINEAR else False

    @njit(cache=True, nogil=True, fastmath=fast)
    def drive(P, dt, n_steps, O, W, status, full, ev, sub_b, sub_a, deg, osc, outmap):
        """Integrate every case ``c`` whose ``status[c]`` is OK and that this driver's observer observes
        (:func:`mapped_cases`) over ``n_steps[c]`` steps of ``dt[c]`` s.

        Each step ``[k h, (k + 1) h]`` is split at the breakpoints inside it, so every sub-step sees one
        polynomial piece of every profile; the outputs are observed at the end of each step.
        ``status[c]`` becomes UNSTABLE when the base runs away (``engine.kernels.peaks.observe``) and
        FAILED on a singular mass matrix; the case stops there. ``full``, ``ev``, ``sub_b``, ``sub_a``,
        ``deg``, ``osc`` are the exact method's prepared maps (empty for the others). ``outmap`` is the
        linear output map ``(G, KF, target, rest_target, still, GZ)`` (``output_map``; empty at the
        nonlinear level), through which the linear levels observe every case whose floor stands still
        and that is not recorded.
        """
        C = dt.shape[0]
        nx = 13 if level == NONLINEAR else 12 + P.zA.shape[1]  # the base, then the extra linear states
        nA = 2 * P.sm.shape[1] if method == EXACT and nx > 13 else 0  # exact: the stages' accelerations
        idx = np.zeros(P.sm.shape[1], dtype=np.int64)
        G, KF, tgt, rtgt, still, GZ = outmap
        m = G.shape[2]
        # the scratch the steps read and write at every step, carved from one block that starts a cache
        # line, each part on lines of its own at fixed distances from the others: allocated one by one,
        # the output map's rows spanned two cache lines at every vector load and store wherever the
        # allocator handed out an address that was not a multiple of 64 bytes, and the parts' distances
        # (a load waits on an earlier store to an address with the same low 12 bits) changed with the
        # batch: up to 40 % more time per step, from one batch to the next
        nB = output_map.SCRATCH if m > 0 else 0  # the output map's rows (output_map.observe)
        nz = nx + 6 * (deg + 1) + nA  # the state, then exact's forcing carried between steps
        nS = rk4.SCRATCH_ROWS * nx  # RK4's stage state and slopes
        nL = exact.LEAN_SCRATCH if method == EXACT else 0  # exact.lean_rows
        oz = whole_lines(nB)  # each part's start in the block, elements
        oQ = oz + whole_lines(nz)
        on = oQ + whole_lines(15)
        oS = on + whole_lines(nx)
        oL = oS + whole_lines(nS)
        block = line_aligned_zeros(oL + nL)
        Bmap = block[:nB]
        z = block[oz : oz + nz]
        x = z[:nx]
        Fv = z[nx:]
        Qmap = block[oQ : oQ + 15]
        xn = block[on : on + nx]  # exact: the new state
        S = block[oS : oS + nS].reshape((rk4.SCRATCH_ROWS, nx))
        # exact: the lean step's rows, the state's map and the piece's forced response (exact.lean_rows)
        L = block[oL : oL + nL]
        # exact: a whole step inside one piece with no recorded floor input or extra linear state takes the
        # lean path (exact.free_step, which advances the base's 12 rows), for a case under no sine floor and
        # with no feedforward actuator: chosen per case, so that a case's result does not depend on the
        # other cases of its batch (the lean path equals the general one to round-off, not bit for bit)
        lean = P.ft.shape[0] == 0 and nx == 12
        carried = False
        F0, rest, ptol = P.f0, O.rest, O.point_tol
        # RK4 at the nonlinear level for a case without a recorded floor or feedforward actuators
        # (``rk4.lean_nonlinear``, chosen per case): the lean step, inlined here on views of the case's
        # arrays made once per case (``rk4.nonlinear_views``), so that no step counts a reference
        lean_nl = False
        g, pbase = P.g, P.pbase
        swt = np.zeros_like(W.sw)  # the lean step's stages' state at the time of a slope
        # the arrays the exact method's lean step and the output map read at every step, as views whose
        # references numba does not count (``engine.kernels.params.borrowed``): made once here, so that no
        # step counts one (an atomic add and subtract per array and step, dearer than the step itself)
        b = borrowed
        xv, Lv, evv, Bv, Qv, GZv = b(x), b(L), b(ev), b(Bmap), b(Qmap), b(GZ)
        F0v, tgtv, rtgtv, restv, ptolv = b(F0), b(tgt), b(rtgt), b(rest), b(ptol)
        # the nonlinear level's RK4 inlines its observer on views made here once (as the lean step's)
        OV = observer_views(P, W, O, x)
        for c in range(C):
            if status[c] != OK:
                continue
            linear = level != NONLINEAR and 0 < m <= output_map.CAPACITY and still[c] and O.slot[c] < 0
            if linear != (observer == MAPPED):
                continue  # the other driver's case
            if observer == MAPPED:
                output_map.start(O, c, G, KF, Bmap, Qmap)
            x[:] = 0.0
            if level == NONLINEAR:
                x[3] = 1.0
            Fv[:] = 0.0
            idx[:] = -1
            h = dt[c]
            tol = 1e-6 * h
            passed = 0
            carried = False
            lean_c = lean and P.famp[c, 0] == 0.0 and P.famp[c, 1] == 0.0 and P.famp[c, 2] == 0.0
            if P.ffon:
                for i in range(P.ffg.shape[1]):
                    if P.ffg[c, i] != 0.0:
                        lean_c = False  # the case's feedforward actuators: the general step
            piece_end = -np.inf  # the earliest start of a stage's next piece, s
            if method == RK4 and level == NONLINEAR:  # the lean step's arrays, once per case
                V = rk4.nonlinear_views(P, c, W, x, S, idx, swt)
                lean_nl = rk4.lean_nonlinear(P, c)
            ET = b(full[c if method == EXACT else 0])
            # k = -1 steps nothing and observes the start: one call site of each observer, whose body
            # (inlined: the output map's and, at the nonlinear level's RK4, the nonlinear one's) numba
            # then compiles once per driver instead of twice
            for k in range(-1, n_steps[c]):
                t0 = k * h
                t1 = (k + 1) * h
                ta = t0
                ok = True
                while k >= 0:
                    fresh = piece_end <= ta + tol  # a stage enters a new piece (always at the case's start)
                    if fresh:
                        advance_pieces(P, c, ta, idx, tol)
                        piece_end = next_breakpoint(P, c, idx, np.inf, tol)
                    if method == EXACT:
                        tb = exact.next_split(evv, c, passed, t1, tol)
                        if lean_c and tb == t1 and ta == t0 and not fresh:
                            if not carried:  # the piece's forced response, from the forcing at t0
                                exact.lean_rows(ET, Fv, deg, Lv)
                                carried = True
                            exact.free_step(Lv, xv, deg, t1 - t0)
                            ok = True
                        else:
                            carried = False  # exact.step builds the forcing anew wherever it uses it
                            ok = exact.step(
                                P,
                                c,
                                ta,
                                tb,
                                t0,
                                t1,
                                fresh,
                                passed,
                                z,
                                Fv,
                                xn,
                                idx,
                                W,
                                full,
                                sub_b,
                                sub_a,
                                deg,
                                osc,
                            )
                    else:
                        tb = piece_end if piece_end < t1 - tol else t1
                        if method == RK4 and level == LTI:
                            ok = rk4.step_lti(P, c, ta, tb - ta, x, S, idx, W)
                        elif method == RK4 and level == NONLINEAR and lean_nl:
                            ok = rk4.step_nonlinear(c, ta, tb - ta, V, g, pbase)  # inlined
                        elif method == RK4:
                            ok = rk4.step(P, c, level, ta, tb - ta, x, S, idx, W)
                        else:
                            ok = euler.step(P, c, level, ta, tb - ta, x, idx, W)
                    if not ok or tb == t1:
                        break
                    passed += 1
                    ta = tb
                if not ok:
                    status[c] = FAILED
                    break
                if observer == MAPPED:
                    seen = output_map.observe(c, t1, xv, k + 1, F0v, tgtv, rtgtv, restv, ptolv, Bv, Qv, GZv)
                elif method == RK4 and level == NONLINEAR:
                    seen = observe_nonlinear_on(P, O, c, t1, k + 1, OV)  # inlined
                elif level == NONLINEAR:
                    seen = observe_nonlinear(P, c, t1, x, W, O, k + 1)
                else:
                    seen = observe(P, c, t1, x, W, O, k + 1)
                if not seen:
                    status[c] = UNSTABLE
                    break
            if observer == MAPPED:
                output_map.finish(O, c, Bmap, Qmap)

    return drive


ENTRIES = {
    (name, fidelity): tuple(
        pair_driver(method, FIDELITIES[fidelity], observer)
        for observer in ((GENERAL,) if fidelity == "nonlinear" else (MAPPED, GENERAL))
    )
    for name, method, fidelities in (
        ("euler", EULER, ("lti", "ltv", "nonlinear")),
        ("rk4", RK4, ("lti", "ltv", "nonlinear")),
        ("exact", EXACT, ("lti",)),
    )
    for fidelity in fidelities
}
"""The cached drivers of each stepped method and fidelity level, by ``(method, level)`` names, indexed by
observer code (:data:`MAPPED`, :data:`GENERAL`; the nonlinear level's one driver at 0): what a run calls
from Python (and compiles, on an empty cache, alone), and what a check of the kernel cache on disk reads."""


def mapped_cases(level: int, O: Peaks, still: np.ndarray, m: int) -> np.ndarray:
    """Per case (C,), True where the output map observes the case at ``level`` (:data:`MAPPED`): a linear
    level, a map of ``m`` outputs within ``output_map.CAPACITY``, a floor that stands still under the case
    (``still``, ``output_map.still_floor``) and no recorded history (``O.slot``); False where the general
    observer does (:data:`GENERAL`). The drivers decide each case alike, in their loop."""
    if level == NONLINEAR or not 0 < m <= output_map.CAPACITY:
        return np.zeros(len(O.slot), dtype=bool)
    return np.asarray(still, dtype=bool) & (np.asarray(O.slot) < 0)


_LEVEL_NAMES = {level: name for name, level in FIDELITIES.items()}

_NO_MAPS = (
    np.zeros((1, 0, 12)),
    np.zeros((0, 1)),
    np.zeros((0, 1, 0, 12)),
    np.zeros((0, 1, 0, 12)),
    0,
    False,
)

_NO_OUTPUT_MAP = (
    np.zeros((0, 6, 0)),
    np.zeros((0, 2, 0)),
    np.zeros((0, 0)),
    np.zeros((0, 1, 0)),
    np.zeros(0, dtype=np.bool_),
    np.zeros((0, 2, 0, 0)),
)


def run(
    name: str,
    P: Params,
    level: int,
    dt: np.ndarray,
    n_steps: np.ndarray,
    O: Peaks,
    W: Work,
    status: np.ndarray,
    messages: list[str] | None = None,
    slot_target: np.ndarray | None = None,
    slot_rest_target: np.ndarray | None = None,
) -> None:
    """Integrate every OK case with the stepped method ``name`` (``euler``, ``rk4`` or ``exact``).

    ``dt`` (C,) s and ``n_steps`` (C,) per case; ``O`` the peak accumulators, ``W`` scratch, ``status``
    (C,) int8 updated in place (see :func:`drive`). ``messages`` is accepted for the common interface; the
    status says all a stepped method has to say. ``slot_target`` (C, nz) and ``slot_rest_target`` (C, K, nz)
    are the extra linear states' static values at the end and in each rest interval (None: zero).
    """
    maps = exact.prepare(P, dt, dt * n_steps) if name == "exact" else _NO_MAPS
    full, ev, sub_b, sub_a, deg, osc = maps
    if level != NONLINEAR:
        built = output_map.build(P, O.target, O.rest_target, slot_target, slot_rest_target)
        outmap = (*built[:4], output_map.still_floor(P), built.GZ)
    else:
        outmap = _NO_OUTPUT_MAP
    due = status == OK
    mapped = mapped_cases(level, O, outmap[4], outmap[0].shape[2])
    # each driver integrates its observer's cases and passes over the others: a batch without cases for
    # one never calls it (nor, on an empty cache, compiles it)
    groups = (due,) if level == NONLINEAR else (due & mapped, due & ~mapped)
    args = (kernel_struct(P), dt, n_steps, kernel_struct(O), kernel_struct(W), status, full, ev, sub_b, sub_a)
    for drive, cases in zip(ENTRIES[name, _LEVEL_NAMES[level]], groups, strict=True):
        if cases.any():
            drive(*args, int(deg), bool(osc), outmap)
