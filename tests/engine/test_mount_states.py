"""Mounts with internal states: an air mount's orifice as a standard linear solid (Zener) and an
elastomer's Maxwell ladder, as extra linear states of the lti and ltv levels (``engine.model
.mount_relaxation_block``), checked against the closed-form loss peak and transfer functions."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from isolab.engine import model, mount_laws, simulate
from isolab.engine.scene import SceneError
from tests.engine.scenes import scene, vertical_stage

BASE, PUSH = 1000.0, 10.0
"""Base and stage masses of the heave scene, kg (the stage pushes at the c.g.: heave alone)."""
K1, K2, TAU = 4e6, 2e6, 0.01
"""Each of the four mounts: static spring (N/m), branch spring (N/m), relaxation time (s)."""


def heave_scene(k_static: float, kb: np.ndarray, tau: np.ndarray, duration: float = 0.5):
    """Four mounts near the c.g. under a wide base: static ``k_static`` vertically (1 % of it across),
    relaxation branches ``kb`` (B,) N/m with times ``tau`` (B,) s vertically, no viscous damping; a 10 kg
    stage accelerating up at 1 m/s^2 at the c.g. pushes the base down with 10 N."""
    b = scene(
        mass=BASE,
        size=(2.0, 2.0, 0.5),
        span=(0.4, 0.4),
        k=(k_static / 100, k_static / 100, k_static),
        c=(0.0, 0.0, 0.0),
        stages=[vertical_stage(PUSH, 1.0)],
        duration=duration,
        gravity_stiffness=False,
    )
    B = len(kb)
    k_b = np.zeros((1, 4, 3, B))
    k_b[:, :, 2] = kb
    t_b = np.ones((1, 4, 3, B))
    t_b[:, :, 2] = tau
    return replace(b, iso_branch_k=k_b, iso_branch_tau=t_b)


def heave_step(
    k_static: float, kb: np.ndarray, tau: np.ndarray, t: np.ndarray, derivative: int = 0
) -> np.ndarray:
    """Closed-form heave (m) under the step force ``F = -PUSH * 1 N``: ``X(s) = F / (s D(s))`` with ``D(s)
    = M s^2 + 4 K(s)``, ``K(s) = k + sum k_b tau_b s / (1 + tau_b s)``, inverted by residues (the poles of
    ``D(s) prod(1 + tau_b s)``); its ``derivative``-th time derivative (m/s^d) with ``derivative`` > 0."""
    M, F = BASE + PUSH, -PUSH
    num = np.poly1d([1.0])  # prod(1 + tau_b s)
    for tt in tau:
        num = num * np.poly1d([tt, 1.0])
    den = np.poly1d([M, 0.0, 4 * k_static]) * num
    for i, (k, tt) in enumerate(zip(kb, tau, strict=True)):
        others = np.poly1d([1.0])
        for jj, t2 in enumerate(tau):
            if jj != i:
                others = others * np.poly1d([t2, 1.0])
        den = den + np.poly1d([4 * k * tt, 0.0]) * others
    x = np.full_like(t, F * num(0.0) / den(0.0) if derivative == 0 else 0.0)
    for p in den.roots:
        x = x + (F * num(p) / (p * den.deriv()(p)) * p**derivative * np.exp(p * t)).real
    return x


def test_the_zener_state_space_has_the_closed_form_loss_peak() -> None:
    """A spring ``k1`` in parallel with ``k2`` in series with a dashpot ``c``: ``K(w) = k1 + k2 i w tau /
    (1 + i w tau)``, ``tau = c / k2``; ``eta(w) = k2 w tau / (k1 + (k1 + k2) w^2 tau^2)`` peaks at
    ``eta_max = k2 / (2 sqrt(k1 (k1 + k2)))`` where ``w tau = sqrt(k1 / (k1 + k2))``. The mount's complex
    stiffness read from the engine's state block (force per unit deflection of one mount's branch states)
    sweeps to that peak."""
    b = heave_scene(K1, np.array([K2]), np.array([TAU]))
    blk = model.mount_relaxation_block(b)
    assert blk is not None and blk.A.shape[1:] == (4, 4)
    # one mount's state: w' = delta' - w / tau; force -k2 w: K_branch(s) = k2 s / (s + 1/tau) / ... per delta
    a = blk.A[0, 0, 0]
    row = blk.X[0, 0, 6:]
    gain = -blk.G[0, :, 0] @ row / (row @ row)  # k2 (the force's size per unit state along the deflection)
    w = np.geomspace(1.0, 1e4, 200_001)
    K = K1 + gain * (1j * w) / (1j * w - a)
    eta = K.imag / K.real
    i = int(np.argmax(eta))
    eta_max, w_peak = mount_laws.zener_peak(K1, K2, K2 * TAU)
    assert eta_max == pytest.approx(K2 / (2 * np.sqrt(K1 * (K1 + K2))), rel=1e-12)
    assert w_peak == pytest.approx(np.sqrt(K1 / (K1 + K2)) / TAU, rel=1e-12)
    assert eta[i] == pytest.approx(eta_max, rel=1e-8)
    assert w[i] == pytest.approx(w_peak, rel=1e-4)


@pytest.mark.parametrize(
    ("fidelity", "integrator", "dt", "tol"),
    [("lti", "exact", 1e-3, 1e-12), ("lti", "rk4", 1e-4, 1e-8), ("ltv", "rk4", 1e-4, 1e-8)],
)
def test_a_mass_on_zener_mounts_follows_its_transfer_function(fidelity, integrator, dt, tol) -> None:
    t = np.arange(501) * 1e-3
    ref = heave_step(K1, np.array([K2]), np.array([TAU]), t)
    b = heave_scene(K1, np.array([K2]), np.array([TAU]))
    r = simulate(b, fidelity=fidelity, integrator=integrator, dt=dt, record=[0])
    assert r.status[0] == 0, r.message[0]
    z = np.interp(t, r.history["time"][0], r.history["displacement"][0, :, 2])
    assert np.abs(z - ref).max() <= tol * np.abs(ref).max()
    # the static spring alone (no branch) or the fast spring alone would move measurably differently
    for k in (K1, K1 + K2):
        other = heave_step(k, np.array([]), np.array([]), t)
        assert np.abs(other - ref).max() > 0.05 * np.abs(ref).max()


@pytest.mark.parametrize(
    ("fidelity", "integrator", "dt", "tol"),
    [("lti", "exact", 1e-3, 1e-9), ("lti", "rk4", 1e-4, 1e-6), ("ltv", "rk4", 1e-4, 1e-6)],
)
def test_a_zener_mount_reports_the_force_of_its_branch(fidelity, integrator, dt, tol) -> None:
    """The mounts' reported forces are what moves the base: their vertical sum equals ``M z'' + F`` (the
    base and stage, M, accelerating as the closed form says, and the stage's push F) at every output time,
    which the static spring's force alone does not (it is off by a fifth of the peak at first); each
    mount's peak is a quarter of that sum's largest value."""
    t = np.arange(501) * 1e-3
    b = heave_scene(K1, np.array([K2]), np.array([TAU]))
    r = simulate(b, fidelity=fidelity, integrator=integrator, dt=dt, record=[0])
    assert r.status[0] == 0, r.message[0]
    want = (BASE + PUSH) * heave_step(K1, np.array([K2]), np.array([TAU]), t, derivative=2) + PUSH
    forces = r.history["isolator_force"][0, :, :, 2]  # (steps, 4), N, on the base
    got = np.interp(t, r.history["time"][0], forces.sum(axis=1))
    assert np.abs(got - want).max() <= tol * np.abs(want).max()
    spring_alone = np.interp(t, r.history["time"][0], -4 * K1 * r.history["displacement"][0, :, 2])
    assert np.abs(spring_alone - want).max() > 0.1 * np.abs(want).max()
    fine = np.linspace(0.0, 0.5, 200_001)
    peak = np.abs((BASE + PUSH) * heave_step(K1, np.array([K2]), np.array([TAU]), fine, 2) + PUSH).max() / 4
    np.testing.assert_allclose(r.peak_isolator_force[0, :, 2], peak, rtol=1e-4)
    # a case not recorded (the output map's, which knows no branch force: the full observer takes it) the same
    plain = simulate(b, fidelity=fidelity, integrator=integrator, dt=dt)
    assert np.array_equal(plain.peak_isolator_force, r.peak_isolator_force)
    assert np.array_equal(plain.max_isolator_load, r.max_isolator_load)


def test_the_zener_mount_matches_its_equivalent_spring_damper_at_the_tuned_frequency() -> None:
    """The equivalent (``mount_laws.equivalent_viscous``: ``K(w_n)`` at the heave frequency it gives) has
    the Zener system's heave pole to 2 % in frequency and 10 % in decay rate (7.5 % here: the loss factor
    of 0.2 varies over the pole's bandwidth), and the engine's heave response to a force at ``w_n`` itself
    exactly (not at 0.3 ``w_n``); the relaxation's real pole it leaves out."""
    M = BASE + PUSH
    ke, ce, wn = mount_laws.equivalent_viscous(4 * K1, np.array([4 * K2]), np.array([TAU]), M)
    b = heave_scene(K1, np.array([K2]), np.array([TAU]))
    lam = np.linalg.eigvals(model.slot_state_matrix(model.params(b))[0])
    heave = lam[np.argmin(np.abs(np.abs(lam) - wn))]
    eq = np.roots([M, ce, ke])
    eq = eq[np.argmax(eq.imag)]
    assert abs(heave.imag) == pytest.approx(eq.imag, rel=0.02)
    assert -heave.real == pytest.approx(-eq.real, rel=0.1)
    # the engine's state-space heave response to a vertical force equals the equivalent's at w_n exactly
    A = model.slot_state_matrix(model.params(b))[0]
    force = np.zeros(A.shape[0])
    force[8] = 1.0 / M  # a unit vertical force at the c.g.: heave acceleration 1 / M

    def heave_per_force(w: float) -> complex:
        return np.linalg.solve(1j * w * np.eye(A.shape[0]) - A, force)[2]

    def equivalent_per_force(w: float) -> complex:
        return 1.0 / (-M * w * w + ke + 1j * w * ce)

    assert heave_per_force(wn) == pytest.approx(equivalent_per_force(wn), rel=1e-9)
    assert abs(heave_per_force(0.3 * wn) / equivalent_per_force(0.3 * wn) - 1) > 0.05  # elsewhere not


