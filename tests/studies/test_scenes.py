"""Scenes to engine batches: machine, mounts, preset stiffness from load share, profiles, floor, studies."""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from isolab.engine import profiles
from isolab.engine.model import preload
from isolab.engine.scene import SceneError
from isolab.studies.inputs.scenes import build_batch, slowest_decay_time
from isolab.studies.inputs.schema import Scene, Simulation
from isolab.studies.inputs.study import Study, load_study, study_from_json, validate_study

EXAMPLES = Path(__file__).resolve().parents[2] / "studies" / "examples"
G = 9.80665


def scriber() -> dict:
    return yaml.safe_load((EXAMPLES / "article-scriber.yaml").read_text())


def symmetric(preset: str = "air", stage_y: float = 1.0, **iso) -> dict:
    """A 2 t block with mounts in the c.g. plane and one stage above the c.g."""
    return {
        "machine": {"block": {"size": [1.0, 2.0, 0.4], "density": 2500.0}},  # c.g. (0.5, 1.0, 0.2)
        "isolators": {"preset": preset, "layout": {"span_x": 0.8, "span_y": 1.6, "height": 0.0}, **iso},
        "stages": [
            {
                "name": "y",
                "mass": 300.0,
                "home": [0.5, stage_y, 0.5],
                "axis": [0, 1, 0],
                "profile": {"type": "trapezoid", "travel": 0.5, "velocity": 1.0, "acceleration": 5.0},
            },
        ],
    }


def test_article_scene_batch_shapes_and_values():
    scene = Scene.model_validate(scriber())
    b = build_batch([scene])
    assert (b.n_cases, b.n_isolators, b.n_stages, b.n_points) == (1, 4, 2, 2)
    mass = 2700 * 2.6 * 4.2 * 0.34
    assert b.mass[0] == pytest.approx(mass)
    np.testing.assert_allclose(b.cg[0], [1.3, 2.1, 0.17])
    np.testing.assert_allclose(
        np.diag(b.inertia[0]), mass / 12 * np.array([4.2**2 + 0.34**2, 2.6**2 + 0.34**2, 2.6**2 + 4.2**2])
    )
    np.testing.assert_allclose(
        b.iso_pos[0], [[0.2, 0.3, -0.33], [2.4, 0.3, -0.33], [2.4, 3.9, -0.33], [0.2, 3.9, -0.33]], atol=1e-12
    )
    np.testing.assert_allclose(b.stage_mass[0], [1000.0, 100.0])
    np.testing.assert_allclose(b.stage_home[0], [[1.3, 0.6, 0.47], [1.15, 0.6, 0.6]])
    np.testing.assert_allclose(b.stage_axis[0], [[0, 1, 0], [1, 0, 0]])
    assert b.stage_parent.tolist() == [-1, 0]
    np.testing.assert_allclose(b.points[0], [[1.15, 0.6, 0.6], [1.3, 3.6, 0.9]])
    assert not b.iso_skyhook.any() and not b.has_floor_motion
    # the Y stage parked 1.5 m behind the c.g. loads the rear mounts (y = 0.3) more
    assert b.iso_k[0, 0, 2] > b.iso_k[0, 3, 2]
    # profiles: the engine's own builders with the scene's numbers
    y = profiles.scan(3.0, 2.0, 2 * G, dwell=0.2, repeats=1)
    x = profiles.trapezoid(0.3, 1.0, G, start=1.65)
    ref = profiles.stack([y, x])
    for got, want in zip((b.prof_t, b.prof_s, b.prof_v, b.prof_a, b.prof_j), ref, strict=True):
        np.testing.assert_array_equal(got, want)
    # duration auto: last move end (out 1.602 s, dwell, back 1.602 s, dwell) + 9.2 time constants of the
    # slowest-decaying mode (the 3.5 Hz, 10 % heave: 1 / (0.1 * 2 pi 3.5) = 0.455 s), more than 3 s
    end = 2 * (3.0 / 2.0 + 2.0 / (2 * G)) + 2 * 0.2
    tau = slowest_decay_time(b)[0]
    assert tau == pytest.approx(1 / (0.1 * 2 * math.pi * 3.5), rel=0.05)
    assert b.duration[0] == pytest.approx(end + 9.2 * tau)
    assert b.settle_tol[0] == 10e-6 and b.gravity_stiffness and b.g == G


