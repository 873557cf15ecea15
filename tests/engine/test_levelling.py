"""Levelling valves of air mounts as extra linear states (``engine.linear_states.levelling``), checked
against the closed-form characteristic polynomial of a valve on a heave mode, the valve's steady state
(height error back to zero, the valves carrying the static load change) and the dead band's rest."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from isolab.engine import model, simulate
from isolab.engine.scene import SceneError
from tests.engine.scenes import scene, vertical_stage, y_stage

G = 9.80665
KZ, CZ = 2e6, 2e4
"""Each mount's vertical stiffness (N/m) and damping (N s/m) in the test scenes."""


def with_valves(b, valves, tau, band=0.0):
    """``b`` with its mounts plumbed to ``valves`` (n,) (-1: none), time constant ``tau`` (s) and dead band
    ``band`` (m)."""
    C, n = b.n_cases, b.n_isolators
    v = np.repeat(np.asarray(valves, dtype=np.int64)[None], C, axis=0)
    return replace(b, iso_valve=v, iso_level_time=np.full((C, n), tau), iso_level_band=np.full((C, n), band))


FRONT_BACK = [0, 0, 1, 1]
"""Mounts 0, 1 (y > 0) on one valve, 2, 3 (y < 0) on another (``tests.engine.scenes.scene``'s order)."""


def test_eigenvalues_of_one_valve_on_a_heave_mode_are_the_roots_of_the_cubic():
    """Four mounts in the c.g. plane on one valve: heave decouples, and the state matrix's eigenvalues
    include the three roots of ``m s^3 + c s^2 + k s + k / tau`` (k, c the four mounts' sums); without a
    valve the heave pair alone (``m s^2 + c s + k``)."""
    tau = 2.0
    b = with_valves(scene(gravity_stiffness=False), [0, 0, 0, 0], tau)
    m, k, c = 10_000.0, 4 * KZ, 4 * CZ
    eig = np.linalg.eigvals(model.slot_state_matrix(model.params(b))[0])
    assert eig.shape == (13,)
    for root in np.roots([m, c, k, k / tau]):
        assert np.min(np.abs(eig - root)) < 1e-7 * abs(root)
    slow = np.roots([m, c, k, k / tau]).real.max()
    # the valve's pole: -(1 / tau) (1 + c / (k tau)) to first order in the mount's damping time c / k
    assert slow == pytest.approx(-(1.0 + c / (k * tau)) / tau, rel=1e-3)
    rigid = np.linalg.eigvals(model.slot_state_matrix(model.params(scene(gravity_stiffness=False)))[0])
    for root in np.roots([m, c, k]):
        assert np.min(np.abs(rigid - root)) < 1e-7 * abs(root)


@pytest.mark.parametrize("integrator", ["exact", "rk4"])
def test_a_step_load_is_levelled_away_and_carried_by_the_valve(integrator):
    """A 500 kg stage at the c.g. pushing up at 1 m/s^2 is a step load of -500 N on heave. Without a valve
    the base settles 500 N / k lower; with one its height follows the closed-form step response of the
    third-order heave-and-valve loop back to its set height (the valve force then carries the 500 N)."""
    tau, F = 0.5, 500.0
    base = scene(gravity_stiffness=False, stages=[vertical_stage(500.0, 1.0)], duration=6.0)
    b = with_valves(base, [0, 0, 0, 0], tau)
    k = 4 * KZ
    plain = simulate(base, "lti", integrator, 1e-3, record=[0])
    lev = simulate(b, "lti", integrator, 1e-3, record=[0])
    zp = plain.history["displacement"][0, :, 2]
    zl = lev.history["displacement"][0, :, 2]
    t = lev.history["time"][0]
    assert zp[-1] == pytest.approx(-F / k, rel=1e-6)
    assert abs(zl[-1]) < 1e-5 * F / k  # 6 s = 12 tau: the height error gone
    # closed form: (m s^2 + c s + k) X = Z - F / s, s Z = -(k / tau) X, so X = -F / D(s) with
    # D = m s^3 + c s^2 + k s + k / tau (m: base and stage): x(t) = sum over D's roots p, -F e^(p t) / D'(p)
    D = np.array([10_500.0, 4 * CZ, k, k / tau])
    x = sum(-F * np.exp(p * t) / np.polyval(np.polyder(D), p) for p in np.roots(D)).real
    np.testing.assert_allclose(zl, x, rtol=0, atol=1e-6 * F / k)
    # at rest the mounts' reported forces carry the 500 N, on springs alone or through the valve: the
    # mounts' own springs are back at their set height, and each reports its share of the valve's force
    for r in (plain, lev):
        assert r.history["isolator_force"][0, -1, :, 2].sum() == pytest.approx(F, rel=1e-4)
        assert np.all(r.max_isolator_load[0] >= r.static_isolator_load[0] + F / 4 * (1 - 1e-4))


