"""Steady-state floor-to-point velocity (engine.frequency) against closed forms."""

from __future__ import annotations

import numpy as np
import pytest
from scenes import scene, trapezoid_pieces

from isolab.engine import frequency, model, simulate
from isolab.engine.results import OK, TIPPING

MASS = 10_000.0
KZ, CZ = 2e6, 2e4  # per mount


def _matrices(b):
    return model.mass_matrix(b), model.stiffness_matrix(b), model.damping_matrix(b)


def _G(b, f):
    d, _, r = model.relative_geometry(b)
    c_rel = b.iso_c * (1.0 - b.iso_skyhook[..., None])
    return frequency.floor_to_point_velocity(*_matrices(b), d, b.iso_k, c_rel, r, f)


def sdof_transmissibility(r, zeta):
    return np.sqrt((1 + (2 * zeta * r) ** 2) / ((1 - r**2) ** 2 + (2 * zeta * r) ** 2))


def test_band_centres_and_edges():
    assert frequency.BAND_CENTRES[0] == 1.0
    assert np.allclose(frequency.BAND_CENTRES[[10, 19]], [10.0, 10**1.9])
    nominal = np.array(frequency.NOMINAL_CENTRES, dtype=float)
    assert np.all(np.abs(np.log10(nominal / frequency.BAND_CENTRES)) < 0.01)
    # contiguous bands: each upper edge is the next lower edge
    assert np.allclose(frequency.BAND_UPPER[:-1], frequency.BAND_LOWER[1:], rtol=1e-14)
    f, w = frequency.band_quadrature(5)
    assert np.allclose(w.sum(axis=1), 1.0, rtol=1e-13)
    assert np.all((f > frequency.BAND_LOWER[:, None]) & (f < frequency.BAND_UPPER[:, None]))


@pytest.mark.parametrize("point", [(0.0, 0.0, 0.0), (0.9, -1.4, 0.3)])
def test_heave_is_sdof_base_excitation(point):
    """Mounts in the c.g. plane, centred: a vertical floor drives heave alone, and |H_zz| is the SDOF
    base-excitation transmissibility times 2 pi f, at every frequency, for any point of the base."""
    b = scene(height=0.0, k=(1e6, 1e6, KZ), c=(1e4, 1e4, CZ), points=[point])
    f = np.geomspace(0.3, 150.0, 400)
    d, _, r = model.relative_geometry(b)
    H = frequency.floor_displacement_to_point_velocity(*_matrices(b), d, b.iso_k, b.iso_c, r, f)[0, :, 0]
    assert np.allclose(H, _G(b, f)[0, :, 0] * (2j * np.pi * f)[:, None, None], rtol=1e-14)
    fn = np.sqrt(4 * KZ / MASS) / (2 * np.pi)
    zeta = 4 * CZ / (2 * np.sqrt(4 * KZ * MASS))
    expect = sdof_transmissibility(f / fn, zeta) * 2 * np.pi * f
    assert np.allclose(np.abs(H[:, 2, 2]), expect, rtol=1e-9, atol=0)
    # vertical floor moves the point vertically only
    assert np.max(np.abs(H[:, :2, 2])) < 1e-9 * np.max(np.abs(H[:, 2, 2]))


def test_skyhook_heave():
    """A sky-hook damper acts on the base's absolute velocity: heave follows k / (k - m w^2 + i w c)."""
    b = scene(height=0.0, k=(1e6, 1e6, KZ), c=(1e4, 1e4, CZ), skyhook=True)
    f = np.geomspace(0.3, 150.0, 200)
    G = _G(b, f)[0, :, 0, 2, 2]
    w = 2 * np.pi * f
    expect = 4 * KZ / (4 * KZ - MASS * w**2 + 1j * w * 4 * CZ)
    assert np.allclose(G, expect, rtol=1e-9, atol=0)
    # far above resonance it isolates better than the same damper on the relative velocity (40 against
    # 20 dB/decade)
    passive = _G(scene(height=0.0, k=(1e6, 1e6, KZ), c=(1e4, 1e4, CZ)), f)[0, :, 0, 2, 2]
    hi = f > 100
    assert np.all(np.abs(G[hi]) < 0.5 * np.abs(passive[hi]))