@pytest.mark.parametrize("preset", ["active", "air", "elastomer"])
def test_preset_gives_the_vertical_and_horizontal_natural_frequency(preset):
    for stage_y in (1.0, 1.5):  # stage above the c.g., then off-centre: loads differ, frequency does not
        b = build_batch([Scene.model_validate(symmetric(preset, stage_y))])
        m_total = b.mass[0] + b.stage_mass[0].sum()
        fz = math.sqrt(b.iso_k[0, :, 2].sum() / m_total) / (2 * math.pi)
        fx = math.sqrt(b.iso_k[0, :, 0].sum() / m_total) / (2 * math.pi)
        from isolab.studies.inputs.isolators import PRESETS

        assert fz == pytest.approx(PRESETS[preset].f_vertical, rel=1e-12)
        assert fx == pytest.approx(PRESETS[preset].f_horizontal, rel=1e-12)
        assert b.iso_skyhook[0].tolist() == [PRESETS[preset].skyhook] * 4
        load = b.iso_k[0, :, 2] / (2 * math.pi * PRESETS[preset].f_vertical) ** 2 * G
        np.testing.assert_allclose(
            b.iso_c[0, :, 2], 2 * PRESETS[preset].zeta * np.sqrt(b.iso_k[0, :, 2] * load / G)
        )
        if stage_y == 1.0:
            np.testing.assert_allclose(load, m_total * G / 4, rtol=1e-12)  # symmetric: a quarter each


def test_preset_loads_match_the_engine_preload():
    b = build_batch([Scene.model_validate(scriber())])
    k = b.iso_k[0, :, 2]
    load = k / (2 * math.pi * 3.5) ** 2 * G  # the example's air mounts: 3.5 Hz vertical
    np.testing.assert_allclose(preload(b)[0], load, rtol=1e-9)
    assert load.sum() == pytest.approx((b.mass[0] + b.stage_mass[0].sum()) * G, rel=1e-12)


def test_explicit_values_win_over_presets():
    d = symmetric("air", k={"horizontal": "2e5 N/m"}, c={"z": 3000.0}, zeta="20 %")
    b = build_batch([Scene.model_validate(d)])
    np.testing.assert_allclose(b.iso_k[0, :, :2], 2e5)
    m_total = b.mass[0] + b.stage_mass[0].sum()
    np.testing.assert_allclose(b.iso_k[0, :, 2], m_total / 4 * (2 * math.pi * 3.0) ** 2)
    np.testing.assert_allclose(b.iso_c[0, :, 2], 3000.0)
    # horizontal damping from zeta with the explicit stiffness and each mount's load
    np.testing.assert_allclose(b.iso_c[0, :, 0], 2 * 0.2 * np.sqrt(2e5 * m_total / 4))


def test_listed_mounts_own_values_and_preset():
    d = symmetric("air", f_vertical="4 Hz")
    pos = [[0.1, 0.2, 0.2], [0.9, 0.2, 0.2], [0.9, 1.8, 0.2], [0.1, 1.8, 0.2]]
    d["isolators"] = {
        "preset": "air",
        "f_vertical": "4 Hz",
        "skyhook": True,
        "list": [
            {"position": pos[0]},
            {"position": pos[1], "preset": "elastomer"},
            {"position": pos[2], "f_horizontal": "2 Hz", "skyhook": False},
            {"position": pos[3], "k": [1e5, 2e5, 3e5], "c": [10, 20, 30]},
        ],
    }
    b = build_batch([Scene.model_validate(d)])
    m_total = b.mass[0] + b.stage_mass[0].sum()
    load = m_total * G / 4  # stage at the c.g. line: symmetric
    w = 2 * math.pi
    np.testing.assert_allclose(b.iso_k[0, 0], load / G * w**2 * np.array([9.0, 9.0, 16.0]))  # group override
    np.testing.assert_allclose(b.iso_k[0, 1], load / G * w**2 * np.array([100.0, 100.0, 100.0]))  # own preset
    np.testing.assert_allclose(b.iso_k[0, 2], load / G * w**2 * np.array([4.0, 4.0, 16.0]))
    np.testing.assert_allclose(b.iso_k[0, 3], [1e5, 2e5, 3e5])
    np.testing.assert_allclose(b.iso_c[0, 3], [10, 20, 30])
    np.testing.assert_allclose(b.iso_c[0, 1], 2 * 0.05 * np.sqrt(b.iso_k[0, 1] * load / G))
    assert b.iso_skyhook[0].tolist() == [True, False, False, True]
    np.testing.assert_allclose(b.iso_pos[0], pos)


