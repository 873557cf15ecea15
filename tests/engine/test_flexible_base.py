"""A flexible base: elastic modes coupled to the rigid base by modal superposition (the extra linear
states of ``engine.model.linear_slot``), checked against closed forms and an independent assembly."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from isolab.engine import model, simulate
from isolab.engine.scene import SceneError
from tests.engine.scenes import scene, vertical_stage, y_stage

SX, SY = 1.1, 1.8
"""Half spans of the test scenes' mounts (mounts at (+-SX, +-SY, 0) about the c.g.), m."""
TWIST = np.array([1.0, -1.0, 1.0, -1.0])
"""A twisting mode's vertical shape at the mounts (+SX+SY, -SX+SY, -SX-SY, +SX-SY): orthogonal to heave,
pitch and roll, so the mounts stiffen it without coupling it to the rigid base."""


def flexible(b, freq, zeta, mass, iso, stage=None, point=None):
    """``b`` with one elastic mode: free-free ``freq`` (Hz), damping ratio ``zeta``, modal ``mass`` (kg) and
    vertical shapes ``iso`` (n,), ``stage`` (m,), ``point`` (p,) (1 at the worst corner)."""
    C, n, m, p = b.n_cases, b.n_isolators, b.n_stages, b.n_points

    def vertical(values, k):
        out = np.zeros((C, k, 3, 1))
        if values is not None:
            out[:, :, 2, 0] = values
        return out

    return replace(
        b,
        base_mode_frequency=np.full((C, 1), freq),
        base_mode_damping=np.full((C, 1), zeta),
        base_mode_mass=np.full((C, 1), mass),
        base_mode_iso=vertical(iso, n),
        base_mode_stage=vertical(stage, m),
        base_mode_point=vertical(point, p),
    )


def test_a_twisting_mode_on_its_mounts_stiffens_by_their_stiffness():
    """``w^2 = w0^2 + sum k_z phi_j^2 / m``: four mounts of 2 MN/m add 8 MN/m to a 2,500 kg mode at 30 Hz
    (4.4 % up)."""
    b = flexible(scene(span=(2 * SX, 2 * SY)), 30.0, 0.0, 2500.0, TWIST)
    P = model.params(b)
    lam = np.linalg.eigvals(model.slot_state_matrix(P)[0])
    w0 = 2 * np.pi * 30.0
    expected = np.sqrt(w0**2 + 4 * 2e6 / 2500.0)
    got = np.abs(lam)[np.argmin(np.abs(np.abs(lam) - expected))]
    assert got == pytest.approx(expected, rel=1e-9)
    assert expected / w0 - 1 > 0.01  # a shift the check can see


def _coupled_system(b):
    """The base and its mode as one second-order system ``[q, eta]``, assembled independently: each
    mount's deflection ``B_j [q, eta]`` with ``B_j = [I, -[d_j]x, phi_j]``, the mode's own stiffness
    ``w0^2 m``; masses ``diag(M, m + sum m_s phi_s^2)``."""
    d, _, _ = model.relative_geometry(b)
    n = b.n_isolators
    M = np.zeros((7, 7))
    M[:6, :6] = model.mass_matrix(b)[0]
    phi_s = b.base_mode_stage[0, :, :, 0]
    M[6, 6] = b.base_mode_mass[0, 0] + np.einsum("s,sa,sa->", b.stage_mass[0], phi_s, phi_s)
    K = np.zeros((7, 7))
    Cm = np.zeros((7, 7))
    assert not b.gravity_stiffness  # the mounts' stiffness is all there is
    for j in range(n):
        B = np.zeros((3, 7))
        B[:, :3] = np.eye(3)
        B[:, 3:6] = -model.skew(d[0, j])
        B[:, 6] = b.base_mode_iso[0, j, :, 0]
        K += B.T @ np.diag(b.iso_k[0, j]) @ B
        Cm += B.T @ np.diag(b.iso_c[0, j]) @ B
    w0 = 2 * np.pi * b.base_mode_frequency[0, 0]
    K[6, 6] += w0**2 * b.base_mode_mass[0, 0]
    Cm[6, 6] += 2 * b.base_mode_damping[0, 0] * w0 * b.base_mode_mass[0, 0]
    return M, K, Cm


