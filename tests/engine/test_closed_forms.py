"""The engine against closed forms: natural frequencies, step response, transmissibility, momentum, statics.

Every expected value is computed here by hand from the scene's numbers, never read back from the engine.
"""

from __future__ import annotations

import numpy as np
import pytest
from scenes import box_inertia, mount, pieces_array, scene, vertical_stage, y_stage
from scipy.spatial.transform import Rotation

from isolab.engine import GRAVITY, concat, simulate
from isolab.engine.profiles import Pieces, evaluate, trapezoid
from isolab.engine.results import DOF_NAMES

TWO_PI = 2 * np.pi
M = 10_000.0
SIZE = (2.6, 4.2, 0.34)
SPAN = (2.2, 3.6)
A_HALF, B_HALF = SPAN[0] / 2, SPAN[1] / 2  # mount lever arms along X (a) and Y (b), m
K_MOUNT = (1.0e6, 1.5e6, 2.0e6)  # distinct per axis so that no two modes share a frequency
C_MOUNT = (1.0e3, 2.0e3, 3.0e3)


def _mode_of(result, dof: int, share: float) -> int:
    """Index of the mode whose kinetic energy lies in ``dof`` by more than ``share``."""
    hits = np.flatnonzero(result.mode_energy[0, :, dof] > share)
    assert hits.size == 1, f"no single mode dominated by {DOF_NAMES[dof]}: {result.mode_energy[0, :, dof]}"
    return int(hits[0])


# ------------------------------------------------------------------------------------------------- modes
def test_symmetric_layout_in_cg_plane_has_the_six_textbook_frequencies_and_damping() -> None:
    b = scene(mass=M, size=SIZE, span=SPAN, height=0.0, k=K_MOUNT, c=C_MOUNT, duration=0.01)
    r = simulate(b, "lti", "exact", dt=1e-3)
    kx, ky, kz = K_MOUNT
    cx, cy, cz = C_MOUNT
    ixx, iyy, izz = np.diag(box_inertia(M, *SIZE))
    a, bb = A_HALF, B_HALF
    stiff = [4 * kx, 4 * ky, 4 * kz, 4 * kz * bb**2, 4 * kz * a**2, 4 * (kx * bb**2 + ky * a**2)]
    damp = [4 * cx, 4 * cy, 4 * cz, 4 * cz * bb**2, 4 * cz * a**2, 4 * (cx * bb**2 + cy * a**2)]
    inert = [M, M, M, ixx, iyy, izz]
    for dof in range(6):
        # in this layout every mode moves exactly one DOF: its share is 1 up to rounding
        j = _mode_of(r, dof, 1 - 1e-9)
        f = np.sqrt(stiff[dof] / inert[dof]) / TWO_PI
        zeta = damp[dof] / (2 * np.sqrt(stiff[dof] * inert[dof]))
        # a 6x6 symmetric eigenproblem with well-separated roots: accurate to ~1e-14; 1e-9 leaves room
        assert r.natural_frequency[0, j] == pytest.approx(f, rel=1e-9), DOF_NAMES[dof]
        assert r.damping_ratio[0, j] == pytest.approx(zeta, rel=1e-9), DOF_NAMES[dof]
    # the brief's vertical damping check in the vendor's per-mount terms: 4 cz / (2 sqrt(4 kz M))
    jz = _mode_of(r, 2, 1 - 1e-9)
    assert r.damping_ratio[0, jz] == pytest.approx(cz / np.sqrt(kz * M), rel=1e-9)
    assert not r.mechanism.any()


def _pair(k11: float, k12: float, k22: float, m1: float, m2: float) -> tuple[np.ndarray, np.ndarray]:
    """The 2-DOF closed form of det(K - w^2 diag(m1, m2)) = 0: roots w^2 ascending, and each mode's
    kinetic-energy share in the first DOF (mode shape (k12, w^2 m1 - k11) from the first row)."""
    p = k11 * m2 + k22 * m1
    q = k11 * k22 - k12**2
    disc = np.sqrt(p * p - 4 * m1 * m2 * q)
    w2 = np.array([(p - disc) / (2 * m1 * m2), (p + disc) / (2 * m1 * m2)])
    phi1, phi2 = k12 * np.ones(2), w2 * m1 - k11
    share = m1 * phi1**2 / (m1 * phi1**2 + m2 * phi2**2)
    return w2, share


