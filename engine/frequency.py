"""Steady-state response of the base to floor vibration, in the frequency domain (the ``lti`` level).

The linear model with the stages at home, ``M q'' + C q' + K q = f_floor``, driven by a uniform floor
displacement ``x_f`` (the same under every mount). An isolator pushes on the base with ``k_j x_f + c'_j
x_f'``, where ``c'_j`` is its damping on the *relative* velocity: zero for a sky-hook (active) mount,
whose damper acts on the base's absolute velocity only (it stays in ``C``). Per floor axis ``a`` and
angular frequency ``w``::

    (K - w^2 M + i w C) q_a = sum_j T_j^T (k_j + i w c'_j) e_a,     T_j = [I, -[d_j]x]

and a point ``r`` (relative to the c.g.) moves with ``u + theta x r = [I, -[r]x] q``. Its velocity per
unit floor displacement is ``H = i w [I, -[r]x] q_a``; per unit floor *velocity* it is ``G = H / (i w)``.

One-third-octave bands (base 10): band ``n`` has the exact centre ``10^(n/10)`` Hz and edges a twentieth
of a decade either side; the bands of 1 Hz (n = 0) to 80 Hz (nominal; n = 19) are :data:`BAND_CENTRES`.
A floor given as RMS velocity per band is taken as a velocity PSD flat within each band; the three floor
axes are uncorrelated. A point's band RMS velocity along axis ``o`` is then::

    v_o,b^2 = sum_a V_a,b^2 * (mean over band b, in linear frequency, of |G_oa(f)|^2)

the mean taken by composite Gauss-Legendre quadrature (see :func:`band_quadrature`). Everything here is
numpy, vectorised over the case dimension; SI units throughout.
"""

from __future__ import annotations

import numpy as np

from isolab.engine import modal, model
from isolab.engine.scene import SceneBatch

N_BANDS = 20
"""One-third-octave bands from 1 Hz to 80 Hz (nominal)."""
BAND_NUMBERS = np.arange(N_BANDS)
"""Band numbers ``n``: exact centre ``10^(n/10)`` Hz."""
BAND_CENTRES = 10.0 ** (BAND_NUMBERS / 10.0)
"""Exact (base-10) band centres, Hz: 1, 1.259, 1.585, ... 79.43."""
NOMINAL_CENTRES = (1, 1.25, 1.6, 2, 2.5, 3.15, 4, 5, 6.3, 8, 10, 12.5, 16, 20, 25, 31.5, 40, 50, 63, 80)
"""The bands' nominal centres, Hz (IEC 61260 / ISO 266 preferred numbers)."""
BAND_HALF_WIDTH = 10.0**0.05
"""Ratio of a band's upper edge to its centre (and of its centre to its lower edge)."""
BAND_LOWER = BAND_CENTRES / BAND_HALF_WIDTH
"""Lower band edges, Hz."""
BAND_UPPER = BAND_CENTRES * BAND_HALF_WIDTH
"""Upper band edges, Hz."""

GAUSS_POINTS = 4
"""Gauss-Legendre points per sub-interval of a band."""
MIN_SUBDIVISIONS, MAX_SUBDIVISIONS = 4, 64
"""Sub-intervals per band: at least 4, more for lightly damped modes (:func:`subdivisions`), at most 64."""
_SOLVES_PER_CHUNK = 200_000
"""Complex 6x6 systems solved at once (bounds the memory of a large batch)."""