def test_floor_motion_and_simulation_fields():
    d = symmetric()
    d["floor"] = {
        "sine": {
            "amplitude": ["10 um", 0, "5 um"],
            "frequency": ["8 Hz", 0, "12 Hz"],
            "phase": [0, 0, "90 deg"],
        }
    }
    d["simulation"] = {"duration": "2.5 s", "settle_tolerance": "5 um", "gravity_stiffness": False}
    b = build_batch([Scene.model_validate(d)])
    np.testing.assert_allclose(b.floor_amp[0], [10e-6, 0, 5e-6])
    np.testing.assert_allclose(b.floor_freq[0], [8, 0, 12])
    np.testing.assert_allclose(b.floor_phase[0], [0, 0, math.pi / 2])
    assert b.duration[0] == 2.5 and b.settle_tol[0] == pytest.approx(5e-6) and not b.gravity_stiffness
    d["floor"] = {"recorded": {"dt": "2 ms", "displacement": {"z": [0, 1e-6, 2e-6, 1e-6]}}}
    b = build_batch([Scene.model_validate(d)], simulation=Simulation(duration=1.0))
    np.testing.assert_allclose(b.floor_t, [0, 0.002, 0.004, 0.006])
    np.testing.assert_allclose(b.floor_disp[0], [[0] * 4, [0] * 4, [0, 1e-6, 2e-6, 1e-6]])
    assert b.duration[0] == 1.0 and b.gravity_stiffness and b.has_floor_motion


def test_auto_duration_lets_the_slowest_mode_decay():
    """Soft, lightly damped mounts need longer than the 3 s margin: 9.2 time constants 1 / (zeta w)."""
    d = symmetric("air", f_vertical="1 Hz", f_horizontal="1 Hz", zeta="10 %")
    b = build_batch([Scene.model_validate(d)])
    last = b.prof_t[0].max()  # the final rest piece starts when the move ends
    tau_heave = 1.0 / (0.1 * 2 * math.pi * 1.0)  # 1.6 s; a rocking mode may decay slower still
    assert 9.2 * tau_heave * (1 - 1e-9) <= b.duration[0] - last < 60.0
    assert b.duration[0] == pytest.approx(min(last + 9.2 * slowest_decay_time(b)[0], 60.0), rel=1e-9)


def test_auto_duration_is_capped():
    d = symmetric()
    d["stages"][0]["profile"] = {"type": "trapezoid", "travel": 0.7, "velocity": 0.01, "acceleration": 1.0}
    assert build_batch([Scene.model_validate(d)]).duration[0] == 60.0


def test_several_scenes_and_overrides():
    scenes = [Scene.model_validate(symmetric(p)) for p in ("active", "air", "elastomer")]
    b = build_batch(scenes)
    assert b.n_cases == 3 and b.iso_skyhook[:, 0].tolist() == [True, False, False]
    assert b.iso_k[0, 0, 2] < b.iso_k[1, 0, 2] < b.iso_k[2, 0, 2]
    one = Scene.model_validate(symmetric())
    b = build_batch([one], {"stages.y.mass": np.array([100.0, 200.0]), "isolators.layout.span_x": 0.5})
    assert b.n_cases == 2
    np.testing.assert_allclose(b.stage_mass[:, 0], [100.0, 200.0])
    np.testing.assert_allclose(b.iso_pos[:, 1, 0] - b.iso_pos[:, 0, 0], 0.5)
    with pytest.raises(ValueError, match="stages.y.mass: must be positive"):
        build_batch([one], {"stages.y.mass": np.array([100.0, -1.0])})
    d = symmetric()
    d["stages"][0]["name"] = "z"
    with pytest.raises(ValueError, match="differs in shape"):
        build_batch([one, Scene.model_validate(d)])


def test_combination_that_unloads_a_mount_names_the_case():
    one = Scene.model_validate(scriber())
    with pytest.raises(SceneError, match=r"isolator \d would carry .* \(case 1\)"):
        build_batch(
            [one], {"isolators.layout.span_y": np.array([3.6, 0.3]), "stages.y.mass": 2000.0}, n_cases=2
        )


def slow_batch(study: Study, idx: np.ndarray):
    """Reference: apply each case to the scene dict, validate it with pydantic, build one by one."""
    return build_batch([study.case_scene(int(i)) for i in idx])


def assert_same_batch(fast, slow):
    for name in (
        "mass",
        "inertia",
        "cg",
        "iso_pos",
        "iso_k",
        "iso_c",
        "iso_skyhook",
        "stage_mass",
        "stage_home",
        "stage_axis",
        "stage_parent",
        "prof_t",
        "prof_s",
        "prof_v",
        "prof_a",
        "prof_j",
        "points",
        "floor_amp",
        "duration",
        "settle_tol",
    ):
        np.testing.assert_allclose(getattr(fast, name), getattr(slow, name), rtol=1e-12, atol=0, err_msg=name)