@pytest.mark.parametrize("gravity_stiffness", [True, False])
def test_mounts_below_the_cg_couple_translation_with_rocking(gravity_stiffness: bool) -> None:
    h = 0.5  # mounts 0.5 m below the c.g.
    b = scene(
        mass=M,
        size=SIZE,
        span=SPAN,
        height=h,
        k=K_MOUNT,
        c=C_MOUNT,
        duration=0.01,
        gravity_stiffness=gravity_stiffness,
    )
    r = simulate(b, "lti", "exact", dt=1e-3)
    kx, ky, kz = K_MOUNT
    ixx, iyy, izz = np.diag(box_inertia(M, *SIZE))
    a, bb = A_HALF, B_HALF
    # preload and weight tilting with the base: rocking stiffness -(weight x height above the mounts)
    rock = M * GRAVITY * h if gravity_stiffness else 0.0
    # x with rotation about Y: delta_x = x - h theta_y; z springs add kz a^2 per mount
    x_ry, x_share = _pair(4 * kx, -4 * kx * h, 4 * kx * h**2 + 4 * kz * a**2 - rock, M, iyy)
    # y with rotation about X: delta_y = y + h theta_x; z springs add kz b^2 per mount
    y_rx, y_share = _pair(4 * ky, 4 * ky * h, 4 * ky * h**2 + 4 * kz * bb**2 - rock, M, ixx)
    f_z = np.sqrt(4 * kz / M) / TWO_PI
    f_yaw = np.sqrt(4 * (kx * bb**2 + ky * a**2) / izz) / TWO_PI
    expected = np.sort(np.concatenate([np.sqrt(x_ry), np.sqrt(y_rx), [TWO_PI * f_z, TWO_PI * f_yaw]]))
    np.testing.assert_allclose(r.natural_frequency[0], expected / TWO_PI, rtol=1e-9)
    # heave and yaw stay pure; the rocking pairs share their energy between translation and rotation
    assert r.natural_frequency[0, _mode_of(r, 2, 1 - 1e-9)] == pytest.approx(f_z, rel=1e-9)
    assert r.natural_frequency[0, _mode_of(r, 5, 1 - 1e-9)] == pytest.approx(f_yaw, rel=1e-9)
    e = r.mode_energy[0]
    for trans, rot, roots, share in ((0, 4, x_ry, x_share), (1, 3, y_rx, y_share)):
        for w2, sh in zip(roots, share, strict=True):
            j = int(np.argmin(np.abs(r.natural_frequency[0] - np.sqrt(w2) / TWO_PI)))
            assert e[j, trans] + e[j, rot] == pytest.approx(1.0, abs=1e-9)
            assert e[j, trans] == pytest.approx(sh, rel=1e-7)
            assert min(e[j, trans], e[j, rot]) > 0.01, f"mode {j} not mixed: {e[j]}"


# --------------------------------------------------------------------------------------- step response
A0 = 2.0  # stage acceleration, m/s^2
M_STAGE = 1000.0


def _heave_step(t: np.ndarray, kz: float, cz: float) -> tuple[np.ndarray, float]:
    """x(t) of the one-DOF heave under the step force -m a0, and the static deflection F/k."""
    mass = M + M_STAGE  # the stage moves with the base: it adds to the moving mass
    k, c, f = 4 * kz, 4 * cz, -M_STAGE * A0
    wn = np.sqrt(k / mass)
    zeta = c / (2 * np.sqrt(k * mass))
    wd = wn * np.sqrt(1 - zeta**2)
    x = f / k * (1 - np.exp(-zeta * wn * t) * (np.cos(wd * t) + zeta / np.sqrt(1 - zeta**2) * np.sin(wd * t)))
    return x, f / k