def band_quadrature(n_sub: int, n_gauss: int = GAUSS_POINTS) -> tuple[np.ndarray, np.ndarray]:
    """Frequencies (20, Q) Hz and weights (20, Q) that average a function over each band in linear
    frequency: ``mean_b(f) ~= sum_q w[b, q] g(f[b, q])`` (the weights of a band sum to 1).

    Composite Gauss-Legendre: the band is cut into ``n_sub`` sub-intervals of equal width in log
    frequency, each with ``n_gauss`` points; ``Q = n_sub * n_gauss``.
    """
    x, w = np.polynomial.legendre.leggauss(int(n_gauss))
    cuts = np.linspace(np.log10(BAND_LOWER), np.log10(BAND_UPPER), int(n_sub) + 1, axis=1)  # (20, n_sub+1)
    lo, hi = 10.0 ** cuts[:, :-1], 10.0 ** cuts[:, 1:]  # (20, n_sub) sub-interval edges, Hz
    mid, half = (hi + lo) / 2.0, (hi - lo) / 2.0
    f = mid[..., None] + half[..., None] * x  # (20, n_sub, n_gauss)
    wt = half[..., None] * w / (BAND_UPPER - BAND_LOWER)[:, None, None]
    return f.reshape(N_BANDS, -1), wt.reshape(N_BANDS, -1)


def subdivisions(damping_ratio: np.ndarray, frequency: np.ndarray) -> int:
    """Sub-intervals per band that resolve the sharpest resonance inside the bands.

    A mode of damping ratio ``zeta`` has a half-power width of ``2 zeta f``; a band is ``0.23 f`` wide.
    Sub-intervals no wider than ``zeta f`` put at least two of them (eight quadrature points) across each
    peak: ``ceil(0.23 / zeta_min)``, within :data:`MIN_SUBDIVISIONS` .. :data:`MAX_SUBDIVISIONS`, where
    ``zeta_min`` is the least damping ratio (over all cases) of a mode between the lowest band's lower edge
    and the highest band's upper edge.
    """
    z = np.asarray(damping_ratio, dtype=float)
    f = np.asarray(frequency, dtype=float)
    inside = (f >= BAND_LOWER[0]) & (f <= BAND_UPPER[-1]) & np.isfinite(z)
    if not inside.any():
        return MIN_SUBDIVISIONS
    zmin = float(z[inside].min())
    if not zmin > 0.0:
        return MAX_SUBDIVISIONS
    width = float(BAND_UPPER[0] - BAND_LOWER[0])  # a band's width over its centre: 0.2307
    return int(np.clip(np.ceil(width / zmin), MIN_SUBDIVISIONS, MAX_SUBDIVISIONS))


def _lever(r: np.ndarray) -> np.ndarray:
    """``[I, -[r]x]`` (..., 3, 6): a body point's displacement from ``q = [u, theta]``."""
    T = np.zeros(r.shape[:-1] + (3, 6))
    T[..., :, :3] = np.eye(3)
    T[..., :, 3:] = -model.skew(r)
    return T


