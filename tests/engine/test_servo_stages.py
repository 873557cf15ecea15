"""Stages on a servo: the following error as extra linear states (``engine.linear_states.servo``), checked
against the closed-form second-order error, the prescribed motion it tends to, and the momentum of base
and stages; and relative points (tool to work) that read it."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from isolab.engine import simulate
from isolab.engine.scene import SceneError
from tests.engine.scenes import scene, y_stage
from tests.engine.test_flexible_base import flexible

G = 9.80665


def constant_y(mass: float, accel: float, home=(0.0, -1.5, 0.3)) -> dict:
    """A stage along +Y accelerating at a constant ``accel`` (m/s^2) from rest at t = 0."""
    return {
        "mass": mass,
        "home": home,
        "axis": (0.0, 1.0, 0.0),
        "pieces": np.array([[0.0], [0.0], [0.0], [accel], [0.0]]),
    }


def on_servo(b, freq, zeta, stage=0):
    """``b`` with stage ``stage`` on a servo of natural frequency ``freq`` (Hz) and damping ratio ``zeta``."""
    f = np.zeros((b.n_cases, b.n_stages))
    z = np.zeros((b.n_cases, b.n_stages))
    f[:, stage], z[:, stage] = freq, zeta
    return replace(b, stage_servo_frequency=f, stage_servo_damping=z)


def with_relative(b, tool_stage, work_point):
    """``b`` with one more point: relative, the tool on stage ``tool_stage`` (-1 the base, at point 0),
    the work at material point ``work_point`` of the base."""
    C, p = b.n_cases, b.n_points
    kind = np.zeros((C, p + 1), dtype=np.int8)
    kind[:, p] = 1
    tool = np.full((C, p + 1), -1, dtype=np.int64)
    tool[:, p] = tool_stage
    where = b.stage_home[:, tool_stage] if tool_stage >= 0 else b.points[:, 0]
    return replace(
        b,
        points=np.concatenate([b.points, where[:, None]], axis=1),
        point_settle_tol=None,
        base_mode_point=None,
        point_relative=kind,
        point_tool_stage=tool,
        point_work_stage=np.full((C, p + 1), -1, dtype=np.int64),
    )


def step_error(t, a, w, zeta):
    """The closed-form error of ``e'' + 2 zeta w e' + w^2 e = a`` from rest (underdamped), m."""
    wd = w * np.sqrt(1 - zeta**2)
    return a / w**2 * (1 - np.exp(-zeta * w * t) * (np.cos(wd * t) + zeta * w / wd * np.sin(wd * t)))


@pytest.mark.parametrize("integrator", ["exact", "rk4"])
def test_on_a_very_stiff_base_the_error_is_the_textbook_second_order_response(integrator):
    """A 500 kg stage pushed at 2 g on a 20 Hz, zeta 0.3 servo by a base of 10^7 kg on stiff mounts: the
    error rises as the closed-form step response to the steady ``a / w^2`` (621 um), its peak the
    overshoot ``exp(-zeta pi / sqrt(1 - zeta^2))``; a relative point from the stage to the base reads it."""
    a, f, zeta = 2 * G, 20.0, 0.3
    w = 2 * np.pi * f
    b = scene(mass=1e7, k=(1e12, 1e12, 2e12), c=(1e8, 1e8, 2e8), stages=[constant_y(500.0, a)], duration=0.6)
    b = with_relative(on_servo(b, f, zeta), 0, 0)
    r = simulate(b, fidelity="lti", integrator=integrator, dt=1e-4, record=[0])
    assert r.status[0] == 0
    steady = a / w**2
    overshoot = np.exp(-zeta * np.pi / np.sqrt(1 - zeta**2))
    assert r.peak_following_error[0] == pytest.approx(steady * (1 + overshoot), rel=2e-4)
    h = r.history
    t = h["time"][0]
    e = -h["point_displacement"][0, :, 1, 1]  # the relative point reads -e along Y
    assert np.abs(e - step_error(t, a, w, zeta)).max() < 2e-4 * steady
    assert e[-1] == pytest.approx(steady, rel=2e-4)
    assert r.peak_point_displacement[0, 1, 1] == pytest.approx(r.peak_following_error[0], rel=1e-12)
    assert r.peak_point_displacement[0, 1, [0, 2]] == pytest.approx([0.0, 0.0], abs=1e-15)