def test_study_batch_matches_case_by_case_validation_grid():
    s = load_study(EXAMPLES / "isolator-comparison.yaml")
    idx = np.array([11, 0, 5, 3, 8, 4])  # mixed isolator types, out of order
    fast = s.batch(idx)
    assert_same_batch(fast, slow_batch(s, idx))
    types = s.design().values["isolator_type"][idx]
    assert fast.iso_skyhook[:, 0].tolist() == [t == "active" for t in types]
    np.testing.assert_allclose(fast.prof_a[:, 0, 0], s.design().values["stage_y_acceleration"][idx])


def test_study_batch_matches_case_by_case_validation_every_path():
    """Every continuous path of a scene, varied at once, goes into the arrays as pydantic would put it."""
    d = scriber()
    d["floor"] = {"sine": {"amplitude": [1e-6, 2e-6, 3e-6], "frequency": [5, 6, 7]}}
    d["stages"][1]["profile"] = {
        "type": "sequence",
        "start": 1.65,
        "segments": [
            {"move": 0.1, "velocity": 1.0, "acceleration": 5.0, "jerk": 500.0},
            {"dwell": 0.1},
            {"move": -0.1, "velocity": 1.0, "acceleration": 5.0},
        ],
    }
    d["isolators"]["k"] = {"z": 1e6}
    params = [
        ("machine.block.size.0", 2.4, 2.8),
        ("machine.block.size.1", 4.0, 4.2),
        ("machine.block.size.2", 0.3, 0.4),
        ("machine.block.density", 2600, 2800),
        ("machine.block.corner.2", 0.0, 0.1),
        ("isolators.f_vertical", 2.0, 4.0),
        ("isolators.f_horizontal", 2.0, 4.0),
        ("isolators.zeta", 0.05, 0.3),
        ("isolators.k.z", 5e5, 2e6),
        ("isolators.c.horizontal", 1e3, 1e4),
        ("isolators.layout.span_x", 2.0, 2.4),
        ("isolators.layout.span_y", 3.0, 3.8),
        ("isolators.layout.height", 0.2, 0.6),
        ("stages.y.mass", 500, 1500),
        ("stages.y.home.x", 1.0, 1.5),
        ("stages.y.home.z", 0.4, 0.6),
        ("stages.y.profile.travel", 2.0, 3.0),
        ("stages.y.profile.velocity", 1.0, 2.0),
        ("stages.y.profile.acceleration", 5.0, 20.0),
        ("stages.y.profile.jerk", 200.0, 2000.0),
        ("stages.y.profile.dwell", 0.1, 0.3),
        ("stages.y.profile.start", 0.0, 0.2),
        ("stages.x.profile.segments.0.move", 0.05, 0.2),
        ("stages.x.profile.segments.1.dwell", 0.0, 0.2),
        ("stages.x.profile.segments.2.velocity", 0.5, 1.5),
        ("stages.x.profile.start", 1.6, 1.9),
        ("points.camera.z", 0.5, 1.0),
        ("floor.sine.amplitude.z", 1e-6, 1e-5),
        ("floor.sine.frequency.x", 1, 50),
        ("floor.sine.phase.y", 0, 3),
        ("simulation.duration", 3.0, 6.0),
        ("simulation.settle_tolerance", 1e-6, 1e-5),
    ]
    data = {
        "name": "all",
        "scene": d,
        "design": {"type": "random", "samples": 12, "seed": 9},
        "parameters": [{"path": p, "range": {"start": lo, "stop": hi}} for p, lo, hi in params],
    }
    s = Study.model_validate(data)
    idx = np.arange(12)[::-1]
    fast = s.batch(idx)
    assert_same_batch(fast, slow_batch(s, idx))
    # and the values really vary (an override that went nowhere would make every case alike)
    assert np.unique(fast.iso_pos[:, 0, 0]).size == 12 and np.unique(fast.prof_t[:, 1, 1]).size == 12
    assert np.unique(fast.floor_phase[:, 1]).size == 12 and np.unique(fast.duration).size == 12


