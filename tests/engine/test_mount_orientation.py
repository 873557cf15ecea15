"""Mounts on their own axes (``SceneBatch.iso_frame``): the floor-frame tensor ``Q diag(k) Q^T``, the
decoupling of an inclined symmetric layout, and the time-domain forces at every level."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from isolab.engine import model, simulate
from isolab.engine.modal import modes
from isolab.engine.scene import SceneError
from isolab.engine.validation import validate
from tests.engine.scenes import scene, trapezoid_pieces


def rotation_y(angle: float) -> np.ndarray:
    """Rotation by ``angle`` (rad) about Y: columns are the rotated x, y, z."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def inclined(batch, phi: float, kq: float, kp: float, cq: float = 0.0, cp: float = 0.0):
    """``batch``'s four mounts inclined by ``phi`` about Y, each toward the c.g. in the X-Z plane (the
    mount at +x turned by -phi, at -x by +phi), stiffness ``kq`` across and ``kp`` along its own z."""
    x = batch.iso_pos[0, :, 0]
    Q = np.stack([rotation_y(-phi if xj > 0 else phi) for xj in x])[None]
    k = np.broadcast_to([kq, kq, kp], batch.iso_k.shape).copy()
    c = np.broadcast_to([cq, cq, cp], batch.iso_c.shape).copy()
    return replace(batch, iso_frame=Q, iso_k=k, iso_c=c)


def test_tensor_is_the_rotated_diagonal() -> None:
    b = inclined(scene(height=0.3), 0.4, 2e5, 1e6)
    T = model.isolator_tensor(b, b.iso_k)
    s, c = np.sin(0.4), np.cos(0.4)
    # mount 0 sits at +x: turned by -phi, its own z points toward -x (toward the c.g.)
    assert T[0, 0, 0, 0] == pytest.approx(2e5 * c * c + 1e6 * s * s)
    assert T[0, 0, 2, 2] == pytest.approx(2e5 * s * s + 1e6 * c * c)
    assert T[0, 0, 0, 2] == pytest.approx(-(1e6 - 2e5) * s * c)
    assert T[0, 1, 0, 2] == pytest.approx(+(1e6 - 2e5) * s * c)  # the mirrored mount at -x
    assert np.allclose(T, np.swapaxes(T, -1, -2))


def test_inclined_layout_focused_on_the_cg_decouples_x_and_rocking() -> None:
    """Mounts at (+-a, +-b, -h) inclined toward the c.g. by phi: X and rotation about Y decouple when
    ``kxz a = kxx h``, i.e. ``h = a (kp - kq) sin phi cos phi / (kp sin^2 phi + kq cos^2 phi)`` (the
    mounts' elastic axes meet at the c.g.). Then ``f_x = sqrt(4 kxx / M) / 2 pi`` and
    ``f_ry = sqrt(4 (kxx h^2 - 2 kxz a h + kzz a^2) / Iyy) / 2 pi`` exactly."""
    kq, kp, phi, a = 2e5, 1.2e6, np.radians(30.0), 1.1
    kxx = kp * np.sin(phi) ** 2 + kq * np.cos(phi) ** 2
    kzz = kp * np.cos(phi) ** 2 + kq * np.sin(phi) ** 2
    kxz = (kp - kq) * np.sin(phi) * np.cos(phi)
    h = a * kxz / kxx
    b = inclined(scene(height=h, gravity_stiffness=False), phi, kq, kp)
    validate(b)
    K, M = model.stiffness_matrix(b), model.mass_matrix(b)
    assert abs(K[0, 0, 4]) < 1e-9 * K[0, 0, 0]  # x and rotation about Y: decoupled
    md = modes(M, K, model.damping_matrix(b))
    f = np.sort(md.frequency[0])
    f_x = np.sqrt(4 * kxx / b.mass[0]) / (2 * np.pi)
    f_z = np.sqrt(4 * kzz / b.mass[0]) / (2 * np.pi)
    f_ry = np.sqrt(4 * (kxx * h * h - 2 * kxz * a * h + kzz * a * a) / b.inertia[0, 1, 1]) / (2 * np.pi)
    for expected in (f_x, f_z, f_ry):
        assert np.min(np.abs(f - expected)) < 1e-9 * expected
    # the same mounts upright at that height couple X with rocking: no mode at f_x then
    upright = inclined(scene(height=h, gravity_stiffness=False), 0.0, kxx, kzz)
    assert abs(model.stiffness_matrix(upright)[0, 0, 4]) > 0.1 * K[0, 0, 0] * h
    # and inclined at another height, X and rocking couple again
    off = inclined(scene(height=0.5 * h, gravity_stiffness=False), phi, kq, kp)
    assert abs(model.stiffness_matrix(off)[0, 0, 4]) > 0.1 * K[0, 0, 0] * h