def test_band_rms_matches_direct_integral():
    """Band RMS of a flat input through the heave transmissibility equals a dense direct integral."""
    zeta_target = 0.02
    cz = zeta_target * 2 * np.sqrt(4 * KZ * MASS) / 4
    b = scene(height=0.0, k=(1e6, 1e6, KZ), c=(1e4, 1e4, cz), points=[(0.0, 0.0, 0.0)])
    V = np.zeros((1, 3, 20))
    V[0, 2] = np.geomspace(20e-6, 3e-6, 20)  # m/s RMS per band
    out = frequency.batch_point_band_velocity(b, V)[0, 0]  # (3, 20)
    fn = np.sqrt(4 * KZ / MASS) / (2 * np.pi)
    for n in range(20):
        lo, hi = frequency.BAND_LOWER[n], frequency.BAND_UPPER[n]
        f = np.linspace(lo, hi, 200_001)
        T2 = sdof_transmissibility(f / fn, zeta_target) ** 2
        psd = V[0, 2, n] ** 2 / (hi - lo)
        direct = np.sqrt(np.trapezoid(T2 * psd, f))
        assert out[2, n] == pytest.approx(direct, rel=2e-4), n
    assert np.all(out[:2] < 1e-9 * out[2].max())


def test_low_frequency_passes_floor_velocity():
    """Well below the mount frequency the base follows the floor: the band velocity passes 1:1 along
    each axis, for a layout below the c.g. too (rotations vanish at low frequency)."""
    k = (40e6, 40e6, 80e6)  # ~14 Hz and ~20 Hz mounts under 10 t
    b = scene(height=0.5, k=k, c=(4e4, 4e4, 8e4), points=[(1.0, 1.5, 0.8)])
    V = np.zeros((1, 3, 20))
    V[0, :, 0] = [5e-6, 7e-6, 11e-6]  # only the 1 Hz band
    out = frequency.batch_point_band_velocity(b, V)[0, 0]
    assert np.allclose(out[:, 0], V[0, :, 0], rtol=2e-3)
    assert np.all(out[:, 1:] == 0.0)
    G = _G(b, np.array([1e-3]))[0, 0, 0]
    assert np.allclose(G, np.eye(3), atol=1e-6)


def test_simulate_fills_worst_band_even_when_unstable():
    y = {"mass": 500.0, "home": (0.0, 0.0, 0.3), "axis": (0, 1, 0), "pieces": trapezoid_pieces(1.0, 1.0, 5.0)}
    b = scene(n_cases=2, height=0.0, k=(1e6, 1e6, KZ), c=(1e4, 1e4, CZ), stages=[y], points=[(0, 0, 0)])
    b.floor_band_velocity[:, 2, :] = 10e-6
    good = simulate(b, fidelity="lti", integrator="exact", dt=2e-3)
    assert np.all(good.status == OK)
    bands = frequency.batch_point_band_velocity(b)
    top, centre = frequency.worst_band(bands)
    assert np.allclose(good.floor_point_velocity, top)
    assert np.allclose(good.floor_point_velocity_band, centre)
    fz = np.sqrt(4 * KZ / (MASS + 500.0)) / (2 * np.pi)  # heave frequency with the stage on board
    assert abs(np.log10(good.floor_point_velocity_band[0, 0, 2] / fz)) <= 0.051
    assert good.floor_point_velocity[0, 0, 2] > 10e-6  # amplified at resonance
    # a step far past the stability limit: no stepping, yet the floor outputs are there
    bad = simulate(b, fidelity="lti", integrator="euler", dt=5e-2, auto_step=False)
    assert np.all(bad.status != OK)
    assert np.allclose(bad.floor_point_velocity, good.floor_point_velocity)
    # no spectrum: zeros
    b.floor_band_velocity[:] = 0.0
    none = simulate(b, fidelity="lti", integrator="exact", dt=2e-3)
    assert np.all(none.floor_point_velocity == 0) and np.all(none.floor_point_velocity_band == 0)


def test_tipping_case_gets_nan():
    b = scene(height=3.0, k=(1e6, 1e6, 1e4), c=(1e3, 1e3, 1e2), size=(0.5, 0.5, 0.5), span=(0.3, 0.3))
    b.floor_band_velocity[:, 2, :] = 10e-6
    r = simulate(b, fidelity="lti", integrator="exact", dt=2e-3)
    assert r.status[0] == TIPPING
    assert np.all(np.isnan(r.floor_point_velocity))
