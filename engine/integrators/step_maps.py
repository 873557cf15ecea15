"""The exact integrator's step maps: the matrix exponential of its augmented matrix, written for its
structure.

The augmented matrix of the LTI level with a polynomial forcing of degree ``deg`` (``exact.augmented``,
without the sine-floor oscillator) is block upper triangular,

    Z = [[A, B], [0, J]],   A = [[0, I], [A21, A22]] (12, 12),   B = [[0, 0 ...], [M^-1, 0 ...]],

with ``J`` the nilpotent shift that carries ``F_q`` into the derivative of ``F_(q-1)``. Its exponential is
``[[Phi, Gamma], [0, S]]`` where ``S = expm(J h)`` is the exact Taylor shift (blocks ``h^(r-q)/(r-q)! I``).
Only the 12 rows ``[Phi, Gamma]`` advance the base's state, and only they are computed:

- scaling and squaring: ``h`` is halved ``s`` times until the balanced norm ``theta`` of ``A h / 2^s``
  is at most 1/2 (positions scaled by ``sqrt(||A21||)`` so that stiffness and velocity columns weigh
  alike; the norm bounds the truncation error in that scaling, block by block);
- a Taylor series of the top rows, ``T_k = T_(k-1) Z h / k``, each product using the blocks of ``Z``
  (three 12 x 6 x 6 products and a shift instead of a dense N x N product), to the degree ``K`` where
  ``theta^(K+1) / (K+1)!`` falls below 2^-56, plus ``deg + 2`` terms (the block of ``F_q`` starts at the
  term ``q + 2`` in the positions' rows, so each block gets its own ``K`` terms);
- ``s`` squarings in block form, ``Phi <- Phi Phi``, ``Gamma <- Phi Gamma + Gamma S``.

Compared with scipy's dense ``expm`` on the N x N matrix (N = 36 for an S-curve) this does about a tenth of
the arithmetic and none of the per-matrix Python; ``tests/engine/test_step_maps.py`` checks it against
scipy to round-off over six decades of ``|lambda| h``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

TAYLOR_TOL = 2.0**-56
"""Bound on the truncated Taylor tail, relative, in the balanced norm."""


@njit(cache=True)
def _balanced_norm(a21, a22, c):
    """1-norm of ``A`` with the positions scaled by ``sqrt(||A21||_1)`` (the scale returned too)."""
    col21 = 0.0
    for j in range(6):
        s = 0.0
        for i in range(6):
            s += abs(a21[c, i, j])
        col21 = max(col21, s)
    w = math.sqrt(max(col21, 1e-300))
    col22 = 0.0
    for j in range(6):
        s = 0.0
        for i in range(6):
            s += abs(a22[c, i, j])
        col22 = max(col22, s)
    return max(col21 / w, w + col22)


@njit(cache=True)
def top_rows(a21, a22, minv, c, deg, h, out, T, U):
    """Rows 0..11 of ``expm(Z h)`` for case ``c`` into ``out`` (N, 12), transposed (``out[j, i] = E[i,
    j]``), ``N = 12 + 6 (deg + 1)``; ``h`` in s (``h = 0`` gives the identity's rows). ``T``, ``U``
    (12, N) are scratch."""
    N = 12 + 6 * (deg + 1)
    theta = abs(h) * _balanced_norm(a21, a22, c)
    s = 0
    if theta > 0.5:
        s = int(math.ceil(math.log2(theta / 0.5)))
        theta = theta / 2.0**s
    hs = h / 2.0**s
    # Taylor degree for the scaled step
    K = 1
    term = theta
    while K < 30 and term * theta / (K + 1) > TAYLOR_TOL:
        K += 1
        term = term * theta / K
    # T_0 = [I 0]; accumulate the series in U
    for i in range(12):
        for j in range(N):
            T[i, j] = 0.0
            U[i, j] = 0.0
        T[i, i] = 1.0
        U[i, i] = 1.0
    nF = deg + 1
    # the block of F_q reaches the positions at the term q + 2: its own series starts there
    for k in range(1, K + deg + 3):
        f = hs / k
        # (T Z) by blocks, into the columns from the last to the first so T can be overwritten in place:
        # F_q <- F_(q-1) (q >= 1), F_0 <- T_v M^-1, v <- T_q + T_v A22, q <- T_v A21
        for i in range(12):
            for q in range(nF - 1, 0, -1):
                for j in range(6):
                    T[i, 12 + 6 * q + j] = f * T[i, 6 + 6 * q + j]
            tv0, tv1, tv2, tv3, tv4, tv5 = T[i, 6], T[i, 7], T[i, 8], T[i, 9], T[i, 10], T[i, 11]
            for j in range(6):
                T[i, 12 + j] = f * (
                    tv0 * minv[c, 0, j]
                    + tv1 * minv[c, 1, j]
                    + tv2 * minv[c, 2, j]
                    + tv3 * minv[c, 3, j]
                    + tv4 * minv[c, 4, j]
                    + tv5 * minv[c, 5, j]
                )
            for j in range(6):
                T[i, 6 + j] = f * (
                    T[i, j]
                    + tv0 * a22[c, 0, j]
                    + tv1 * a22[c, 1, j]
                    + tv2 * a22[c, 2, j]
                    + tv3 * a22[c, 3, j]
                    + tv4 * a22[c, 4, j]
                    + tv5 * a22[c, 5, j]
                )
            for j in range(6):
                T[i, j] = f * (
                    tv0 * a21[c, 0, j]
                    + tv1 * a21[c, 1, j]
                    + tv2 * a21[c, 2, j]
                    + tv3 * a21[c, 3, j]
                    + tv4 * a21[c, 4, j]
                    + tv5 * a21[c, 5, j]
                )
            for j in range(N):
                U[i, j] += T[i, j]
    # squarings: [[P, Q], [0, S]]^2 = [[P P, P Q + Q S], [0, S S]], S = expm(J hs) the Taylor shift
    for _ in range(s):
        for i in range(12):
            for j in range(N):
                acc = 0.0
                for m in range(12):
                    acc += U[i, m] * U[m, j]
                T[i, j] = acc
            for r in range(nF):
                for q in range(r + 1):
                    w = hs ** (r - q) / math.gamma(r - q + 1.0)
                    for j in range(6):
                        T[i, 12 + 6 * r + j] += w * U[i, 12 + 6 * q + j]
        for i in range(12):
            for j in range(N):
                U[i, j] = T[i, j]
        hs *= 2.0
    for i in range(12):
        for j in range(N):
            out[j, i] = U[i, j]


@njit(cache=True)
def maps(a21, a22, minv, deg, dt, before, offset, n_events, full, sub_b, sub_a):
    """Every case's step maps, transposed top rows as ``exact.step`` takes them: ``full`` (C, N, 12) for
    a whole step ``dt[c]`` (s); per breakpoint ``e < n_events[c]`` of the case, ``sub_b`` (C, E, N, 12) over
    ``before[c, e]`` (from the step's start or the previous breakpoint in the same step to it) and
    ``sub_a`` over ``dt[c] - offset[c, e]`` (from it to the step's end). Unused slots are left as they
    are."""
    C = dt.shape[0]
    N = 12 + 6 * (deg + 1)
    T = np.zeros((12, N))
    U = np.zeros((12, N))
    for c in range(C):
        top_rows(a21, a22, minv, c, deg, dt[c], full[c], T, U)
        for e in range(n_events[c]):
            top_rows(a21, a22, minv, c, deg, before[c, e], sub_b[c, e], T, U)
            top_rows(a21, a22, minv, c, deg, dt[c] - offset[c, e], sub_a[c, e], T, U)
