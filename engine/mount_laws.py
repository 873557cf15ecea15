"""Isolator laws from physics: air springs, the orifice's relaxation, elastomers' Maxwell ladders.

Every law here is linear and written as a complex stiffness ``K(w)`` (N/m) of one mount along one axis: a
static spring ``k0`` in parallel with Maxwell branches (a spring ``k_b`` in series with a dashpot of
relaxation time ``tau_b``):

``K(w) = k0 + sum_b k_b i w tau_b / (1 + i w tau_b)``,  loss factor ``eta(w) = Im K / Re K``.

One branch is the standard linear solid (Zener); an air spring whose reservoir is reached through an
orifice is one. Its state-space form adds one internal state per branch, the dashpot's displacement
``z_b`` (``dz_b/dt = (delta - z_b) / tau_b``, force ``-k0 delta - sum k_b (delta - z_b)``).

As extra linear states of the linear levels (``engine.linear_states.mount_branches``, joined through
``engine.model.SLOT_MODELS``) the state of a branch is its series spring's deflection ``w_b = delta - z_b``:
``dw_b/dt = delta' - w_b / tau_b``, the mount's force ``-k delta - c delta' - sum k_b w_b`` along its axis.

Plain numpy, SI throughout; nothing here is compiled.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from isolab.engine.scene import SceneBatch, SceneError

ATMOSPHERE = 101325.0
"""Standard atmospheric pressure, Pa."""
AIR_VISCOSITY = 1.81e-5
"""Dynamic viscosity of air at 20 C, Pa s."""


def air_pressure(load: ArrayLike, effective_area: ArrayLike) -> np.ndarray:
    """Gauge pressure (Pa) an air spring of ``effective_area`` (m^2) needs to carry ``load`` (N):
    ``F / A``."""
    return np.asarray(load, dtype=float) / np.asarray(effective_area, dtype=float)


def air_stiffness(
    gauge_pressure: ArrayLike,
    effective_area: ArrayLike,
    volume: ArrayLike,
    polytropic_exponent: ArrayLike = 1.4,
    atmosphere: float = ATMOSPHERE,
) -> np.ndarray:
    """Vertical stiffness (N/m) of an air spring: ``n p_abs A^2 / V``, with ``p_abs`` the absolute
    pressure (gauge plus ``atmosphere``, Pa), ``A`` the effective area (m^2), ``V`` the gas volume the
    motion compresses (m^3) and ``n`` the polytropic exponent (1 isothermal, 1.4 adiabatic air). The
    change of effective area with stroke (a bellows' own stiffness) is left out."""
    p_abs = np.asarray(gauge_pressure, dtype=float) + atmosphere
    A = np.asarray(effective_area, dtype=float)
    return np.asarray(polytropic_exponent, dtype=float) * p_abs * A * A / np.asarray(volume, dtype=float)


def orifice_resistance(
    area: ArrayLike, length: ArrayLike, viscosity: ArrayLike = AIR_VISCOSITY
) -> np.ndarray:
    """Flow resistance (Pa s/m^3) of a laminar capillary between spring and reservoir: Hagen-Poiseuille
    ``8 pi mu L / A^2`` for a round bore of ``area`` (m^2) and ``length`` (m), ``mu`` in Pa s."""
    A = np.asarray(area, dtype=float)
    return 8.0 * np.pi * np.asarray(viscosity, dtype=float) * np.asarray(length, dtype=float) / (A * A)


def air_zener(
    gauge_pressure: ArrayLike,
    effective_area: ArrayLike,
    volume: ArrayLike,
    reservoir_volume: ArrayLike,
    resistance: ArrayLike,
    polytropic_exponent: ArrayLike = 1.4,
    atmosphere: float = ATMOSPHERE,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The standard linear solid of an air spring with a reservoir behind an orifice.

    Slow motion shares the gas of spring and reservoir: ``k0 = n p A^2 / (V + V_r)``. Fast motion finds
    the orifice shut: ``k0 + k1 = n p A^2 / V``. At fixed stroke the pressure difference across the
    orifice decays with ``tau = R V V_r / (n p (V + V_r))`` (linearised polytropic gas, volumetric flow
    ``dp / R``), the branch's relaxation time.

    Returns:
        ``k0`` (N/m), ``k1`` (N/m), ``tau`` (s).
    """
    n = np.asarray(polytropic_exponent, dtype=float)
    V = np.asarray(volume, dtype=float)
    Vr = np.asarray(reservoir_volume, dtype=float)
    p_abs = np.asarray(gauge_pressure, dtype=float) + atmosphere
    k0 = air_stiffness(gauge_pressure, effective_area, V + Vr, n, atmosphere)
    k_fast = air_stiffness(gauge_pressure, effective_area, V, n, atmosphere)
    tau = np.asarray(resistance, dtype=float) * V * Vr / (n * p_abs * (V + Vr))
    return k0, k_fast - k0, tau


def complex_stiffness(k0: ArrayLike, kb: ArrayLike, tau: ArrayLike, omega: ArrayLike) -> np.ndarray:
    """``K(w)`` (N/m, complex) of a static spring ``k0`` and Maxwell branches ``kb`` (..., B) N/m with
    relaxation times ``tau`` (..., B) s, at angular frequencies ``omega`` (W,) rad/s: shape (..., W)."""
    w = np.asarray(omega, dtype=float)
    kb = np.asarray(kb, dtype=float)[..., None]
    iwt = 1j * w * np.asarray(tau, dtype=float)[..., None]
    return np.asarray(k0, dtype=float)[..., None] + (kb * iwt / (1.0 + iwt)).sum(axis=-2)


def zener_loss_peak(k0: ArrayLike, k1: ArrayLike, tau: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """The largest loss factor of a standard linear solid and where it is: ``eta_max = k1 / (2 sqrt(k0
    (k0 + k1)))`` at ``w = sqrt(k0 / (k0 + k1)) / tau`` (rad/s)."""
    k0 = np.asarray(k0, dtype=float)
    k1 = np.asarray(k1, dtype=float)
    return k1 / (2.0 * np.sqrt(k0 * (k0 + k1))), np.sqrt(k0 / (k0 + k1)) / np.asarray(tau, dtype=float)


def fit_ladder(
    loss_factor: float, stiffening: float, f_low: float, f_high: float, branches: int = 3
) -> tuple[float, np.ndarray, np.ndarray]:
    """A Maxwell ladder with a nearly constant loss factor over ``[f_low, f_high]`` (Hz), for a static
    stiffness of 1 (scale every stiffness by the mount's).

    The branches' relaxation frequencies are spread log-evenly from half ``f_low`` to twice ``f_high``,
    and their stiffnesses (non-negative) solve, in least squares, ``Im K = loss_factor Re K`` at points
    across the band and ``Re K(f_high) / Re K(f_low) = stiffening``, with ``k0 = 1``. A constant loss
    factor and the stiffening over a decade are tied (Kramers-Kronig: about ``10^(2 eta / pi)``, 1.16 for
    ``eta = 0.1``): a pair far from it is met only in least squares.

    Returns:
        ``k0`` (1.0), ``kb`` (B,), ``tau`` (B,) s.
    """
    from scipy.optimize import nnls

    if not (0.0 < f_low < f_high) or loss_factor <= 0.0 or stiffening < 1.0 or branches < 1:
        raise ValueError("fit_ladder: need 0 < f_low < f_high, a positive loss factor, stiffening >= 1")
    fr = np.geomspace(f_low / 2.0, 2.0 * f_high, branches)
    tau = 1.0 / (2.0 * np.pi * fr)
    w = 2.0 * np.pi * np.geomspace(f_low, f_high, 8 * branches)
    iwt = 1j * w[:, None] * tau[None, :]
    G = iwt / (1.0 + iwt)  # (W, B): each branch's K per unit kb
    weight = np.sqrt(len(w))
    A = np.vstack([G.imag - loss_factor * G.real, weight * (G.real[-1] - stiffening * G.real[0])[None, :]])
    b = np.concatenate([np.full(len(w), loss_factor), [weight * (stiffening - 1.0)]])
    kb, _ = nnls(A, b)
    return 1.0, kb, tau


def equivalent_viscous(
    k0: ArrayLike, kb: ArrayLike, tau: ArrayLike, mass: ArrayLike, iterations: int = 20
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The spring and viscous damper that match a ladder at the natural frequency it gives ``mass`` (kg):
    ``w = sqrt(Re K(w) / m)`` by fixed-point iteration from the static stiffness, then ``k = Re K(w)``,
    ``c = Im K(w) / w``. Exact at that one frequency; the frequency dependence elsewhere is lost.

    Returns:
        ``k`` (N/m), ``c`` (N s/m), ``w`` (rad/s), each of ``k0``'s shape.
    """
    k0 = np.asarray(k0, dtype=float)
    m = np.asarray(mass, dtype=float)
    kb = np.asarray(kb, dtype=float)
    tau = np.asarray(tau, dtype=float)

    def at(w: np.ndarray) -> np.ndarray:  # K at each element's own w
        iwt = 1j * np.asarray(w)[..., None] * tau
        return k0 + (kb * iwt / (1.0 + iwt)).sum(axis=-1)

    w = np.sqrt(k0 / m)
    for _ in range(iterations):
        w = np.sqrt(at(w).real / m)
    K = at(w)
    return K.real, K.imag / w, w


def zener_peak(
    k_static: ArrayLike, k_branch: ArrayLike, c_branch: ArrayLike
) -> tuple[np.ndarray, np.ndarray]:
    """The loss peak of a spring ``k_static`` (N/m) in parallel with a spring ``k_branch`` (N/m) in series
    with a dashpot ``c_branch`` (N s/m): ``eta_max = k_branch / (2 sqrt(k_static (k_static + k_branch)))``
    at ``w = (k_branch / c_branch) sqrt(k_static / (k_static + k_branch))`` (rad/s); the same as
    :func:`zener_loss_peak` with ``tau = c_branch / k_branch``."""
    kb = np.asarray(k_branch, dtype=float)
    return zener_loss_peak(k_static, kb, np.asarray(c_branch, dtype=float) / kb)


def branch_states(b: SceneBatch) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The (mount, own axis, branch) indices of the relaxation branches that carry a state, in the order
    of their states: those whose stiffness ``b.iso_branch_k`` is above 0 in some case."""
    live = (np.asarray(b.iso_branch_k, dtype=float) > 0).any(axis=0)  # (n, 3, B)
    j, a, k = np.nonzero(live)
    return j, a, k


def check_branches(b: SceneBatch) -> None:
    """Refuse relaxation branches with a negative stiffness or a non-positive relaxation time."""
    kb = np.asarray(b.iso_branch_k, dtype=float)
    tau = np.asarray(b.iso_branch_tau, dtype=float)
    if kb.shape != tau.shape or kb.shape[:3] != (b.n_cases, b.n_isolators, 3):
        raise SceneError(
            "iso_branch_k", f"shape {kb.shape} (iso_branch_tau {tau.shape}), expected (C, n, 3, B) for both"
        )
    if (kb < 0).any():
        raise SceneError("iso_branch_k", "a relaxation branch's stiffness must be 0 (none) or above")
    if ((kb > 0) & ~(tau > 0)).any():
        raise SceneError("iso_branch_tau", "a relaxation branch's time must be above 0 s")