@pytest.mark.parametrize(
    ("fidelity", "integrator", "dt", "rtol"),
    [
        # exact discretisation of a constant force: rounding only
        ("lti", "exact", 5e-3, 1e-9),
        # RK4 global error ~ (wn dt)^4 wn t / 120 with wn dt = 0.027: ~1e-7; measured 1.4e-8
        ("lti", "rk4", 1e-3, 1e-6),
        ("ltv", "rk4", 1e-3, 1e-6),
        ("nonlinear", "rk4", 1e-3, 1e-6),
        # DOP853 at rtol 1e-10 over ~5 periods
        ("ltv", "reference", 1e-3, 1e-7),
        ("nonlinear", "reference", 1e-3, 1e-7),
    ],
)
def test_vertical_force_step_gives_the_one_dof_step_response(
    fidelity: str, integrator: str, dt: float, rtol: float
) -> None:
    kz, cz = 2e6, 2e4  # per mount: wn = 28 rad/s, zeta = 0.14
    b = scene(mass=M, k=(1e6, 1e6, kz), c=(1e4, 1e4, cz), stages=[vertical_stage(M_STAGE, A0)], duration=1.0)
    r = simulate(b, fidelity, integrator, dt=dt, record=[0])
    assert r.status[0] == 0, r.message[0]
    t = r.history["time"][0]
    x, static = _heave_step(t, kz, cz)
    z = r.history["displacement"][0, :, 2]
    assert np.abs(z - x).max() <= rtol * abs(static)
    # the step overshoots: a heave of 0.2 mm peaks at F/k (1 + exp(-zeta pi / sqrt(1 - zeta^2)))
    assert np.abs(z).max() > 1.5 * abs(static)
    # nothing else moves: the force acts through the c.g.
    assert np.abs(r.history["displacement"][0, :, :2]).max() <= 1e-12 * abs(static)
    assert np.abs(r.history["rotation"][0]).max() <= 1e-12


# ------------------------------------------------------------------------------------- transmissibility
F_N = 10.0  # heave natural frequency of the transmissibility scenes, Hz


def _floor_scene(ratios: np.ndarray, zeta: np.ndarray, skyhook: bool = False, duration: float = 0.01):
    """Symmetric layout, no stages, heave at F_N Hz, a 10 um vertical floor sine at r F_N per case."""
    kz, cz = mount(M / 4, F_N, 1.0)
    b = scene(
        n_cases=len(ratios),
        mass=M,
        k=(kz, kz, kz),
        c=(cz, cz, cz),
        skyhook=skyhook,
        duration=duration,
        floor_amp=(0.0, 0.0, 10e-6),
        floor_freq=(0.0, 0.0, F_N),
    )
    b.floor_freq[:, 2] = F_N * np.asarray(ratios)
    b.iso_c[:] = np.asarray(zeta)[:, None, None] * cz  # c = 2 zeta sqrt(k m) with m = M / 4
    return b


def _t_passive(r: np.ndarray, zeta: np.ndarray) -> np.ndarray:
    return np.sqrt(1 + (2 * zeta * r) ** 2) / np.sqrt((1 - r**2) ** 2 + (2 * zeta * r) ** 2)


def _t_skyhook(r: np.ndarray, zeta: np.ndarray) -> np.ndarray:
    return 1.0 / np.sqrt((1 - r**2) ** 2 + (2 * zeta * r) ** 2)