def test_identity_frame_is_bit_identical_and_a_quarter_turn_swaps_axes() -> None:
    stage = {
        "mass": 500.0,
        "home": (0.3, -1.0, 0.4),
        "axis": (0.0, 1.0, 0.0),
        "pieces": trapezoid_pieces(1.5, 1.0, 10.0, start=0.05),
    }
    b = scene(k=(1e6, 3e6, 2e6), c=(1e4, 2e4, 3e4), stages=[stage], duration=0.6, height=0.2)
    assert not b.has_orientation
    # a quarter turn about Z with kx, ky swapped is the same mount
    Qz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    turned = replace(
        b,
        iso_frame=np.broadcast_to(Qz, b.iso_frame.shape).copy(),
        iso_k=b.iso_k[..., [1, 0, 2]].copy(),
        iso_c=b.iso_c[..., [1, 0, 2]].copy(),
    )
    assert turned.has_orientation
    for fidelity, integrator in (("lti", "exact"), ("ltv", "rk4"), ("nonlinear", "rk4"), ("ltv", "euler")):
        r0 = simulate(b, fidelity=fidelity, integrator=integrator)
        r1 = simulate(turned, fidelity=fidelity, integrator=integrator)
        for name in ("peak_displacement", "peak_rotation", "final_displacement"):
            x0, x1 = getattr(r0, name), getattr(r1, name)
            assert np.allclose(x0, x1, rtol=1e-9, atol=1e-15), (fidelity, integrator, name)
        # force and load peaks: at the output times for the turned mounts, between them too for the
        # upright ones
        for name in ("peak_isolator_force", "min_isolator_load", "max_isolator_load"):
            assert np.allclose(getattr(r0, name), getattr(r1, name), rtol=2e-3), (fidelity, integrator, name)


def test_inclined_mounts_static_offset_and_levels_agree() -> None:
    """A stage parked off-centre on inclined mounts: every level settles on ``K q = moment of the
    weight`` (the linear model's static solution with the full tensors), and the exact LTI run matches
    RK4 at a small step."""
    stage = {
        "mass": 400.0,
        "home": (0.0, 0.0, 0.3),
        "axis": (1.0, 0.0, 0.0),
        "pieces": trapezoid_pieces(0.8, 1.0, 5.0),
    }
    b = inclined(scene(height=0.4, stages=[stage], duration=4.0), np.radians(25.0), 3e5, 1.5e6, 6e3, 3e4)
    validate(b)
    exact = simulate(b, fidelity="lti", integrator="exact")
    rk4 = simulate(b, fidelity="lti", integrator="rk4", dt=2e-4)
    assert np.allclose(exact.peak_displacement, rk4.peak_displacement, rtol=1e-6)
    K = model.stiffness_matrix(b)[0]
    f = np.zeros(6)
    f[3:] = np.cross([0.8, 0.0, 0.0], [0.0, 0.0, -400.0 * b.g])
    q = np.linalg.solve(K, f)
    assert np.allclose(exact.final_displacement[0], q, rtol=1e-9, atol=1e-14)
    nl = simulate(b, fidelity="nonlinear", integrator="rk4").peak_displacement
    ltv = simulate(b, fidelity="ltv", integrator="rk4").peak_displacement
    assert np.allclose(nl, ltv, rtol=1e-3, atol=1e-3 * ltv.max())  # small motions: the levels agree


def test_frames_that_are_not_rotations_or_meet_floor_motion_are_refused() -> None:
    b = scene()
    skew = b.iso_frame.copy()
    skew[0, 1] *= 2.0
    with pytest.raises(SceneError, match="iso_frame"):
        validate(replace(b, iso_frame=skew))
    mirror = b.iso_frame.copy()
    mirror[0, 0, :, 0] *= -1.0
    with pytest.raises(SceneError, match="rotation"):
        validate(replace(b, iso_frame=mirror))
    shaken = inclined(scene(floor_amp=(0.0, 0.0, 1e-6), floor_freq=(0.0, 0.0, 10.0)), 0.3, 1e5, 1e6)
    with pytest.raises(SceneError, match="floor motion"):
        validate(shaken)
