"""The nonlinear level's preload: vertical in the floor frame (default) or turning with the base.

At small amplitude the nonlinear equations' stiffness is read off the engine's own accelerations by
central differences about the rest state, and compared with the closed forms derived below.
"""

from __future__ import annotations

import numpy as np
import pytest
from scenes import box_inertia, mount, scene, y_stage

from isolab.engine import GRAVITY, model, simulate
from isolab.engine.kernels.dynamics import accel
from isolab.engine.kernels.params import NONLINEAR
from isolab.engine.kernels.structs import kernel_struct
from isolab.engine.scene import SceneError

M = 10_000.0
SIZE = (2.6, 4.2, 0.34)
SPAN = (2.2, 3.6)
H = 0.4  # the c.g. sits this far above the mounts, m


def _soft(preload_with_base: bool, stages=None):
    """Four 1 Hz mounts (distinct horizontal stiffness, so no two modes share a frequency) 0.4 m below
    the c.g. of a 10 t base."""
    kz, _ = mount(M / 4, 1.0, 0.0)
    b = scene(mass=M, size=SIZE, span=SPAN, height=H, k=(0.8 * kz, 1.2 * kz, kz), c=(0, 0, 0), stages=stages)
    b.preload_with_base = preload_with_base
    return b


def _small_amplitude_stiffness(b) -> np.ndarray:
    """``-d(acc)/d(u, phi)`` (6, 6) of the nonlinear level at rest (``phi`` the rotation vector), by
    central differences of the engine's accelerations: ``M^-1 K`` of its small-amplitude motion."""
    P, W = model.params(b), model.work(b)
    KP, KW = kernel_struct(P), kernel_struct(W)
    idx = np.full(b.n_stages, -1, dtype=np.int64)
    eps = 1e-7
    J = np.zeros((6, 6))
    for k in range(6):
        acc = []
        for s in (1.0, -1.0):
            x = np.zeros(13)
            x[3] = 1.0
            if k < 3:
                x[k] = s * eps
            else:
                x[3] = np.cos(eps / 2)
                x[4 + k - 3] = s * np.sin(eps / 2)
            assert accel(KP, 0, NONLINEAR, 0.0, x, idx, KW)
            acc.append(np.array(W.acc))
        J[:, k] = (acc[0] - acc[1]) / (2 * eps)
    return -J


def _pair(k11, k12, k21, k22, m1, m2) -> np.ndarray:
    """Roots w^2 of det([[k11 - w^2 m1, k12], [k21, k22 - w^2 m2]]) = 0, ascending."""
    p = k11 * m2 + k22 * m1
    q = k11 * k22 - k12 * k21
    disc = np.sqrt(p * p - 4 * m1 * m2 * q)
    return np.array([(p - disc) / (2 * m1 * m2), (p + disc) / (2 * m1 * m2)])


def _closed_form(preload_with_base: bool) -> np.ndarray:
    """The six w^2 (ascending) of the base at small amplitude.

    Mounts at d_j = (+-a, +-b, -h), stiffness kx, ky, kz each, preload W/4 each (W = M g); rotation
    theta. Y with pitch (rotation about X): the deflection is y + h theta, so the Y springs give
    F_y = -4 ky (y + h theta) and the moment -4 ky h (y + h theta); the Z springs -4 kz b^2 theta.

    * floor (preload vertical in the floor frame): the mount point moves by theta x d, and the moment of
      the vertical preload about the c.g. becomes (theta x d) x (0, 0, W/4), summing to + W h theta: a
      rocking stiffness -W h. K = [[4 ky, 4 ky h], [4 ky h, 4 ky h^2 + 4 kz b^2 - W h]], symmetric.
    * base (preload (0, 0, W/4) fixed in the base): its moment about the c.g. in the base is d x (0, 0,
      W/4), the same at every angle (no -W h), but its resultant turns with the base, R (0, 0, W) =
      W (theta_y, -theta_x, 1): a force -W theta along Y. K = [[4 ky, 4 ky h + W], [4 ky h,
      4 ky h^2 + 4 kz b^2]], not symmetric (a follower force).

    Both have the same determinant 4 ky (4 kz b^2 - W h): the static tipping limit is the same, only the
    frequencies move. X with roll (rotation about Y) alike with kx, a and the signs of the arm: F_x =
    -4 kx (x - h theta_y) (- W theta_y... + W theta_y with the base's preload). Heave 4 kz / M and yaw
    4 (kx b^2 + ky a^2) / Izz do not see the preload to first order.
    """
    kz, _ = mount(M / 4, 1.0, 0.0)
    kx, ky = 0.8 * kz, 1.2 * kz
    a, b = SPAN[0] / 2, SPAN[1] / 2
    ixx, iyy, izz = np.diag(box_inertia(M, *SIZE))
    W, h = M * GRAVITY, H
    if preload_with_base:
        y_rx = _pair(4 * ky, 4 * ky * h + W, 4 * ky * h, 4 * ky * h**2 + 4 * kz * b**2, M, ixx)
        x_ry = _pair(4 * kx, -4 * kx * h - W, -4 * kx * h, 4 * kx * h**2 + 4 * kz * a**2, M, iyy)
    else:
        y_rx = _pair(4 * ky, 4 * ky * h, 4 * ky * h, 4 * ky * h**2 + 4 * kz * b**2 - W * h, M, ixx)
        x_ry = _pair(4 * kx, -4 * kx * h, -4 * kx * h, 4 * kx * h**2 + 4 * kz * a**2 - W * h, M, iyy)
    return np.sort(np.concatenate([y_rx, x_ry, [4 * kz / M, 4 * (kx * b**2 + ky * a**2) / izz]]))