def test_transmissibility_matches_the_one_dof_formula() -> None:
    ratios = np.array([0.5, 1.0, 2.0, 5.0, 10.0, 10.0, 100.0])
    zeta = np.array([0.2, 0.2, 0.2, 0.2, 0.2, 0.001, 0.001])
    for skyhook, formula in ((False, _t_passive), (True, _t_skyhook)):
        r = simulate(_floor_scene(ratios, zeta, skyhook), "lti", "exact", dt=1e-3)
        # a 6x6 complex solve of a decoupled heave: rounding only; 1e-9 is far inside the brief's 1e-6
        np.testing.assert_allclose(r.transmissibility[:, 2], formula(ratios, zeta), rtol=1e-9)
        # no floor motion along X or Y: no transmissibility reported there
        assert np.all(r.transmissibility[:, :2] == 0.0)
    # light damping: from r = 10 to 100 the passive mount isolates by ~40 dB more
    # (exactly 20 log10(T(10) / T(100)) = 39.92 dB at zeta = 0.001)
    r = simulate(_floor_scene(ratios, zeta), "lti", "exact", dt=1e-3)
    drop = 20 * np.log10(r.transmissibility[5, 2] / r.transmissibility[6, 2])
    assert 39.5 < drop < 40.1
    assert r.transmissibility[1, 2] == pytest.approx(np.sqrt(1 + 0.4**2) / 0.4, rel=1e-9)  # at resonance


@pytest.mark.parametrize(("fidelity", "integrator"), [("lti", "exact"), ("ltv", "rk4")])
def test_simulated_steady_state_amplitude_equals_the_transmissibility(fidelity: str, integrator: str) -> None:
    # r = 2, zeta = 0.2: 30 floor periods of 50 ms; passive and sky-hook mounts side by side
    b = concat(
        [
            _floor_scene(np.array([2.0]), np.array([0.2]), duration=1.5),
            _floor_scene(np.array([2.0]), np.array([0.2]), skyhook=True, duration=1.5),
        ]
    )
    r = simulate(b, fidelity, integrator, dt=1e-3, record=[0, 1])
    t = r.history["time"][0]
    # fit the last 10 periods with sin, cos and offset at the floor frequency: the start transient has
    # decayed by exp(-zeta wn t) = exp(-0.2 * 62.8 * 1.0) = 4e-6 by then
    late = t >= 1.0 - 1e-9
    w = TWO_PI * 2.0 * F_N
    basis = np.stack([np.sin(w * t[late]), np.cos(w * t[late]), np.ones(late.sum())], axis=1)
    for case, formula in ((0, _t_passive), (1, _t_skyhook)):
        z = r.history["displacement"][case, late, 2]
        coef, *_ = np.linalg.lstsq(basis, z, rcond=None)
        amplitude = np.hypot(coef[0], coef[1]) / 10e-6
        expected = formula(np.array(2.0), np.array(0.2))
        # transient 4e-6 of the input, RK4 at w dt = 0.13 loses little more: measured 2e-7 (exact) and
        # 6e-7 (rk4); 1e-5 is far inside the brief's 1 %
        assert amplitude == pytest.approx(expected, rel=1e-5)
        assert r.transmissibility[case, 2] == pytest.approx(expected, rel=1e-9)


# --------------------------------------------------------------------------------------------- momentum
def _free_floating(fidelity: str, integrator: str):
    """Zero stiffness and damping, no gravity: 1000 kg stage, 3 m off-centre stroke on a 10 t base."""
    stage = y_stage(mass=1000.0, travel=3.0, v=2.0, a=2 * GRAVITY, home=(0.6, -1.5, 0.3))
    b = scene(mass=M, k=(0.0, 0.0, 0.0), c=(0.0, 0.0, 0.0), stages=[stage], duration=2.0, g=0.0)
    r = simulate(b, fidelity, integrator, dt=5e-3, record=[0])
    assert r.status[0] == 0, r.message[0]
    h = r.history
    t = h["time"][0]
    s, _, _ = evaluate(Pieces(*(row[None] for row in stage["pieces"])), t)
    rho_h = np.asarray(stage["home"])
    rho = rho_h + s[0][:, None] * np.array([0.0, 1.0, 0.0])  # stage c.g. in the machine frame
    return h["displacement"][0], h["rotation"][0], rho, rho_h, 1000.0, r