def test_a_mass_on_an_elastomer_ladder_follows_its_transfer_function() -> None:
    """Three Maxwell branches fitted to a loss factor of 0.1 over 5-50 Hz: heave at lti/exact against the
    closed-form step response of ``M s^2 + 4 K(s)``."""
    _, kb, tau = mount_laws.fit_ladder(0.1, 10 ** (0.2 / np.pi), 5.0, 50.0, branches=3)
    kb, tau = kb * K1, tau
    t = np.arange(501) * 1e-3
    ref = heave_step(K1, kb, tau, t)
    r = simulate(heave_scene(K1, kb, tau), "lti", "exact", 1e-3, record=[0])
    z = np.interp(t, r.history["time"][0], r.history["displacement"][0, :, 2])
    assert np.abs(z - ref).max() <= 1e-10 * np.abs(ref).max()
    # the ladder damps: the step's overshoot decays (no viscous damper in the scene)
    late = np.abs(ref[t > 0.4] - ref[-1]).max()
    assert late < 0.2 * np.abs(ref[t < 0.1] - ref[-1]).max()


def test_mount_states_settle_to_the_static_spring() -> None:
    """At rest a branch carries no force: the static target is the static spring's, ``F / (4 k1)``."""
    b = heave_scene(K1, np.array([K2]), np.array([TAU]), duration=2.0)
    r = simulate(b, "lti", "exact", 1e-3, record=[0])
    assert r.history["displacement"][0, -1, 2] == pytest.approx(-PUSH / (4 * K1), rel=1e-6)