@pytest.mark.parametrize("preload_with_base", [False, True])
def test_small_amplitude_frequencies_match_the_closed_form(preload_with_base: bool) -> None:
    w2 = np.sort(np.linalg.eigvals(_small_amplitude_stiffness(_soft(preload_with_base))).real)
    # central differences at 1e-7: truncation ~1e-14, rounding ~1e-9 of the stiffness
    np.testing.assert_allclose(w2, _closed_form(preload_with_base), rtol=1e-6)


def test_base_preload_changes_the_rocking_frequency_by_the_closed_form_amount() -> None:
    floor = np.sqrt(np.sort(np.linalg.eigvals(_small_amplitude_stiffness(_soft(False))).real))
    base = np.sqrt(np.sort(np.linalg.eigvals(_small_amplitude_stiffness(_soft(True))).real))
    cf_floor, cf_base = np.sqrt(_closed_form(False)), np.sqrt(_closed_form(True))
    # the pitch-dominated mode: the higher root of the Y-pitch pair (the fastest mode here)
    assert base[-1] / floor[-1] == pytest.approx(cf_base[-1] / cf_floor[-1], rel=1e-6)
    # on 1 Hz mounts the preload's -W h is a few percent of the rocking stiffness: measurable
    assert base[-1] / floor[-1] - 1 > 0.005


def test_floor_preload_is_the_default_and_unchanged() -> None:
    stage = [y_stage(home=(0.2, -1.5, 0.3))]
    default = scene(mass=M, height=H, stages=stage)
    explicit = scene(mass=M, height=H, stages=stage)
    explicit.preload_with_base = False
    assert default.preload_with_base is False
    a = simulate(default, "nonlinear", "rk4", dt=1e-3)
    b = simulate(explicit, "nonlinear", "rk4", dt=1e-3)
    for name in ("peak_displacement", "peak_rotation", "peak_point_displacement", "peak_isolator_force"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    # and the base's preload does change a nonlinear run
    explicit.preload_with_base = True
    c = simulate(explicit, "nonlinear", "rk4", dt=1e-3)
    assert not np.array_equal(a.peak_rotation, c.peak_rotation)


def _balanced(stages=None):
    b = _soft(False, stages)
    b.preload_balanced = True
    return b


def test_balanced_preload_has_no_rocking_stiffness_from_preload_and_weight() -> None:
    """``preload_balanced``: preload and weights cancel in every attitude, so the Y-pitch pair is
    [[4 ky, 4 ky h], [4 ky h, 4 ky h^2 + 4 kz b^2]] (no -W h, symmetric): the linear stiffness without the
    gravity term."""
    kz, _ = mount(M / 4, 1.0, 0.0)
    kx, ky = 0.8 * kz, 1.2 * kz
    a, b = SPAN[0] / 2, SPAN[1] / 2
    ixx, iyy, izz = np.diag(box_inertia(M, *SIZE))
    y_rx = _pair(4 * ky, 4 * ky * H, 4 * ky * H, 4 * ky * H**2 + 4 * kz * b**2, M, ixx)
    x_ry = _pair(4 * kx, -4 * kx * H, -4 * kx * H, 4 * kx * H**2 + 4 * kz * a**2, M, iyy)
    closed = np.sort(np.concatenate([y_rx, x_ry, [4 * kz / M, 4 * (kx * b**2 + ky * a**2) / izz]]))
    w2 = np.sort(np.linalg.eigvals(_small_amplitude_stiffness(_balanced())).real)
    np.testing.assert_allclose(w2, closed, rtol=1e-6)
    # and the rocking mode is stiffer than with the vertical preload (-W h gone)
    assert w2[-1] > np.sort(_closed_form(False))[-1] * 1.01


def test_balanced_and_base_preload_together_are_refused() -> None:
    b = _balanced()
    b.preload_with_base = True
    with pytest.raises(SceneError, match="preload_balanced"):
        simulate(b, "nonlinear", "rk4", dt=1e-3)


def test_balanced_preload_follows_the_linear_model_without_gravity_stiffness() -> None:
    """A 1 t stage moving 3 m on 1 Hz mounts: with the balanced preload the nonlinear level's peaks are
    those of the ltv level without the gravity rocking term (to the second-order terms), and not those of
    the default vertical preload."""
    stage = [y_stage(home=(0.2, -1.5, 0.3))]
    bal = simulate(_balanced(stage), "nonlinear", "rk4", dt=1e-3)
    floor = simulate(_soft(False, stage), "nonlinear", "rk4", dt=1e-3)
    lin = _soft(False, stage)
    lin.gravity_stiffness = False
    ltv = simulate(lin, "ltv", "rk4", dt=1e-3)
    assert bal.status[0] == 0
    pitch_bal, pitch_floor, pitch_ltv = (
        bal.peak_rotation[0, 0],
        floor.peak_rotation[0, 0],
        ltv.peak_rotation[0, 0],
    )
    assert pitch_bal == pytest.approx(pitch_ltv, rel=0.02)
    assert abs(pitch_floor / pitch_bal - 1) > 0.03