def test_free_floating_ltv_keeps_the_common_centre_of_mass() -> None:
    u, th, rho, rho_h, m, r = _free_floating("ltv", "reference")
    composite = (M * u + m * (u + np.cross(th, rho) + rho - rho_h)) / (M + m)
    assert np.abs(composite).max() < 1e-9  # lead measured 1.8e-12 m; the stage travels 3 m
    assert np.abs(u[:, 1]).max() > 0.1  # the base recoils by ~0.27 m: the check is not vacuous
    assert r.mechanism.all() and np.all(r.natural_frequency == 0.0)


def test_free_floating_nonlinear_keeps_the_common_centre_of_mass() -> None:
    u, th, rho, rho_h, m, _ = _free_floating("nonlinear", "reference")
    rot = Rotation.from_rotvec(th).as_matrix()
    composite = (M * u + m * (u + np.einsum("tij,tj->ti", rot, rho) - rho_h)) / (M + m)
    assert np.abs(composite).max() < 1e-9


def test_free_floating_lti_moves_the_common_centre_of_mass() -> None:
    # the frozen mass matrix keeps the stage at home: the momentum balance is off by millimetres
    u, th, rho, rho_h, m, _ = _free_floating("lti", "exact")
    composite = (M * u + m * (u + np.cross(th, rho) + rho - rho_h)) / (M + m)
    assert np.abs(composite).max() > 1e-3


# ------------------------------------------------------------------------------------------ static tilt
def test_parked_stage_tilts_the_base_to_the_static_solution() -> None:
    h, hz, dy, ms = 0.3, 0.3, 1.5, 1000.0  # mounts 0.3 m below the c.g.; stage 0.3 m above it
    mt = M + ms
    k, c = mount(mt / 4, 6.0, 0.6)  # stiff and heavily damped: settled 1 s after the move
    stage = {
        "mass": ms,
        "home": (0.0, -1.5, hz),
        "axis": (0.0, 1.0, 0.0),
        "pieces": pieces_array(trapezoid(dy, 2.0, GRAVITY)),
    }
    b = scene(mass=M, height=h, k=(k, k, k), c=(c, c, c), stages=[stage], duration=2.0)
    # hand solution: y and pitch (rotation about X) couple through the mounts below the c.g.
    rock = mt * GRAVITY * h + ms * GRAVITY * hz  # weights above the mounts, tilting with the base
    kyy, kyr, krr = 4 * k, 4 * k * h, 4 * k * h**2 + 4 * k * B_HALF**2 - rock
    moment = -ms * GRAVITY * dy  # the weight moved by dy along +Y: moment about X
    det = kyy * krr - kyr**2
    y_hand, rx_hand = -kyr * moment / det, kyy * moment / det
    expected = np.array([0.0, y_hand, 0.0, rx_hand, 0.0, 0.0])
    for fidelity, integrator in (("lti", "exact"), ("ltv", "rk4"), ("nonlinear", "rk4")):
        r = simulate(b, fidelity, integrator, dt=1e-3, record=[0])
        assert r.status[0] == 0, r.message[0]
        end = np.concatenate([r.history["displacement"][0, -1], r.history["rotation"][0, -1]])
        if fidelity == "nonlinear":
            # its own static equilibrium: the hand solution plus a part second order in the rotation
            # (3e-4 rad: Z sinks by 1.3e-8 m), where the run ends (to the transient's 1e-9)
            np.testing.assert_allclose(r.final_displacement[0], expected, rtol=1e-6, atol=2e-8)
            np.testing.assert_allclose(end, r.final_displacement[0], atol=5e-9)
        else:
            np.testing.assert_allclose(r.final_displacement[0], expected, rtol=1e-9, atol=1e-15)
        # the transient has decayed to ~1e-9 by t = 2 s (measured: lti, ltv 1e-9; nonlinear 4e-8, its
        # finite rotation of 3e-4 rad adding a second-order part); 1e-6 is well inside the brief's 1e-3
        np.testing.assert_allclose(end[[1, 3]], expected[[1, 3]], rtol=1e-6)
        assert np.abs(end[[0, 2, 4, 5]]).max() < 1e-3 * abs(rx_hand)
        assert r.settled[0]
    assert rx_hand < 0  # the +Y end goes down
