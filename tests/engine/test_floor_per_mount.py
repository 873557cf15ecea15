"""The floor under each mount (engine.frequency): superposition, coherence between mounts, closed forms."""

from __future__ import annotations

import numpy as np
import pytest
from scenes import scene

from isolab.engine import frequency, model
from isolab.engine.scene import SceneError, concat
from isolab.engine.validation import validate

VCD = 6.25e-6


def _coupled(**kw):
    """Mounts 0.5 m below the c.g., a point off the c.g.: every floor axis moves every point axis."""
    b = scene(height=0.5, points=[(-0.15, -1.5, 0.43), (0.0, 0.0, 0.0)], **kw)
    b.floor_band_velocity[:] = VCD
    return b


def _heave():
    """Mounts in the c.g. plane, symmetric, the point at the c.g.: a vertical floor moves heave alone."""
    b = scene(height=0.0, points=[(0.0, 0.0, 0.0)])
    b.floor_band_velocity[:, 2, :] = VCD
    return b


def test_mount_transfers_sum_to_the_uniform_floor():
    b = _coupled()
    d, _, r = model.relative_geometry(b)
    mats = model.mass_matrix(b), model.stiffness_matrix(b), model.damping_matrix(b)
    c_rel = b.iso_c * (1.0 - b.iso_skyhook[..., None])
    f = np.geomspace(0.5, 100.0, 37)
    G = frequency.floor_to_point_velocity(*mats, d, b.iso_k, c_rel, r, f)
    Gj = frequency.floor_to_point_velocity_per_mount(*mats, d, b.iso_k, c_rel, r, f)
    assert Gj.shape == G.shape[:4] + (4, 3)
    assert np.allclose(Gj.sum(axis=4), G, rtol=1e-11, atol=1e-14 * np.abs(G).max())
    # one mount alone is not the uniform floor's quarter on a coupled base (the test can fail)
    assert not np.allclose(4 * Gj[..., 0, :], G, rtol=1e-3)


def test_correlated_without_delay_is_the_uniform_floor():
    b = _coupled()
    uniform = frequency.batch_point_band_velocity(b)
    b.floor_mount_band_velocity = np.repeat(b.floor_band_velocity[:, None], 4, axis=1)
    assert b.has_mount_floor
    per_mount = frequency.batch_point_band_velocity(b)
    assert np.allclose(per_mount, uniform, rtol=1e-10, atol=0.0)
    # a slow wave changes it
    b.floor_delay = (b.iso_pos[..., 1] / 50.0).copy()
    assert not np.allclose(frequency.batch_point_band_velocity(b), uniform, rtol=1e-3)


def test_symmetric_heave_coherence_factors():
    """Each of 4 mounts gives a quarter of the heave: correlated 4x, uncorrelated sqrt(4) = 2x one mount's."""
    b = _heave()
    uniform = frequency.batch_point_band_velocity(b)[0, 0, 2]
    one = b.floor_band_velocity[:, None].repeat(4, axis=1)
    one[:, 1:] = 0.0  # the floor moves under mount 0 alone
    b.floor_mount_band_velocity = one
    single = frequency.batch_point_band_velocity(b)[0, 0, 2]
    assert np.allclose(single, uniform / 4, rtol=1e-9)
    b.floor_mount_band_velocity = None
    out = {}
    for coh in ("correlated", "uncorrelated", "worst_phase"):
        b.floor_coherence = coh
        out[coh] = frequency.batch_point_band_velocity(b)[0, 0, 2]
    assert np.allclose(out["correlated"], 4 * single, rtol=1e-9)
    assert np.allclose(out["uncorrelated"], 2 * single, rtol=1e-9)
    assert np.allclose(out["worst_phase"], out["correlated"], rtol=1e-9)  # equal phases are the worst


@pytest.mark.parametrize("delay_speed", [None, 40.0])
def test_worst_phase_bounds_the_others_in_every_band(delay_speed):
    b = _coupled()
    b.floor_band_velocity[:, 1] = 2 * VCD
    if delay_speed:
        b.floor_delay = (b.iso_pos @ np.array([0.6, 0.8, 0.0]) / delay_speed).copy()
    out = {}
    for coh in ("correlated", "uncorrelated", "worst_phase"):
        b.floor_coherence = coh
        out[coh] = frequency.batch_point_band_velocity(b)
    tol = 1 + 1e-12
    assert (out["worst_phase"] * tol >= out["correlated"]).all()
    assert (out["worst_phase"] * tol >= out["uncorrelated"]).all()
    assert (out["worst_phase"] > 1.05 * out["correlated"]).any()  # phases matter on a coupled base


def test_refusals():
    b = _coupled()
    b.floor_coherence = "partly"
    with pytest.raises(SceneError, match="floor_coherence"):
        validate(b)
    b = _coupled()
    b.floor_mount_band_velocity = np.zeros((1, 3, 3, 20))
    with pytest.raises(SceneError, match="floor_mount_band_velocity"):
        validate(b)
    b = _coupled()
    b.floor_delay = np.zeros((1, 3))
    with pytest.raises(SceneError, match="floor_delay"):
        validate(b)


def test_take_keeps_the_mount_floor():
    b = scene(n_cases=3, height=0.5)
    b.floor_mount_band_velocity = np.arange(3 * 4 * 3 * 20, dtype=float).reshape(3, 4, 3, 20)
    b.floor_coherence = "uncorrelated"
    t = b.take([2])
    assert t.floor_coherence == "uncorrelated"
    assert np.array_equal(t.floor_mount_band_velocity, b.floor_mount_band_velocity[[2]])
    assert scene(n_cases=2).take([1]).floor_mount_band_velocity is None


def test_concat_joins_mount_floors():
    a, b = scene(n_cases=2, height=0.5), scene(n_cases=1, height=0.5)
    assert concat([a, b]).floor_mount_band_velocity is None
    b.floor_band_velocity[:] = VCD
    a.floor_mount_band_velocity = np.ones((2, 4, 3, 20))
    a.floor_coherence = b.floor_coherence = "worst_phase"
    j = concat([a, b])
    assert j.floor_coherence == "worst_phase"
    assert np.array_equal(j.floor_mount_band_velocity[:2], a.floor_mount_band_velocity)
    assert np.array_equal(j.floor_mount_band_velocity[2], np.full((4, 3, 20), VCD))
