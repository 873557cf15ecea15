"""Exact discretisation of the LTI level (matrix exponential with a polynomial hold).

Between two breakpoints of the stage profiles (or samples of a recorded floor motion) the LTI forcing is a
polynomial in time of degree at most three: ``f(t0 + s) = F0 + F1 s + F2 s^2/2 + F3 s^3/6``. Appending the
derivatives ``F0..F3`` (and, for a sine floor motion, a harmonic oscillator per axis) to the state makes the
whole system autonomous, so one matrix exponential of the augmented matrix gives the exact step map:
a zero-order hold for a trapezoid (piecewise-constant acceleration), a first-order or higher hold for an
S-curve. A breakpoint inside a step splits that step. Unconditionally stable; no step-size error.

Inside a piece the forcing derivatives are not recomputed from the stage kinematics at every step: they
are carried to the next step by the exact Taylor shift of the polynomial (``F0 <- F0 + F1 h + ...``), and
rebuilt from the kinematics only where a piece begins (and at every step under a recorded floor motion,
whose samples are breakpoints of their own).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from isolab.engine.integrators.step_maps import maps as structured_maps
from isolab.engine.kernels.excitation import lti_forcing, recorded_floor, stage_state
from isolab.engine.kernels.feedforward import feedforward_generalised
from isolab.engine.kernels.params import Params
from isolab.engine.kernels.rotations import cross

NAME = "exact"
LEVELS = ("lti",)
ORDER = None
"""No step-size error: the step map is exact for the polynomial forcing."""
EXACT = True
GUARDED = False
"""Unconditionally stable: no stability guard."""
PREPARE_BLOCK = 256
"""Cases whose full split-step exponentials are held at once while the step maps are prepared."""


def _degree(P: Params) -> int:
    """Highest derivative of the forcing that can be non-zero within a piece (at least 1 with feedforward
    actuators: their force enters each sub-step as a ramp, see :func:`_feedforward_ramp`)."""
    if P.ffon:
        return max(_polynomial_degree(P), 1)
    return _polynomial_degree(P)


def _polynomial_degree(P: Params) -> int:
    if np.any(P.pj != 0.0):
        return 3
    if P.sm.shape[1]:
        return 2  # the weights' moment follows the travel: quadratic under constant acceleration
    if P.ft.shape[0]:
        return 1
    return 0


def base_rows(P: Params) -> int:
    """Rows of the state the step maps advance: the base's 12 and the extra linear states' ``nz``
    (``Params.zA``)."""
    return 12 + P.zA.shape[1]


def stage_rows(P: Params) -> int:
    """Entries of the stages' accelerations along their axes and their jerks carried in the augmented
    state (``2 m``) when extra linear states take them as forcing, else 0."""
    return 2 * P.sm.shape[1] if P.zA.shape[1] else 0


def augmented(P: Params) -> tuple[np.ndarray, int, int]:
    """The augmented continuous-time matrix (C, N, N), the forcing degree, and the oscillator flag.

    Layout: ``[x (12), z (nz), F0..F_deg (6 each), stage accelerations and jerks (m each, with z only),
    sine-floor oscillator (6, optional)]``. The extra linear states (``Params.zA`` ...) enter as
    ``z' = zA z + zX x + zQ acc + zS s''`` and add ``zM z + sM s''`` to the base's accelerations.
    """
    C = P.mass.shape[0]
    deg = _degree(P)
    osc = int(np.any(P.famp != 0.0))
    nF = 6 * (deg + 1)
    nb = base_rows(P)
    nA = stage_rows(P)
    N = nb + nF + nA + 6 * osc
    Z = np.zeros((C, N, N))
    Z[:, :6, 6:12] = np.eye(6)
    Z[:, 6:12, :6] = P.a21
    Z[:, 6:12, 6:12] = P.a22
    Z[:, 6:12, nb : nb + 6] = P.minv
    for q in range(deg):
        Z[:, nb + 6 * q : nb + 6 + 6 * q, nb + 6 + 6 * q : nb + 12 + 6 * q] = np.eye(6)
    if osc:
        o = nb + nF + nA
        # generalised force of the floor: per axis a, K_a amp_a sin + C'_a amp_a w_a cos
        Bf = np.zeros((C, 6, 6))
        rel = 1.0 - P.sky
        for a in range(3):
            ks = P.k[:, :, a] * P.famp[:, None, a]  # (C, n)
            cs = rel * P.cd[:, :, a] * P.famp[:, None, a] * P.fomega[:, None, a]
            for col, per in ((2 * a, ks), (2 * a + 1, cs)):
                force = np.zeros(P.d.shape)
                force[..., a] = per
                Bf[:, :3, col] = force.sum(axis=1)
                Bf[:, 3:, col] = np.cross(P.d, force).sum(axis=1)
        Z[:, 6:12, o : o + 6] = P.minv @ Bf
        for a in range(3):
            w = P.fomega[:, a]
            Z[:, o + 2 * a, o + 2 * a + 1] = w
            Z[:, o + 2 * a + 1, o + 2 * a] = -w
    if nb > 12:
        m = P.sm.shape[1]
        a = nb + nF  # the stages' accelerations, then their jerks
        Z[:, a : a + m, a + m : a + 2 * m] = np.eye(m)
        Z[:, 6:12, 12:nb] = P.zM
        if P.sM.shape[2]:
            Z[:, 6:12, a : a + m] += P.sM
        Z[:, 12:nb, 12:nb] += P.zA
        Z[:, 12:nb, :12] += P.zX
        Z[:, 12:nb, a : a + m] += P.zS
        Z[:, 12:nb, :] += P.zQ @ Z[:, 6:12, :]  # the base's accelerations are linear in the same
    return Z, deg, osc


def _expm(Z: np.ndarray, h: np.ndarray) -> np.ndarray:
    """``expm(Z h)`` (..., N, N); ``h`` broadcasts over the leading axes."""
    import scipy.linalg  # on first use: most commands never load scipy

    A = Z * np.asarray(h)[..., None, None]
    N = A.shape[-1]
    return scipy.linalg.expm(A.reshape(-1, N, N)).reshape(A.shape)  # one flat batch: much faster than nd


def _top(E: np.ndarray, nb: int = 12) -> np.ndarray:
    """The rows of a step map that advance the state (the base's 12 and ``nb - 12`` extra linear states),
    transposed for the kernel: (..., N, nb)."""
    return np.ascontiguousarray(np.swapaxes(E[..., :nb, :], -1, -2))


def step_maps(Z: np.ndarray, h: np.ndarray, nb: int = 12) -> np.ndarray:
    """The rows of ``expm(Z h)`` that advance the state (``nb`` rows), transposed: (..., N, nb). ``h``
    broadcasts over cases."""
    return _top(_expm(Z, h), nb)


def _rest_of_step(E_full: np.ndarray, E_before: np.ndarray, nb: int = 12) -> np.ndarray:
    """``expm(Z (h - b)) = expm(Z h) expm(Z b)^-1`` from the full step's map (C, N, N) and the maps of
    its first parts ``b`` (C, E, N, N): one block-triangular inverse instead of a second exponential.

    The augmented matrix is block upper triangular, ``[[A, G], [0, J]]``, and so are its exponentials:
    ``[[P, Q], [0, S]]^-1 = [[P^-1, -P^-1 Q S^-1], [0, S^-1]]`` with ``P`` (nb, nb) the state's own map
    (the base's 12 rows and the extra linear states')."""
    P_inv = np.linalg.inv(E_before[..., :nb, :nb])
    S_inv = np.linalg.inv(E_before[..., nb:, nb:])
    inv = np.zeros_like(E_before)
    inv[..., :nb, :nb] = P_inv
    inv[..., :nb, nb:] = -P_inv @ E_before[..., :nb, nb:] @ S_inv
    inv[..., nb:, nb:] = S_inv
    return E_full[:, None, :nb, :] @ inv


def breakpoints(P: Params, dt: np.ndarray, duration: np.ndarray) -> np.ndarray:
    """Per case, the sorted breakpoints inside (0, duration) that do not fall on a step (C, E), s.

    Padded with +inf. These are the times where the forcing polynomial changes. Every case at once: the
    candidates of a case are its stages' piece starts and the recorded floor's sample times; the others,
    and a repeat of a time already kept, become +inf before a sort moves them to the end.
    """
    C = P.mass.shape[0]
    ft = np.asarray(P.ft, dtype=float)
    t = np.concatenate([np.asarray(P.pt, dtype=float).reshape(C, -1), np.broadcast_to(ft, (C, ft.size))], 1)
    with np.errstate(invalid="ignore"):
        r = t / np.asarray(dt, dtype=float)[:, None]
        keep = (t > 0.0) & (t < np.asarray(duration, dtype=float)[:, None]) & (np.abs(r - np.round(r)) > 1e-6)
    t = np.sort(np.where(keep, t, np.inf), axis=1)
    repeat = np.zeros(t.shape, dtype=bool)
    repeat[:, 1:] = t[:, 1:] == t[:, :-1]
    t = np.sort(np.where(repeat, np.inf, t), axis=1)
    E = max(int(np.isfinite(t).sum(axis=1).max(initial=0)), 1)
    out = np.full((C, E), np.inf)
    out[:, : min(E, t.shape[1])] = t[:, :E]
    return out


def prepare(
    P: Params, dt: np.ndarray, duration: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int, int]:
    """Step maps for the full step and for the split steps around each breakpoint.

    Without a sine floor motion the maps come from the structured exponential of
    ``engine.integrators.step_maps``; with one (the oscillator's rotation blocks break that structure)
    from scipy's dense ``expm`` of the augmented matrix, as below.

    Per breakpoint ``t`` in step ``[k h, (k + 1) h]``: the map from the previous breakpoint of the step (or
    the step's start) to ``t``, and the map from ``t`` to the step's end, ``expm(Z h) expm(Z (t - k h))^-1``
    (see :func:`_rest_of_step`). Where ``t`` is the step's only breakpoint both use one exponential.
    """
    deg = _degree(P)
    osc = int(np.any(P.famp != 0.0))
    ev = breakpoints(P, dt, duration)
    C, E = ev.shape
    h = np.asarray(dt, dtype=float)
    within = np.isfinite(ev)  # a prefix of each row: the breakpoints are sorted, padded with +inf
    with np.errstate(invalid="ignore"):
        k = np.floor(ev / h[:, None] + 1e-9)  # the step each breakpoint falls in
        prev = np.concatenate([np.full((C, 1), -np.inf), ev[:, :-1]], axis=1)
        start = np.maximum(k * h[:, None], prev)  # the step's start or the previous breakpoint in it
        before = np.where(within, ev - start, 0.0)
        offset = np.where(within, ev - k * h[:, None], 0.0)  # from the step's start
    n_events = within.sum(axis=1).astype(np.int64)
    # the structured exponential (engine.integrators.step_maps) for every case without a sine floor
    N0 = 12 + 6 * (deg + 1)
    s_full = np.zeros((C, N0, 12))
    s_b = np.zeros((C, E, N0, 12))
    s_a = np.zeros((C, E, N0, 12))
    a21, a22, minv = (np.ascontiguousarray(a, dtype=float) for a in (P.a21, P.a22, P.minv))
    nb = base_rows(P)
    if nb == 12:
        structured_maps(a21, a22, minv, deg, h, before, offset, n_events, s_full, s_b, s_a)
    if not osc and nb == 12:
        return s_full, ev, s_b, s_a, deg, osc
    # a case with a sine floor or extra linear states: scipy's dense expm of the augmented matrix
    Z, deg, osc = augmented(P)
    E_full = _expm(Z, dt)
    full = _top(E_full, nb)
    N = Z.shape[-1]
    sub_b = np.empty((C, E, N, nb))
    sub_a = np.empty((C, E, N, nb))
    for lo in range(0, C, PREPARE_BLOCK):  # the full (N, N) maps only for a block of cases at a time
        blk = slice(lo, min(lo + PREPARE_BLOCK, C))
        E_offset = _expm(Z[blk, None], offset[blk])
        sub_a[blk] = _top(_rest_of_step(E_full[blk], E_offset, nb), nb)
        cs, es = np.nonzero(before[blk] != offset[blk])  # a second breakpoint in the same step
        if cs.size:
            E_offset[cs, es] = _expm(Z[blk][cs], before[blk][cs, es])
        sub_b[blk] = _top(E_offset, nb)
    if nb > 12:
        return full, ev, sub_b, sub_a, deg, osc
    # the others keep the structured maps (their oscillator columns are zero), so that a case's maps do
    # not depend on the batch it runs in
    still = ~np.any(np.asarray(P.famp) != 0.0, axis=1)
    for arr, structured in ((full, s_full), (sub_b, s_b), (sub_a, s_a)):
        arr[still] = 0.0
        arr[still, ..., :N0, :] = structured[still]
    return full, ev, sub_b, sub_a, deg, osc


@njit(cache=True)
def _forcing_poly(P, c, t, idx, W, deg, Fv):
    """Forcing ``F0..F_deg`` (6 each) at the start ``t`` (s) of a piece of polynomial forcing."""
    stage_state(P, c, t, idx, W.rho, W.vr, W.ar, W.jr)
    for i in range(3):
        W.xf[i] = 0.0
        W.vf[i] = 0.0
    recorded_floor(P, c, t, W.xf, W.vf)
    lti_forcing(P, c, W.rho, W.ar, W.xf, W.vf, W.f)
    for i in range(6):
        Fv[i] = W.f[i]
    if deg == 0:
        return
    for i in range(6, Fv.shape[0]):
        Fv[i] = 0.0
    g = P.g
    for i in range(P.sm.shape[1]):
        m = P.sm[c, i]
        r0, r1, r2 = W.rho[i, 0], W.rho[i, 1], W.rho[i, 2]
        v0, v1, v2 = W.vr[i, 0], W.vr[i, 1], W.vr[i, 2]
        a0, a1, a2 = W.ar[i, 0], W.ar[i, 1], W.ar[i, 2]
        j0, j1, j2 = W.jr[i, 0], W.jr[i, 1], W.jr[i, 2]
        # f_t = -m a ; f_r = -m rho x a + m (rho - rho_h) x (0, 0, -g)
        Fv[6] -= m * j0
        Fv[7] -= m * j1
        Fv[8] -= m * j2
        p0, p1, p2 = cross(v0, v1, v2, a0, a1, a2)
        q0, q1, q2 = cross(r0, r1, r2, j0, j1, j2)
        Fv[9] += -m * (p0 + q0) - m * v1 * g
        Fv[10] += -m * (p1 + q1) + m * v0 * g
        Fv[11] += -m * (p2 + q2)
        if deg >= 2:
            p0, p1, p2 = cross(v0, v1, v2, j0, j1, j2)
            Fv[15] += -2.0 * m * p0 - m * a1 * g
            Fv[16] += -2.0 * m * p1 + m * a0 * g
            Fv[17] += -2.0 * m * p2
        if deg >= 3:
            p0, p1, p2 = cross(a0, a1, a2, j0, j1, j2)
            Fv[21] += -2.0 * m * p0 - m * j1 * g
            Fv[22] += -2.0 * m * p1 + m * j0 * g
            Fv[23] += -2.0 * m * p2
    nA = Fv.shape[0] - 6 * (deg + 1)  # the stages' accelerations and jerks along their axes (with z)
    if nA > 0:
        m = nA // 2
        for q in range(m):
            k = idx[q]
            if k >= 0:
                Fv[6 * (deg + 1) + q] = P.pa[c, q, k] + P.pj[c, q, k] * (t - P.pt[c, q, k])
                Fv[6 * (deg + 1) + m + q] = P.pj[c, q, k]
    if P.ft.shape[0] > 0:
        for j in range(P.d.shape[1]):
            p0 = P.k[c, j, 0] * W.vf[0]
            p1 = P.k[c, j, 1] * W.vf[1]
            p2 = P.k[c, j, 2] * W.vf[2]
            Fv[6] += p0
            Fv[7] += p1
            Fv[8] += p2
            m0, m1, m2 = cross(P.d[c, j, 0], P.d[c, j, 1], P.d[c, j, 2], p0, p1, p2)
            Fv[9] += m0
            Fv[10] += m1
            Fv[11] += m2


@njit(cache=True, inline="always")
def taylor_shift(V, o, n, deg, h):
    """Carry a polynomial of degree ``deg`` (<= 3) in time forward by ``h`` s, exactly: ``V`` holds from
    ``o`` on its ``n`` values, then their first, second and third time derivatives (``n`` each, up to
    ``deg``). One loop per degree, so that no loop branches on it (a loop that does is vectorised with
    masked loads and stores, which wait for the stores before them)."""
    if deg == 1:
        for i in range(n):
            V[o + i] += h * V[o + n + i]
    elif deg == 2:
        for i in range(n):
            v1 = V[o + n + i]
            v2 = V[o + 2 * n + i]
            V[o + i] += h * (v1 + 0.5 * h * v2)
            V[o + n + i] = v1 + h * v2
    elif deg >= 3:
        for i in range(n):
            v1 = V[o + n + i]
            v2 = V[o + 2 * n + i]
            v3 = V[o + 3 * n + i]
            V[o + i] += h * (v1 + h * (0.5 * v2 + h * v3 / 6.0))
            V[o + n + i] = v1 + h * (v2 + 0.5 * h * v3)
            V[o + 2 * n + i] = v2 + h * v3


@njit(cache=True, inline="always")
def _shift(Fv, deg, h):
    """Carry the forcing derivatives ``F0..F_deg`` (6 each) of a polynomial piece forward by ``h`` s."""
    taylor_shift(Fv, 0, 6, deg, h)
    off = 6 * (deg + 1)
    m = (Fv.shape[0] - off) // 2  # the stages' accelerations ramp with their jerks (with extra states)
    for q in range(m):
        Fv[off + q] += h * Fv[off + m + q]


@njit(cache=True, inline="always")
def _product(ET, z, out):
    """``out[:12] = E z`` for a step map given transposed, ``ET`` (N, 12), and ``z`` (N,): column by column
    into twelve accumulators held in registers (each column is 12 contiguous numbers, three 4-wide
    multiply-adds), written only after the last column, so ``out`` may be ``z`` itself."""
    nz = z.shape[0]
    a0 = a1 = a2 = a3 = a4 = a5 = a6 = a7 = a8 = a9 = a10 = a11 = 0.0
    for j in range(nz):
        zj = z[j]
        a0 += ET[j, 0] * zj
        a1 += ET[j, 1] * zj
        a2 += ET[j, 2] * zj
        a3 += ET[j, 3] * zj
        a4 += ET[j, 4] * zj
        a5 += ET[j, 5] * zj
        a6 += ET[j, 6] * zj
        a7 += ET[j, 7] * zj
        a8 += ET[j, 8] * zj
        a9 += ET[j, 9] * zj
        a10 += ET[j, 10] * zj
        a11 += ET[j, 11] * zj
    out[0], out[1], out[2], out[3], out[4], out[5] = a0, a1, a2, a3, a4, a5
    out[6], out[7], out[8], out[9], out[10], out[11] = a6, a7, a8, a9, a10, a11


@njit(cache=True, inline="always")
def _product_rows(ET, z, out):
    """``out = E z`` for a step map with more rows than the base's 12 (extra linear states), ``ET``
    (N, nb); ``out`` (nb,) is not ``z``."""
    nb = out.shape[0]
    for i in range(nb):
        out[i] = 0.0
    for j in range(z.shape[0]):
        zj = z[j]
        for i in range(nb):
            out[i] += ET[j, i] * zj


@njit(cache=True)
def _apply(ET, z, osc_on, t, P, c, xn):
    """``xn = E [x, F, oscillator(t)]`` for one (sub)step map given transposed, ``ET`` (N, nb); ``z``
    holds ``[x, F]`` (:func:`_product`), the oscillator's columns follow."""
    if xn.shape[0] == 12:
        _product(ET, z, xn)
    else:
        _product_rows(ET, z, xn)
    nz = z.shape[0]
    if osc_on:
        for a in range(3):
            arg = P.fomega[c, a] * t + P.fphase[c, a]
            sa, ca = np.sin(arg), np.cos(arg)
            for i in range(xn.shape[0]):
                xn[i] += ET[nz + 2 * a, i] * sa + ET[nz + 2 * a + 1, i] * ca


LEAN_WIDTH = 16
"""Elements per row of the lean step's scratch (:func:`lean_rows`): the state's 12 padded to two vectors of
8, so that its loops run as whole vector loops (no remainder, no masked loads after a wider store)."""
_PHI = 0  # 12 rows: row j the full step's map's column of x_j (the state's 12 rows of it)
_NEW = 12 * LEAN_WIDTH  # the new state
_RESP = 13 * LEAN_WIDTH  # deg + 1 rows: the forced response R_0..R_deg
LEAN_SCRATCH = 17 * LEAN_WIDTH
"""Length of the lean step's scratch (:func:`lean_rows`, :func:`free_step`)."""


@njit(cache=True, inline="always")
def lean_rows(ET, Fv, deg, L):
    """Load the lean step's rows into the flat scratch ``L`` (:data:`LEAN_SCRATCH`,): the state's columns
    of a whole step's map ``ET`` (N, 12) and its forced part with its time derivatives, from the forcing
    ``Fv = F0..F_deg`` (6 each) at the step's start. Each row is :data:`LEAN_WIDTH` long (zeros past 12).

    A whole step maps ``x`` to ``Phi x + sum_r Gamma_r F_r(t)``, with ``Gamma_r`` the columns of ``F_r``.
    Inside one polynomial piece that forced part is itself a polynomial in the step's start ``t``, its
    ``q``-th derivative ``R_q = sum_r Gamma_r F_(q + r)`` (``F_q`` beyond ``deg`` being zero): once per
    piece, instead of ``6 (deg + 1)`` columns of the product at every step (:func:`free_step`)."""
    for j in range(12):
        for i in range(12):
            L[_PHI + LEAN_WIDTH * j + i] = ET[j, i]
    for q in range(deg + 1):
        a0 = a1 = a2 = a3 = a4 = a5 = a6 = a7 = a8 = a9 = a10 = a11 = 0.0
        for r in range(deg + 1 - q):
            for k in range(6):
                j = 12 + 6 * r + k
                f = Fv[6 * (q + r) + k]
                a0 += ET[j, 0] * f
                a1 += ET[j, 1] * f
                a2 += ET[j, 2] * f
                a3 += ET[j, 3] * f
                a4 += ET[j, 4] * f
                a5 += ET[j, 5] * f
                a6 += ET[j, 6] * f
                a7 += ET[j, 7] * f
                a8 += ET[j, 8] * f
                a9 += ET[j, 9] * f
                a10 += ET[j, 10] * f
                a11 += ET[j, 11] * f
        o = _RESP + LEAN_WIDTH * q
        L[o], L[o + 1], L[o + 2], L[o + 3], L[o + 4], L[o + 5] = a0, a1, a2, a3, a4, a5
        L[o + 6], L[o + 7], L[o + 8], L[o + 9], L[o + 10], L[o + 11] = a6, a7, a8, a9, a10, a11


@njit(cache=True, inline="always")
def free_step(L, x, deg, h):
    """Advance ``x`` (12,) over one whole step of ``h`` s inside one polynomial piece, the forcing without
    feedforward, oscillator or recorded floor: ``x <- Phi x + R_0`` through the rows of ``L`` loaded by
    :func:`lean_rows`, whose forced response then moves on by its exact Taylor shift. 144 multiply-adds
    instead of ``12 N``, equal to the product with the forcing's columns to round-off. The rows lie a
    fixed distance apart in one array, so both loops run as 8-wide vector loops over the state's rows,
    each row's sum taken in the order a scalar loop over the columns takes it."""
    x0, x1, x2, x3, x4, x5 = x[0], x[1], x[2], x[3], x[4], x[5]
    x6, x7, x8, x9, x10, x11 = x[6], x[7], x[8], x[9], x[10], x[11]
    W = LEAN_WIDTH
    for i in range(W):
        L[_NEW + i] = (
            L[_RESP + i]
            + L[i] * x0
            + L[W + i] * x1
            + L[2 * W + i] * x2
            + L[3 * W + i] * x3
            + L[4 * W + i] * x4
            + L[5 * W + i] * x5
            + L[6 * W + i] * x6
            + L[7 * W + i] * x7
            + L[8 * W + i] * x8
            + L[9 * W + i] * x9
            + L[10 * W + i] * x10
            + L[11 * W + i] * x11
        )
    # copied in the vectors' own halves (8, then 4): a load that spans two of the stores above would wait
    # for both to complete
    n = _NEW
    x[0], x[1], x[2], x[3] = L[n], L[n + 1], L[n + 2], L[n + 3]
    x[4], x[5], x[6], x[7] = L[n + 4], L[n + 5], L[n + 6], L[n + 7]
    x[8], x[9], x[10], x[11] = L[n + 8], L[n + 9], L[n + 10], L[n + 11]
    taylor_shift(L, _RESP, W, deg, h)


@njit(cache=True, inline="always")
def next_split(ev, c, passed, t_end, tol):
    """End of the current sub-step: the next breakpoint of case ``c`` (the ``passed``-th of ``ev``, which
    holds the profile breakpoints and the recorded floor's samples off the step grid), or ``t_end`` (s)."""
    if passed < ev.shape[1] and ev[c, passed] < t_end - tol:
        return ev[c, passed]
    return t_end


@njit(cache=True)
def _feedforward_ramp(P, c, ta, tb, idx, W, Fv, sign):
    """Add (``sign`` 1) or take back (-1) the feedforward actuators' generalised force as the ramp through
    its values at ``ta`` and ``tb`` (s) to the forcing's ``F0``, ``F1``: a first-order hold over the
    sub-step. The actuator force (a low-passed, clipped wrench) is not polynomial in time; this hold is
    the exact integrator's one approximation, O(h^2) in the force. ``W.ffs`` (24,) keeps the forcing as it
    was, restored bit for bit on the take-back."""
    if sign < 0:
        for i in range(12):
            Fv[i] = W.ffs[12 + i]
        return
    feedforward_generalised(P, c, ta, idx, W, W.ffs, 0)
    feedforward_generalised(P, c, tb, idx, W, W.ffs, 6)
    for i in range(6):
        W.ffs[6 + i] = (W.ffs[6 + i] - W.ffs[i]) / (tb - ta)
    for i in range(12):
        W.ffs[12 + i] = Fv[i]
        Fv[i] += W.ffs[i]


@njit(cache=True, inline="always")
def step(P, c, ta, tb, t0, t1, fresh, passed, z, Fv, xn, idx, W, full, sub_b, sub_a, deg, osc_on):
    """Advance ``x`` (12,) exactly from ``ta`` to ``tb`` (s) inside the step ``[t0, t1]``.

    ``passed`` breakpoints of the case are behind ``ta``; ``fresh`` says a stage entered a new piece at
    ``ta``. ``z`` is ``[x (12), F0..F_deg (6 each)]``: the state and the forcing derivatives carried
    between steps, ``Fv`` the view of its forcing part; ``xn`` (12,) is scratch for the new state. A
    sub-step that ends on a breakpoint takes that breakpoint's map from ``sub_b``; the rest of a split
    step its map from ``sub_a``; an unsplit step the full map. Always True.
    """
    if tb < t1:
        _forcing_poly(P, c, ta, idx, W, deg, Fv)
        if P.ffon:
            _feedforward_ramp(P, c, ta, tb, idx, W, Fv, 1.0)
        _apply(sub_b[c, passed], z, osc_on, ta, P, c, xn)
        if P.ffon:
            _feedforward_ramp(P, c, ta, tb, idx, W, Fv, -1.0)
        z[: xn.shape[0]] = xn
        return True
    split = ta > t0
    if split or fresh or P.ft.shape[0] > 0:
        _forcing_poly(P, c, ta, idx, W, deg, Fv)
    if P.ffon:
        _feedforward_ramp(P, c, ta, t1, idx, W, Fv, 1.0)
    if split:
        _apply(sub_a[c, passed - 1], z, osc_on, ta, P, c, xn)
    else:
        _apply(full[c], z, osc_on, ta, P, c, xn)
    if P.ffon:
        _feedforward_ramp(P, c, ta, t1, idx, W, Fv, -1.0)
    z[: xn.shape[0]] = xn
    _shift(Fv, deg, t1 - ta)
    return True