def floor_to_point_velocity(
    M: np.ndarray,
    K: np.ndarray,
    C: np.ndarray,
    d: np.ndarray,
    k: np.ndarray,
    c_rel: np.ndarray,
    r: np.ndarray,
    freq: np.ndarray,
) -> np.ndarray:
    """Velocity of each point per unit floor *velocity* (complex ``G``, (Cn, F, p, 3 out, 3 in), 1).

    Multiply by ``i 2 pi f`` for the velocity per unit floor displacement (``H``, 1/s).

    Args:
        M, K, C: (Cn, 6, 6) mass, stiffness and damping matrices of the base, SI (``engine.model``).
        d: (Cn, n, 3) isolator lever arms from the c.g., m.
        k: (Cn, n, 3) isolator stiffness per floor axis, N/m.
        c_rel: (Cn, n, 3) damping on the relative velocity per floor axis, N s/m (zero for sky-hook).
        r: (Cn, p, 3) points of interest relative to the c.g., m.
        freq: (F,) or (Cn, F) frequencies, Hz (positive).
    """
    Cn = M.shape[0]
    f = np.broadcast_to(np.asarray(freq, dtype=float), (Cn, np.shape(freq)[-1]))
    w = 2.0 * np.pi * f  # (Cn, F)
    T = _lever(d)  # (Cn, n, 3, 6)
    P = _lever(r)  # (Cn, p, 3, 6)
    TK = np.einsum("cnki,cnk->cnik", T, k)  # (Cn, n, 6, 3): T^T diag(k) per mount
    TC = np.einsum("cnki,cnk->cnik", T, c_rel)
    Fk, Fc = TK.sum(axis=1), TC.sum(axis=1)  # (Cn, 6, 3): generalised force per unit floor x_f, v_f
    out = np.empty((Cn, f.shape[1], r.shape[1], 3, 3), dtype=complex)
    step = max(1, _SOLVES_PER_CHUNK // max(1, Cn))
    for lo in range(0, f.shape[1], step):
        ww = w[:, lo : lo + step, None, None]  # (Cn, Fc, 1, 1)
        D = K[:, None] - ww**2 * M[:, None] + 1j * ww * C[:, None]
        rhs = Fk[:, None] + 1j * ww * Fc[:, None]  # per unit floor displacement
        q = np.linalg.solve(D, rhs)  # (Cn, Fc, 6, 3)
        # point displacement per unit floor displacement = point velocity per unit floor velocity
        out[:, lo : lo + step] = np.einsum("cpoi,cfia->cfpoa", P, q)
    return out


def floor_displacement_to_point_velocity(
    M: np.ndarray,
    K: np.ndarray,
    C: np.ndarray,
    d: np.ndarray,
    k: np.ndarray,
    c_rel: np.ndarray,
    r: np.ndarray,
    freq: np.ndarray,
) -> np.ndarray:
    """Velocity of each point per unit floor *displacement*: ``H = i 2 pi f G`` (complex, (Cn, F, p, 3 out,
    3 in), 1/s). Arguments as :func:`floor_to_point_velocity`."""
    G = floor_to_point_velocity(M, K, C, d, k, c_rel, r, freq)
    f = np.broadcast_to(np.asarray(freq, dtype=float), (M.shape[0], np.shape(freq)[-1]))
    return G * (2j * np.pi * f)[:, :, None, None, None]


def point_band_velocity(
    M: np.ndarray,
    K: np.ndarray,
    C: np.ndarray,
    d: np.ndarray,
    k: np.ndarray,
    c_rel: np.ndarray,
    r: np.ndarray,
    band_velocity: np.ndarray,
    n_sub: int = MIN_SUBDIVISIONS,
) -> np.ndarray:
    """Band RMS velocity of each point per axis (Cn, p, 3, 20), m/s, for the floor's band RMS velocity
    ``band_velocity`` (Cn, 3 floor axes, 20 bands) m/s (axes uncorrelated, each flat within a band).

    The other arguments as :func:`floor_to_point_velocity`; ``n_sub`` sub-intervals per band
    (:func:`band_quadrature`, :func:`subdivisions`).
    """
    fq, wq = band_quadrature(n_sub)
    Cn = M.shape[0]
    out = np.zeros((Cn, r.shape[1], 3, N_BANDS))
    V2 = np.asarray(band_velocity, dtype=float) ** 2  # (Cn, 3, 20)
    chunk = max(1, _SOLVES_PER_CHUNK // fq.size)
    for lo in range(0, Cn, chunk):
        s = slice(lo, lo + chunk)
        G = floor_to_point_velocity(M[s], K[s], C[s], d[s], k[s], c_rel[s], r[s], fq.reshape(-1))
        G2 = (G.real**2 + G.imag**2).reshape(G.shape[0], N_BANDS, -1, r.shape[1], 3, 3)
        mean = np.einsum("cbqpoa,bq->cpoab", G2, wq)  # (c, p, out, in, band)
        out[s] = np.einsum("cpoab,cab->cpob", mean, V2[s])
    return np.sqrt(out)


def floor_to_point_velocity_per_mount(
    M: np.ndarray,
    K: np.ndarray,
    C: np.ndarray,
    d: np.ndarray,
    k: np.ndarray,
    c_rel: np.ndarray,
    r: np.ndarray,
    freq: np.ndarray,
) -> np.ndarray:
    """Velocity of each point per unit floor velocity under *one* mount (complex ``G_j``, (Cn, F, p,
    3 out, n mounts, 3 in), 1): the floor moves under mount ``j`` alone.

    ``(K - w^2 M + i w C) q_ja = T_j^T (k_j + i w c'_j) e_a``; by superposition the sum over the mounts is
    :func:`floor_to_point_velocity` (the uniform floor). Arguments as that function.
    """
    Cn, n = M.shape[0], d.shape[1]
    f = np.broadcast_to(np.asarray(freq, dtype=float), (Cn, np.shape(freq)[-1]))
    w = 2.0 * np.pi * f
    T = _lever(d)  # (Cn, n, 3, 6)
    P = _lever(r)
    Fk = np.einsum("cnki,cnk->cink", T, k).reshape(Cn, 6, n * 3)  # column (j, a): T_j^T k_j e_a
    Fc = np.einsum("cnki,cnk->cink", T, c_rel).reshape(Cn, 6, n * 3)
    out = np.empty((Cn, f.shape[1], r.shape[1], 3, n, 3), dtype=complex)
    step = max(1, _SOLVES_PER_CHUNK // max(1, Cn * n))
    for lo in range(0, f.shape[1], step):
        ww = w[:, lo : lo + step, None, None]
        D = K[:, None] - ww**2 * M[:, None] + 1j * ww * C[:, None]
        q = np.linalg.solve(D, Fk[:, None] + 1j * ww * Fc[:, None])  # (Cn, Fc, 6, 3n)
        pq = np.einsum("cpoi,cfim->cfpom", P, q)
        out[:, lo : lo + step] = pq.reshape(pq.shape[:4] + (n, 3))
    return out


def mount_band_velocity(
    M: np.ndarray,
    K: np.ndarray,
    C: np.ndarray,
    d: np.ndarray,
    k: np.ndarray,
    c_rel: np.ndarray,
    r: np.ndarray,
    band_velocity: np.ndarray,
    delay: np.ndarray,
    coherence: str,
    n_sub: int = MIN_SUBDIVISIONS,
) -> np.ndarray:
    """Band RMS velocity of each point per axis (Cn, p, 3, 20), m/s, when the floor under each mount has
    its own band RMS velocity ``band_velocity`` (Cn, n, 3 floor axes, 20) m/s and delay ``delay`` (Cn, n)
    s. The floor axes stay uncorrelated; between mounts, per floor axis ``a``, band ``b``:

    - ``correlated``: ``v^2 = mean_b |sum_j G_j V_jab exp(-i w tau_j)|^2`` (a travelling wave when the
      delays differ; the uniform floor when they are zero and ``V_j`` equal);
    - ``uncorrelated``: ``v^2 = sum_j V_jab^2 mean_b |G_j|^2``;
    - ``worst_phase``: ``v^2 = mean_b (sum_j |G_j| V_jab)^2``, the largest response any phases between
      the mounts give at each frequency (an upper bound of both others).

    Summed over the floor axes. Other arguments as :func:`point_band_velocity`.
    """
    fq, wq = band_quadrature(n_sub)
    Cn, n, p = M.shape[0], d.shape[1], r.shape[1]
    out = np.zeros((Cn, p, 3, N_BANDS))
    V = np.asarray(band_velocity, dtype=float)  # (Cn, n, 3, 20)
    omega = 2.0 * np.pi * fq  # (20, Q)
    chunk = max(1, _SOLVES_PER_CHUNK // (fq.size * max(1, n * p)))
    for lo in range(0, Cn, chunk):
        s = slice(lo, lo + chunk)
        G = floor_to_point_velocity_per_mount(M[s], K[s], C[s], d[s], k[s], c_rel[s], r[s], fq.reshape(-1))
        G = G.reshape(G.shape[0], N_BANDS, -1, p, 3, n, 3)  # (c, b, q, p, o, j, a)
        if coherence == "uncorrelated":
            mean = np.einsum("cbqpoja,bq->cpojab", G.real**2 + G.imag**2, wq)
            out[s] = np.einsum("cpojab,cjab->cpob", mean, V[s] ** 2)
            continue
        if coherence == "worst_phase":
            S = np.einsum("cbqpoja,cjab->cbqpoa", np.abs(G), V[s])
        else:
            phase = np.exp(
                -1j * omega[None, :, :, None] * np.asarray(delay[s], dtype=float)[:, None, None, :]
            )
            S = np.einsum("cbqpoja,cjab,cbqj->cbqpoa", G, V[s], phase)
        out[s] = np.einsum("cbqpoa,bq->cpob", S.real**2 + S.imag**2, wq)
    return np.sqrt(out)


def batch_point_band_velocity(
    batch: SceneBatch,
    band_velocity: np.ndarray | None = None,
    matrices: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    modes: modal.Modes | None = None,
) -> np.ndarray:
    """Band RMS velocity of each point of interest per axis (C, p, 3, 20), m/s, of a batch under its
    floor spectrum (``batch.floor_band_velocity``, or ``band_velocity`` (C, 3, 20) m/s).

    ``matrices`` (M, K, C of ``engine.model`` with the stages at home) and ``modes`` (their
    ``modal.modes``) are computed when not given. Cases with a mechanism or a tipping mode get NaN.
    """
    V = batch.floor_band_velocity if band_velocity is None else band_velocity
    V = np.broadcast_to(np.asarray(V, dtype=float), (batch.n_cases, 3, N_BANDS))
    if matrices is None:
        matrices = model.mass_matrix(batch), model.stiffness_matrix(batch), model.damping_matrix(batch)
    M, K, Cm = matrices
    if modes is None:
        modes = modal.modes(M, K, Cm)
    bad = modes.tipping | modes.mechanism.any(axis=1)
    out = np.full((batch.n_cases, batch.n_points, 3, N_BANDS), np.nan)
    good = np.flatnonzero(~bad)
    if good.size == 0 or batch.n_points == 0:
        return out
    d, _, r = model.relative_geometry(batch)
    c_rel = batch.iso_c * (1.0 - np.asarray(batch.iso_skyhook, dtype=float)[..., None])
    n_sub = subdivisions(modes.damping_ratio[good], modes.frequency[good])
    if band_velocity is None and batch.has_mount_floor:
        Vm = batch.floor_mount_band_velocity
        if Vm is None:
            Vm = np.broadcast_to(V[:, None], (batch.n_cases, batch.n_isolators, 3, N_BANDS))
        out[good] = mount_band_velocity(
            M[good], K[good], Cm[good], d[good], batch.iso_k[good], c_rel[good], r[good],
            np.asarray(Vm)[good], np.asarray(batch.floor_delay)[good], batch.floor_coherence, n_sub,
        )  # fmt: skip
        return out
    out[good] = point_band_velocity(
        M[good], K[good], Cm[good], d[good], batch.iso_k[good], c_rel[good], r[good], V[good], n_sub
    )
    return out


def worst_band(band_velocity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Largest band RMS velocity over the bands (last axis) and the exact centre of that band, Hz.

    Where every band is zero the centre is 0; where the input is NaN both are NaN.
    """
    v = np.asarray(band_velocity, dtype=float)
    nan = np.isnan(v).any(axis=-1)
    safe = np.where(np.isnan(v), -np.inf, v)
    idx = np.argmax(safe, axis=-1)
    top = np.take_along_axis(safe, idx[..., None], axis=-1)[..., 0]
    centre = np.where(top > 0.0, BAND_CENTRES[idx], 0.0)
    top = np.where(nan, np.nan, np.maximum(top, 0.0))
    return top, np.where(nan, np.nan, centre)