def test_the_coupled_model_matches_solve_ivp_on_the_same_linear_system():
    """A 10 kg stage accelerating down at 1 m/s^2 from an off-centre home (a constant force at a point
    that drives heave, pitch and the mode): the lti level (exact and rk4) against DOP853 on the
    independently assembled system, at a point of interest that sees the mode."""
    home = (0.6, -0.9, 0.0)
    stage = vertical_stage(10.0, -1.0, home=home)
    b = scene(
        span=(2 * SX, 2 * SY), stages=[stage], points=[(SX, SY, 0.2)], duration=0.5, gravity_stiffness=False
    )
    b = flexible(b, 60.0, 0.02, 2500.0, np.array([1.0, -0.4, 0.7, -0.2]), stage=[0.5], point=[0.9])
    M, K, Cm = _coupled_system(b)
    f = np.zeros(7)
    f[:3] = [0.0, 0.0, 10.0]  # the stage's reaction -m a on the base, at its home
    f[3:6] = np.cross(home, f[:3])
    f[6] = 0.5 * 10.0  # and on the mode, through its shape there
    Minv = np.linalg.inv(M)

    def rhs(t, y):
        return np.concatenate([y[7:], Minv @ (f - K @ y[:7] - Cm @ y[7:])])

    t = np.arange(0, 501) * 1e-3
    sol = solve_ivp(rhs, (0, 0.5), np.zeros(14), method="DOP853", t_eval=t, rtol=1e-11, atol=1e-15)
    q = sol.y[:7].T
    p = np.array([SX, SY, 0.2])
    z_ref = q[:, 2] + q[:, 3] * p[1] - q[:, 4] * p[0] + 0.9 * q[:, 6]
    for integrator, tol in (("exact", 1e-7), ("rk4", 1e-5)):
        r = simulate(b, fidelity="lti", integrator=integrator, dt=1e-3, record=[0])
        assert r.status[0] == 0, r.message[0]
        z = r.history["point_displacement"][0, :, 0, 2]
        assert np.abs(z - z_ref).max() <= tol * np.abs(z_ref).max(), integrator
        assert r.peak_point_displacement[0, 0, 2] == pytest.approx(np.abs(z_ref).max(), rel=1e-4)
    # without the mode the point moves measurably differently: the check can fail
    rigid = simulate(
        replace(
            b,
            base_mode_frequency=None,
            base_mode_damping=None,
            base_mode_mass=None,
            base_mode_iso=None,
            base_mode_stage=None,
            base_mode_point=None,
        ),
        fidelity="lti",
        integrator="exact",
        dt=1e-3,
    )
    assert abs(rigid.peak_point_displacement[0, 0, 2] / np.abs(z_ref).max() - 1) > 1e-4


def test_a_very_stiff_mode_gives_the_rigid_base():
    """A mode at 20 kHz (lti/exact) deflects the base by (80 / 20,000)^2 = 1.6e-5 of a mode at 80 Hz: the
    peaks are the rigid base's to 3e-5, and the ltv level's with a 2 kHz mode to 1e-3."""
    b = scene(
        span=(2 * SX, 2 * SY), stages=[y_stage(home=(0.0, -1.5, 0.3))], points=[(SX, SY, 0.2)], duration=2.0
    )
    rigid_exact = simulate(b, fidelity="lti", integrator="exact", dt=1e-3)

    def bending(freq):  # the stage's Y force drives the mode (a section turning under it), the tool sees it
        f = flexible(b, freq, 0.01, 2500.0, TWIST, stage=[0.8], point=[1.0])
        f.base_mode_stage[:, 0, 1, 0] = 0.3
        f.base_mode_point[:, 0, 1, 0] = 0.3
        return f

    r = simulate(bending(2e4), fidelity="lti", integrator="exact", dt=1e-3)
    np.testing.assert_allclose(r.peak_point_displacement, rigid_exact.peak_point_displacement, rtol=3e-5)
    np.testing.assert_allclose(r.peak_isolator_force, rigid_exact.peak_isolator_force, rtol=3e-5)
    soft = simulate(bending(80.0), "lti", "exact", 1e-3)
    change = np.abs(
        soft.peak_point_displacement[0, 0, 1:] / rigid_exact.peak_point_displacement[0, 0, 1:] - 1
    )
    assert change.max() > 1e-3  # Y and Z (the X peak is 0)
    rigid_ltv = simulate(b, fidelity="ltv", integrator="rk4", dt=1e-4)
    r = simulate(bending(2e3), "ltv", "rk4", 1e-4)
    assert r.status[0] == 0, r.message[0]
    np.testing.assert_allclose(r.peak_point_displacement, rigid_ltv.peak_point_displacement, rtol=1e-3)


def test_the_levels_and_integrators_that_do_not_model_it_refuse_it_by_name():
    b = flexible(scene(span=(2 * SX, 2 * SY)), 80.0, 0.01, 2500.0, TWIST)
    for fidelity, integrator, words in (
        ("nonlinear", "rk4", "lti and ltv"),
        ("lti", "euler", "rk4 or exact"),
    ):
        with pytest.raises(SceneError) as err:
            simulate(b, fidelity=fidelity, integrator=integrator)
        assert err.value.field == "base_mode_frequency" and words in err.value.reason
