"""Stages on a servo and relative points from the scene file (``stages[].servo``, ``points.<name>.relative``):
the arrays they give, a study varying the bandwidth, and bad input named by its field."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from isolab.engine import simulate
from isolab.engine.linear_states.servo import carried_mass
from isolab.studies.inputs.parameters import available_paths, resolve
from isolab.studies.inputs.scenes import build_batch
from isolab.studies.inputs.study import load_scene, scene_batch

ARTICLE = "studies/examples/article-scriber.yaml"


def scriber(servo: dict | None = None, points: dict | None = None) -> dict:
    """The article's scriber with a servo on its Y stage and extra points."""
    data = yaml.safe_load(open(ARTICLE))
    if servo is not None:
        next(s for s in data["stages"] if s["name"] == "y")["servo"] = servo
    data["points"].update(points or {})
    data.setdefault("simulation", {}).update({"fidelity": "lti", "integrator": "exact"})
    return data


def test_a_servo_by_stiffness_is_the_same_as_by_bandwidth_of_the_mass_it_moves():
    """The Y drive moves Y and the X stage on it: ``w = sqrt(k / M)``, ``zeta = c / (2 sqrt(k M))`` with
    ``M = m_y + m_x``."""
    by_bw, _ = scene_batch(load_scene(scriber({"bandwidth": "40 Hz", "damping_ratio": 0.5})))
    M = carried_mass(by_bw)[0, 0]
    assert M == pytest.approx(by_bw.stage_mass[0].sum())
    w = 2 * np.pi * 40.0
    k, c = M * w**2, 2 * 0.5 * w * M
    by_k, _ = scene_batch(load_scene(scriber({"stiffness": f"{k} N/m", "damping": f"{c} N*s/m"})))
    assert by_k.stage_servo_frequency[0] == pytest.approx(by_bw.stage_servo_frequency[0], rel=1e-12)
    assert by_k.stage_servo_damping[0] == pytest.approx(by_bw.stage_servo_damping[0], rel=1e-12)
    assert by_bw.stage_servo_frequency[0, 1] == 0.0  # the X stage follows its profile exactly


def test_a_study_varies_the_bandwidth_and_the_error_falls_as_its_square():
    scene = load_scene(
        scriber({"bandwidth": "20 Hz"}, {"tool_to_work": {"relative": {"tool": "x", "work": "camera"}}})
    )
    path = "stages.y.servo.bandwidth"
    assert path in available_paths(scene)
    assert resolve(path, scene).dimension == "frequency"
    batch = build_batch([scene], {path: np.array([20.0, 40.0])})
    assert batch.stage_servo_frequency[:, 0] == pytest.approx([20.0, 40.0])
    r = simulate(batch, fidelity="lti", integrator="exact", dt=5e-4)
    assert (r.status == 0).all(), r.message
    ratio = r.peak_following_error[0] / r.peak_following_error[1]
    assert ratio == pytest.approx(4.0, rel=0.1)
    # the tool rides on X, which rides on Y: its relative point reads the Y error along Y
    tool = list(scene.points).index("tool_to_work")
    assert r.peak_point_displacement[:, tool, 1] == pytest.approx(r.peak_following_error, rel=1e-9)


def test_bad_servo_and_relative_point_input_is_named():
    with pytest.raises(Exception, match="bandwidth"):
        load_scene(scriber({"bandwidth": "-5 Hz"}))
    with pytest.raises(Exception, match="servo: give bandwidth"):
        load_scene(scriber({"bandwidth": "5 Hz", "stiffness": "1e6 N/m"}))
    with pytest.raises(Exception, match=r"points.tw.relative.work: no stage or material point named 'table'"):
        load_scene(scriber(points={"tw": {"relative": {"tool": "x", "work": "table"}}}))
    scene = load_scene(scriber({"bandwidth": "20 Hz"}))
    with pytest.raises(ValueError, match="stages.z.servo.bandwidth"):
        resolve("stages.z.servo.bandwidth", scene)
    with pytest.raises(ValueError, match="stages.x.servo.bandwidth"):
        resolve("stages.x.servo.bandwidth", scene)  # X has no servo