def test_levels_integrators_and_inputs_that_do_not_model_the_states_refuse_them_by_name() -> None:
    b = heave_scene(K1, np.array([K2]), np.array([TAU]))
    for fidelity, integrator, words in (
        ("nonlinear", "rk4", "lti and ltv"),
        ("lti", "euler", "rk4 or exact"),
        ("ltv", "reference", "rk4 or exact"),
    ):
        with pytest.raises(SceneError) as err:
            simulate(b, fidelity=fidelity, integrator=integrator)
        assert err.value.field == "iso_branch_k" and words in err.value.reason
    with pytest.raises(SceneError, match="floor"):
        simulate(
            replace(b, floor_amp=np.array([[0.0, 0.0, 1e-6]]), floor_freq=np.array([[0, 0, 5.0]])), "lti"
        )
    bad = replace(b, iso_branch_k=-b.iso_branch_k)
    with pytest.raises(SceneError) as err:
        simulate(bad, "lti", "exact")
    assert err.value.field == "iso_branch_k"
    bad = replace(b, iso_branch_tau=np.zeros_like(b.iso_branch_tau))
    with pytest.raises(SceneError) as err:
        simulate(bad, "lti", "exact")
    assert err.value.field == "iso_branch_tau"


def test_a_scene_without_branches_has_no_extra_states() -> None:
    b = scene(stages=[vertical_stage(PUSH, 1.0)])
    assert not b.has_mount_branches and model.mount_relaxation_block(b) is None
    assert model.params(b).zA.shape == (1, 0, 0)