@pytest.mark.parametrize(("fidelity", "integrator"), [("lti", "exact"), ("lti", "rk4"), ("ltv", "rk4")])
def test_two_valves_carry_the_weight_moment_of_a_travelled_stage(fidelity, integrator):
    """A 1,000 kg stage travels 3 m along Y: its weight moment shifts m g 3 m / 3.6 m = 8,172 N from the
    back mounts to the front ones. A valve on each pair brings both pairs back to their set height (heave
    and pitch zero, where without valves the base stays pitched), and the static solve gives each valve
    the load shift."""
    stage = y_stage(v=1.0, a=2.0)
    base = scene(stages=[stage], duration=8.0)
    b = with_valves(base, FRONT_BACK, 0.4)
    plain = simulate(base, fidelity, integrator, 1e-3, record=[0])
    lev = simulate(b, fidelity, integrator, 1e-3, record=[0])
    pitch_plain = plain.history["rotation"][0, -1, 0]
    assert abs(pitch_plain) > 1e-4  # rad: the unlevelled base stays pitched
    end = lev.history
    assert abs(end["rotation"][0, -1, 0]) < 1e-4 * abs(pitch_plain)
    assert abs(end["displacement"][0, -1, 2]) < 1e-8
    shift = 1000.0 * G * 3.0 / 3.6
    q, z = model.slot_static(b, fidelity, model.static_offset(b, fidelity))
    np.testing.assert_allclose(z[0], [shift, -shift], rtol=1e-8)
    # the loads at rest are the statics' whoever carries them: each front mount half the valve's shift
    # more, each back mount half less, as on the plain springs
    for r in (plain, lev):
        half = np.array([1.0, 1.0, -1.0, -1.0]) * shift / 2
        np.testing.assert_allclose(r.history["isolator_force"][0, -1, :, 2], half, rtol=1e-3)
        assert np.all(r.max_isolator_load[0, :2] >= r.static_isolator_load[0, :2] + shift / 2 * (1 - 1e-3))
        assert np.all(r.min_isolator_load[0, 2:] <= r.static_isolator_load[0, 2:] - shift / 2 * (1 - 1e-3))
    # heave (m), roll and pitch (rad) back to zero to round-off (the order of the steps' sums changes it
    # with the CPU's vector width: 2e-13 to 2e-12 seen), against the 1e-4 rad the unlevelled base keeps
    assert np.abs(lev.final_displacement[0, 2:5]).max() < 1e-11
    assert lev.settled[0]


def test_a_dead_band_stops_the_valve_at_its_edge():
    """With a dead band d an equilibrium needs DB(h, d) = 0: the base comes to rest with its height error
    inside +-d. Outside the band the loop is the linear one about the band's edge, so a load that sags
    the base well past the band is levelled to the edge it came from (-d), not to the set height, the
    valve carrying the load less k d."""
    tau, F, d = 1.0, 500.0, 20e-6
    base = scene(gravity_stiffness=False, stages=[vertical_stage(500.0, 1.0)], duration=10.0)
    lev = simulate(with_valves(base, [0, 0, 0, 0], tau, d), "lti", "rk4", 1e-3, record=[0])
    z = lev.history["displacement"][0, :, 2]
    assert F / (4 * KZ) > 3 * d  # the load's sag (62.5 um) is well outside the band
    # outside the band the loop is the linear one about -d: the height creeps to the band's lower edge
    # with the valve's pole and stays outside it
    assert -d * 1.001 <= z[-1] < -d
    assert np.all(np.diff(z[-3000:]) > 0)
    linear = simulate(with_valves(base, [0, 0, 0, 0], tau), "lti", "rk4", 1e-3, record=[0])
    assert abs(linear.history["displacement"][0, -1, 2]) < 1e-3 * d  # without the band: the set height


def test_a_very_slow_valve_changes_nothing():
    """A valve with a time constant of 10^9 s adds a force of order 10^-9 of the load: the peaks equal the
    unlevelled scene's."""
    base = scene(stages=[y_stage()], duration=3.0)
    plain = simulate(base, "ltv", "rk4", 1e-3)
    lev = simulate(with_valves(base, FRONT_BACK, 1e9), "ltv", "rk4", 1e-3)
    np.testing.assert_allclose(lev.peak_displacement, plain.peak_displacement, rtol=1e-6)
    np.testing.assert_allclose(lev.peak_rotation, plain.peak_rotation, rtol=1e-6)
    np.testing.assert_allclose(lev.peak_isolator_deflection, plain.peak_isolator_deflection, rtol=1e-6)


def test_refusals_name_the_field():
    """Four valves, a dead band with the exact integrator, the nonlinear level, euler, a valve without a
    time constant and mounts of one valve with different figures are refused, naming the input."""
    base = scene(stages=[y_stage()])
    cases = [
        (with_valves(base, [0, 1, 2, 3], 1.0), "ltv", "rk4", "iso_valve", "plumb two mounts to one valve"),
        (with_valves(base, FRONT_BACK, 1.0, 1e-5), "lti", "exact", "iso_level_band", "rk4"),
        (with_valves(base, FRONT_BACK, 1.0), "nonlinear", "rk4", "iso_valve", "lti and ltv"),
        (with_valves(base, FRONT_BACK, 1.0), "ltv", "euler", "iso_valve", "rk4 or exact"),
        (with_valves(base, FRONT_BACK, 0.0), "ltv", "rk4", "iso_level_time", "positive"),
        (with_valves(base, FRONT_BACK, 1.0, -1e-6), "ltv", "rk4", "iso_level_band", "negative"),
    ]
    for b, fidelity, integrator, field, words in cases:
        with pytest.raises(SceneError) as err:
            simulate(b, fidelity, integrator, 1e-3)
        assert err.value.field == field
        assert words in str(err.value)
    b = with_valves(base, FRONT_BACK, 1.0)
    tau = np.array(b.iso_level_time)
    tau[:, 1] = 2.0
    with pytest.raises(SceneError) as err:
        simulate(replace(b, iso_level_time=tau), "ltv", "rk4", 1e-3)
    assert err.value.field == "iso_level_time"
    assert "share valve 0" in str(err.value)