def test_as_the_bandwidth_grows_the_base_tends_to_the_prescribed_motion_as_one_over_its_square():
    """The article's 1,000 kg Y stage (2 g, 3 m) on servos of 25, 50, 100 and 200 Hz: the base's peak
    differs from the prescribed stage's by ``O(1 / f^2)`` (each doubling divides it by about 4)."""
    b = scene(stages=[y_stage()], duration=3.0)
    ideal = simulate(b, fidelity="lti", integrator="exact", dt=5e-4, record=[0])
    gaps = []
    for f in (25.0, 50.0, 100.0, 200.0):
        r = simulate(on_servo(b, f, 0.7), fidelity="lti", integrator="exact", dt=5e-4, record=[0])
        gap = np.abs(r.history["displacement"][0] - ideal.history["displacement"][0]).max()
        gaps.append(gap / np.abs(ideal.history["displacement"][0]).max())
    ratios = np.array(gaps[:-1]) / np.array(gaps[1:])
    assert gaps[-1] < 1e-3
    assert np.all((ratios > 3.0) & (ratios < 5.0)), (gaps, ratios)


def test_with_free_mounts_and_no_gravity_the_centre_of_mass_of_base_and_stages_stays_put():
    """Mounts of zero stiffness and damping, no gravity: no external force, so ``m_tot u + theta x sum m
    rho + m (r - e) n`` stays zero (the momentum, integrated) with the stage on a servo."""
    st = y_stage()
    b = scene(k=(0.0, 0.0, 0.0), c=(0.0, 0.0, 0.0), stages=[st], duration=2.5, g=0.0, gravity_stiffness=False)
    b = with_relative(on_servo(b, 30.0, 0.5), 0, 0)
    r = simulate(b, fidelity="lti", integrator="exact", dt=5e-4, record=[0])
    h = r.history
    t = h["time"][0]
    pieces = st["pieces"]
    k = np.clip(np.searchsorted(pieces[0], t, side="right") - 1, 0, None)
    tau = t - pieces[0, k]
    travel = pieces[1, k] + pieces[2, k] * tau + 0.5 * pieces[3, k] * tau**2
    e = -h["point_displacement"][0, :, 1, 1]
    m, mt = 1000.0, 11_000.0
    S = m * np.asarray(st["home"])
    com = mt * h["displacement"][0] + np.cross(h["rotation"][0], S) + m * (travel - e)[:, None] * [0, 1, 0]
    assert np.abs(com).max() < 1e-9 * m * 3.0
    assert np.abs(e).max() > 1e-5  # the error is there to see


def test_relative_points_read_zero_on_a_rigid_base_and_the_modal_difference_on_a_flexible_one():
    """Two points fixed on the base: on a rigid base with ideal stages their relative point reads zero at
    every level; on a base with an elastic mode it reads the difference of the mode's shape between them
    times its coordinate, which is the two points' difference less the rigid rotation of their offset."""
    pts = [(1.0, 1.5, 0.2), (-1.0, -1.5, 0.0)]
    b = scene(stages=[y_stage()], points=pts, duration=2.0)
    b = with_relative(b, -1, 1)  # tool at point 0, work at point 1
    for fidelity, integrator in (("lti", "exact"), ("ltv", "rk4"), ("nonlinear", "rk4")):
        r = simulate(b, fidelity=fidelity, integrator=integrator, dt=1e-3, record=[0])
        assert r.status[0] == 0
        assert np.abs(r.history["point_displacement"][0][:, 2]).max() == 0.0
        assert r.peak_point_displacement[0, 2] == pytest.approx([0.0, 0.0, 0.0], abs=0.0)
    shapes = np.array([0.8, -0.5])  # the mode's vertical shape at points 0 and 1
    fb = flexible(
        b,
        60.0,
        0.02,
        2500.0,
        np.array([1.0, 1.0, -1.0, -1.0]),  # pitch-like at the mounts: the Y stage drives it
        stage=[0.3],
        point=np.array([shapes[0], shapes[1], shapes[0] - shapes[1]]),
    )
    for fidelity, integrator in (("lti", "exact"), ("ltv", "rk4")):
        r = simulate(fb, fidelity=fidelity, integrator=integrator, dt=1e-3, record=[0])
        h = r.history
        rigid_turn = np.cross(h["rotation"][0], np.subtract(*pts))
        expected = h["point_displacement"][0][:, 0] - h["point_displacement"][0][:, 1] - rigid_turn
        rel = h["point_displacement"][0][:, 2]
        assert np.abs(rel - expected).max() < 1e-12 * np.abs(h["point_displacement"][0]).max()
        assert np.abs(rel[:, 2]).max() > 1e-8  # the mode is there to see


def test_where_a_servo_is_not_modelled_the_scene_is_refused_naming_the_input():
    b = on_servo(scene(stages=[y_stage()]), 50.0, 0.7)
    for fidelity, integrator in (("ltv", "rk4"), ("nonlinear", "rk4"), ("lti", "euler")):
        with pytest.raises(SceneError, match="stage_servo_frequency") as err:
            simulate(b, fidelity=fidelity, integrator=integrator)
        assert ("lti level" if integrator == "rk4" else "rk4 or exact") in str(err.value)
    with pytest.raises(SceneError, match="stage_servo_frequency.*not negative"):
        simulate(on_servo(scene(stages=[y_stage()]), -5.0, 0.7), fidelity="lti", integrator="exact")