def test_lhs_10000_batch_builds_fast():
    s = load_study(EXAMPLES / "lhs-10000.yaml")
    t0 = time.perf_counter()
    b = s.batch(np.arange(s.n_cases))
    elapsed = time.perf_counter() - t0
    print(f"\nbatch of {s.n_cases} LHS cases built in {elapsed * 1e3:.1f} ms")
    assert b.n_cases == 10_000 and elapsed < 2.0
    d = s.design()
    np.testing.assert_allclose(
        b.iso_k[:, :, 0], np.repeat(d.values["isolator_k_horizontal"][:, None], 4, axis=1)
    )
    np.testing.assert_allclose(b.iso_k[:, :, 0], b.iso_k[:, :, 1])
    np.testing.assert_allclose(b.stage_mass[:, 0], d.values["stage_y_mass"])
    np.testing.assert_allclose(b.iso_pos[:, 2, 1] - b.iso_pos[:, 1, 1], d.values["isolator_span_y"])
    assert np.all(b.duration == 5.0)
    # vertical stiffness stays the air preset on the load each mount carries in that case
    m_total = b.mass + b.stage_mass.sum(axis=1)
    np.testing.assert_allclose(b.iso_k[:, :, 2].sum(axis=1), m_total * (2 * math.pi * 3.5) ** 2, rtol=1e-12)
    idx = np.array([0, 4321, 9999])
    assert_same_batch(s.batch(idx), slow_batch(s, idx))


def test_batch_index_checks():
    s = load_study(EXAMPLES / "isolator-comparison.yaml")
    with pytest.raises(ValueError, match="indices"):
        s.batch(np.array([12]))
    b = s.batch(slice(2, 5))
    assert b.n_cases == 3


def test_study_reports_a_combination_that_unloads_a_mount_at_validation():
    data = {
        "name": "t",
        "scene": scriber(),
        "parameters": [
            {"path": "isolators.layout.span_y", "values": [3.6, "0.6 m"]},
            {"path": "stages.y.mass", "values": [100, "3 t"]},
        ],
    }
    with pytest.raises(
        ValueError,
        match=r"case 3 \(isolator_span_y, stage_y_mass = 0.6 m, 3000 kg\): isolators: "
        r"isolator \d would carry",
    ):
        validate_study(data)
    data["parameters"][1]["values"] = [100, "1 t"]  # each value alone, and every combination, is fine
    assert validate_study(data).n_cases == 4


def test_a_stored_definition_is_rebuilt_by_parsing_alone_and_the_build_still_refuses_a_bad_case():
    """Parse -> check -> build: a worker rebuilds a stored definition without the check step (no dry run);
    a case that is not a physical scene is still refused when it is built."""
    data = {
        "name": "t",
        "scene": scriber(),
        "parameters": [
            {"path": "isolators.layout.span_y", "values": [3.6, "0.6 m"]},
            {"path": "stages.y.mass", "values": [100, "3 t"]},
        ],
    }
    with pytest.raises(ValueError, match="case 3"):
        validate_study(data)
    study = study_from_json(json.dumps(data))
    assert study.n_cases == 4
    assert study_from_json(json.dumps(data)) is study  # one parse per process and definition
    assert study.batch([0, 1, 2]).n_cases == 3
    with pytest.raises(ValueError, match=r"case 3 \(isolator_span_y, stage_y_mass = 0.6 m, 3000 kg\)"):
        study.batch([3])


def test_scene_batch_labels():
    from isolab.studies.inputs.study import scene_batch

    b, names = scene_batch(Scene.model_validate(scriber()))
    assert names == {
        "isolators": ["mount_0", "mount_1", "mount_2", "mount_3"],
        "points": ["tool", "camera"],
        "stages": ["y", "x"],
    }
    assert b.n_cases == 1 and b.n_isolators == 4


def test_tuning_applies_only_to_the_chosen_type():
    """A machine's tuned air mounts stay air mounts: choosing another type takes that type's preset."""
    d = symmetric("air", tuning={"air": {"f_vertical": "3.5 Hz", "zeta": "20 %"}})
    b = build_batch([Scene.model_validate(d)])
    m_total = b.mass[0] + b.stage_mass[0].sum()
    np.testing.assert_allclose(b.iso_k[0, :, 2].sum(), m_total * (2 * math.pi * 3.5) ** 2, rtol=1e-12)
    np.testing.assert_allclose(b.iso_k[0, :, 0].sum(), m_total * (2 * math.pi * 3.0) ** 2, rtol=1e-12)
    np.testing.assert_allclose(b.iso_c[0, :, 2], 2 * 0.2 * np.sqrt(b.iso_k[0, :, 2] * m_total / 4))
    d["isolators"]["preset"] = "elastomer"
    b = build_batch([Scene.model_validate(d)])
    np.testing.assert_allclose(b.iso_k[0, :, 2].sum(), m_total * (2 * math.pi * 10.0) ** 2, rtol=1e-12)
