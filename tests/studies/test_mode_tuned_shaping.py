"""A shaper tuned to one of the scene's own modes, and the move-time cost of shaping as an output.

The scene is one degree of freedom in effect: a granite block on four equal mounts in the plane of its
c.g., shaken by a stage that moves vertically through the c.g., so only heave is excited. With mounts of
vertical frequency ``f_v`` and damping ratio ``zeta`` (the load-based preset stiffness), the heave mode is
exactly ``f_v`` and ``zeta``; with explicit vertical stiffness ``k`` per mount it is
``sqrt(4 k / M) / 2 pi``, ``M`` the block's and the stage's mass.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from pydantic import ValidationError

from isolab.engine import simulate
from isolab.engine.results import OK, OUTPUTS
from isolab.engine.scene import SceneError
from isolab.studies.inputs.parameters import available_paths
from isolab.studies.inputs.scenes import build_batch
from isolab.studies.inputs.schema import Scene, error_messages
from isolab.studies.inputs.study import load_study, study_labels
from isolab.studies.questions.goals import goal_values
from isolab.studies.results.cases import case_table
from isolab.studies.results.dataset import to_dataset

F_V, ZETA = 5.0, 0.05
BLOCK = 2.0 * 2.0 * 0.5 * 2700.0  # kg
STAGE = 100.0  # kg
PERIODS = {"zv": 0.5, "zvd": 1.0, "ei": 1.0}
"""The shaper's duration in damped periods of its mode."""


def heave_scene(shaper: dict[str, Any] | None = None, **isolators: Any) -> dict[str, Any]:
    profile: dict[str, Any] = {
        "type": "trapezoid",
        "travel": "10 mm",
        "velocity": "0.1 m/s",
        "acceleration": "2 m/s^2",
        "start": "0.1 s",
    }
    if shaper is not None:
        profile["shaper"] = shaper
    return {
        "machine": {"block": {"size": [2.0, 2.0, 0.5], "density": 2700.0, "corner": [0, 0, 0]}},
        "isolators": {
            "preset": "air",
            "f_vertical": f"{F_V} Hz",
            "f_horizontal": "3 Hz",
            "zeta": ZETA,
            "layout": {"span_x": "1.6 m", "span_y": "1.6 m", "height": "0 m"},
            **isolators,
        },
        "stages": [
            {"name": "z", "mass": STAGE, "home": [1.0, 1.0, 0.25], "axis": [0, 0, 1], "profile": profile}
        ],
        "points": {"tool": [1.0, 1.0, 0.25]},
        "simulation": {"fidelity": "lti", "integrator": "exact", "dt": "1 ms", "duration": "3 s"},
    }


def _batch(shaper: dict[str, Any] | None = None, **isolators: Any):
    return build_batch([Scene.model_validate(heave_scene(shaper, **isolators))])


def _run(batch, tol: float):
    batch.point_settle_tol[:] = tol
    batch.settle_tol[:] = tol
    r = simulate(batch, "lti", "exact", dt=1e-3)
    assert r.status.tolist() == [OK] * batch.n_cases, r.message
    return r


def test_a_mode_tuned_zv_is_the_zv_tuned_by_hand_to_the_closed_form_mode() -> None:
    plain = _batch()
    r0 = _run(plain, 1e-9)
    heave = int(np.argmax(r0.mode_energy[0, :, 2]))
    # the scene's heave mode is the mounts' vertical frequency and damping (closed form)
    assert r0.natural_frequency[0, heave] == pytest.approx(F_V, rel=1e-12)
    assert r0.damping_ratio[0, heave] == pytest.approx(ZETA, rel=1e-12)
    by_hand = _batch({"type": "zv", "frequency": f"{F_V} Hz", "damping": ZETA})
    for mode in ("heave", "z", heave + 1):
        tuned = _batch({"type": "zv", "mode": mode})
        for name in ("prof_t", "prof_s", "prof_v", "prof_a", "prof_j"):
            np.testing.assert_allclose(getattr(tuned, name), getattr(by_hand, name), rtol=1e-12, atol=1e-15)
    # residual vibration: the unshaped move leaves the heave ringing; both shapers leave none, alike
    residual = float(np.max(r0.peak_point_displacement)) * 1e-3
    unshaped = _run(plain, residual)
    shaped = [_run(b, residual) for b in (by_hand, _batch({"type": "zv", "mode": "heave"}))]
    assert unshaped.point_settling_time[0, 0] > 1.0  # ln(1000) / (zeta w) = 4.4 s to decay by 1000
    for r in shaped:
        assert r.point_settling_time[0, 0] == 0.0
        assert r.settled[0]
    np.testing.assert_allclose(
        shaped[1].peak_point_displacement, shaped[0].peak_point_displacement, rtol=1e-9
    )


def test_a_study_of_the_mount_stiffness_retunes_the_shaper_and_reports_its_move_time() -> None:
    """Per case: the heave frequency of the stiffness, the shaper tuned to it, and the move time longer
    than the unshaped move's by half the damped period (ZV) or a whole one (ZVD, EI)."""
    stiffness = [2e5, 4e5, 8e5]  # N/m per mount
    kinds = ["zv", "zvd", "ei"]
    study = load_study(
        {
            "name": "mode-tuned",
            "scene": heave_scene({"type": "zv", "mode": "heave"}),
            "parameters": [
                {"path": "isolators.k.z", "values": [f"{k} N/m" for k in stiffness]},
                {"path": "stages.z.profile.shaper.type", "values": kinds},
            ],
            "design": {"type": "grid"},
        }
    )
    assert study.n_cases == 9
    batch = study.batch(np.arange(9))
    r = simulate(batch, "lti", "exact", dt=1e-3)
    assert (r.status == OK).all(), r.message
    plain = _run(_batch(), 1e-5).move_time[0]
    assert plain == pytest.approx(0.1 + 0.05 + 0.05 + 0.05)  # start, accelerate, cruise 5 mm, decelerate
    ds = to_dataset(r, study.design(), isolator_names=study_labels(study)[0], point_names=["tool"])
    for k in stiffness:
        f = np.sqrt(4 * k / (BLOCK + STAGE)) / (2 * np.pi)
        for kind in kinds:
            case = ds.sel(isolator_k_z=k, stage_z_shaper_type=kind)
            heave = int(np.argmax(case["mode_energy"].sel(dof="z").values))
            assert float(case["natural_frequency"][heave]) == pytest.approx(f, rel=1e-12)
            zeta = float(case["damping_ratio"][heave])
            assert zeta == pytest.approx(ZETA, rel=1e-9)
            damped_period = 1.0 / (f * np.sqrt(1.0 - zeta**2))
            cost = float(case["move_time"]) - plain
            assert cost == pytest.approx(PERIODS[kind] * damped_period, rel=1e-9)
            ready = float(case["move_time"]) + float(case["settling_time"])
            assert float(case["ready_time"]) == pytest.approx(ready, rel=1e-12)
            point = float(case["move_time"]) + float(case["point_settling_time"].sel(point="tool"))
            assert float(case["point_ready_time"].sel(point="tool")) == pytest.approx(point, rel=1e-12)
    assert ds["move_time"].attrs["units"] == OUTPUTS["move_time"].unit == "s"
    assert "shaper included" in ds["move_time"].attrs["long_name"]
    table = case_table(ds)
    assert {"move_time", "point_ready_time_tool"} <= set(table.default)
    # the time to ready as an objective: minimise tool settling plus move time, the move time bounded
    goals = load_study(
        {
            "name": "fastest-ready",
            "scene": heave_scene({"type": "zvd", "mode": "heave"}),
            "parameters": [{"path": "isolators.k.z", "range": {"start": "2e5 N/m", "stop": "8e5 N/m"}}],
            "design": {
                "type": "optimize",
                "objective": "minimize ready_time.tool",
                "constraints": ["move_time <= 600 ms"],
                "budget": 8,
                "population": 4,
            },
        }
    ).goals
    assert goals is not None
    F, G = goal_values(ds, goals)
    np.testing.assert_allclose(F[:, 0], ds["point_ready_time"].sel(point="tool").values.reshape(-1))
    np.testing.assert_allclose(G[:, 1], (ds["move_time"].values.reshape(-1) - 0.6) / 0.6, rtol=1e-12)


@pytest.mark.parametrize(
    ("shaper", "path", "words"),
    [
        ({"type": "zv", "mode": "bounce"}, "shaper.mode", "unknown mode 'bounce'"),
        ({"type": "zv", "mode": 7}, "shaper.mode", "modes 1 to 6"),
        ({"type": "zv", "mode": 0}, "shaper.mode", "out of range"),
        ({"type": "zv", "mode": True}, "shaper.mode", "mode number or name"),
        ({"type": "zv", "mode": "heave", "frequency": "5 Hz"}, "shaper.frequency", "not both"),
        ({"type": "zv", "mode": "heave", "damping": 0.1}, "shaper.damping", "mode's damping ratio"),
        ({"type": "zv"}, "shaper.frequency", "or the mode"),
    ],
)
def test_a_bad_mode_is_refused_naming_the_field(shaper: dict[str, Any], path: str, words: str) -> None:
    with pytest.raises(ValidationError) as err:
        Scene.model_validate(heave_scene(shaper))
    (message,) = error_messages(err.value)
    assert f"stages.0.profile.trapezoid.{path}: " in message and words in message


def test_a_mode_without_stiffness_or_frequency_to_vary_is_refused() -> None:
    # no horizontal stiffness: surge is a mechanism, there is nothing to tune to
    with pytest.raises(
        SceneError, match=r"stages\[0\]\.profile\.shaper\.mode: the surge mode has no stiffness"
    ):
        _batch({"type": "zv", "mode": "surge"}, k={"x": 0.0, "y": 0.0})
    # a mode-tuned shaper's frequency and damping are the mode's: a study cannot set them
    scene = Scene.model_validate(heave_scene({"type": "zv", "mode": "heave"}))
    assert "stages.z.profile.shaper.type" in available_paths(scene)
    assert "stages.z.profile.shaper.frequency" not in available_paths(scene)
    with pytest.raises(ValueError, match="stages.z.profile.shaper.frequency"):
        load_study(
            {
                "name": "bad",
                "scene": heave_scene({"type": "zv", "mode": "heave"}),
                "parameters": [{"path": "stages.z.profile.shaper.frequency", "values": ["4 Hz", "5 Hz"]}],
                "design": {"type": "grid"},
            }
        )
