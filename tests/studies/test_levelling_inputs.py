"""Levelling valves from the scene file (``isolators[.list[j]].levelling``): the valves' arrays of the batch,
the scriber example levelled back to its set height, a study varying the time constant, and bad input
refused naming the field (a 422 over REST)."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
import yaml
from fastapi.testclient import TestClient
from pydantic import ValidationError

from isolab.engine import simulate
from isolab.service.api.app import create_app
from isolab.service.settings import Settings
from isolab.studies.inputs.parameters import available_paths, resolve
from isolab.studies.inputs.scenes import build_batch
from isolab.studies.inputs.study import load_scene, scene_batch, validate_study
from isolab.studies.run.costs import CASE_OVERHEAD, LEVELLING_STEP_FACTOR, estimate_seconds_per_case

EXAMPLE = Path(__file__).parents[2] / "studies" / "examples" / "scriber-levelling.yaml"
TOKEN = "s3cret"


def example() -> dict:
    return yaml.safe_load(EXAMPLE.read_text())


def mounts_levelling(*specs: dict | None) -> dict:
    """The example with each listed mount's ``levelling`` block replaced by ``specs`` (None: none)."""
    data = example()
    for m, spec in zip(data["isolators"]["list"], specs, strict=True):
        m.pop("levelling")
        if spec is not None:
            m["levelling"] = copy.deepcopy(spec)
    return data


def mount_heights(batch, history) -> np.ndarray:
    """(T, n) each mount's height change ``u_z + (theta x d)_z``, m, of case 0's recorded history."""
    d = batch.iso_pos[0] - batch.cg[0]
    u, th = history["displacement"][0], history["rotation"][0]
    return u[:, 2:3] + th[:, 0:1] * d[None, :, 1] - th[:, 1:2] * d[None, :, 0]


def test_the_example_plumbs_three_valves_and_levels_the_base_back() -> None:
    """Two mounts on ``home_end``, one valve each for the others; after the 3 m move the valves bring every
    mount back to its set height (without them the base stays pitched by about 3 mm at the mounts)."""
    batch, _ = scene_batch(load_scene(EXAMPLE))
    assert batch.iso_valve[0].tolist() == [0, 0, 1, 2]
    assert np.all(batch.iso_level_time == 2.0) and np.all(batch.iso_level_band == 0.0)
    assert batch.duration[0] == pytest.approx(1.6020 + 9.2 * 2.0, abs=1e-3)  # auto: 9.2 valve time constants
    r = simulate(batch, "ltv", "rk4", 1e-3, record=[0])
    h = mount_heights(batch, r.history)
    assert np.abs(h[-1]).max() < 1e-6
    plain, _ = scene_batch(load_scene(mounts_levelling(None, None, None, None)))
    assert plain.iso_valve.max() == -1 and plain.duration[0] < batch.duration[0]
    p = simulate(plain, "ltv", "rk4", 1e-3, record=[0])
    assert np.abs(mount_heights(plain, p.history)[-1]).min() > 2e-3
    assert np.all(np.abs(h).max(axis=0) < np.abs(mount_heights(plain, p.history)).max(axis=0))


def test_a_group_block_gives_every_mount_a_valve_and_a_study_varies_its_time_constant() -> None:
    data = mounts_levelling(None, None, None, None)
    data["isolators"]["levelling"] = {"time_constant": "3 s", "valve": "all"}
    scene = load_scene(data)
    path = "isolators.levelling.time_constant"
    assert path in available_paths(scene)
    assert resolve(path, scene).dimension == "time"
    batch = build_batch([scene], {path: np.array([1.0, 4.0])})
    assert batch.iso_valve.tolist() == [[0, 0, 0, 0]] * 2
    assert batch.iso_level_time[:, 0].tolist() == [1.0, 4.0]


LEV = {"time_constant": "2 s"}


@pytest.mark.parametrize(
    ("data", "words"),
    [
        (mounts_levelling({"time_constant": "0 s"}, None, None, None), "time_constant"),
        (mounts_levelling({"time_constant": "-1 s"}, None, None, None), "time_constant"),
        (mounts_levelling({"time_constant": "1 s", "dead_band": "-1 um"}, None, None, None), "dead_band"),
        (mounts_levelling({"time_constant": "1 s", "flow": 3}, None, None, None), "flow"),
        (mounts_levelling(LEV, LEV, LEV, LEV), "isolators.list.3.levelling: valve 'mount 3' is the 4th"),
        (
            mounts_levelling({**LEV, "valve": "a"}, {"time_constant": "3 s", "valve": "a"}, None, None),
            "isolators.list.1.levelling.time_constant: mount 1 and mount 0 share valve 'a'",
        ),
    ],
)
def test_bad_levelling_input_is_named(data: dict, words: str) -> None:
    with pytest.raises(ValidationError, match=words):
        load_scene(data)


def test_levelling_on_a_mount_that_is_not_air_and_unmodelled_choices_are_refused() -> None:
    data = mounts_levelling(LEV, None, None, None)
    data["isolators"]["list"][0]["preset"] = "elastomer"
    with pytest.raises(ValidationError, match="isolators.list.0.levelling: mount 0 is not an air mount"):
        load_scene(data)
    for sim, words in (
        ({"fidelity": "nonlinear"}, "simulation.fidelity: levelling valves"),
        ({"integrator": "euler"}, "simulation.integrator: levelling valves"),
    ):
        data = mounts_levelling(LEV, None, None, None)
        data["simulation"].update(sim)
        data["simulation"] = {k: v for k, v in data["simulation"].items() if v is not None}
        with pytest.raises(ValidationError, match=words):
            load_scene(data)
    data = mounts_levelling(LEV, None, None, None)
    data["floor"] = {"sine": {"amplitude": ["0 m", "0 m", "1 um"], "frequency": ["0 Hz", "0 Hz", "10 Hz"]}}
    with pytest.raises(ValidationError, match="floor: levelling valves"):
        load_scene(data)
    data = mounts_levelling({**LEV, "dead_band": "10 um"}, None, None, None)
    data["simulation"].update({"fidelity": "lti", "integrator": "exact"})
    with pytest.raises(ValidationError, match=r"isolators.list.0.levelling.dead_band: .* rk4"):
        load_scene(data)
    data["simulation"]["integrator"] = "rk4"
    assert load_scene(data).isolators.listed[0].levelling is not None


def test_over_rest_bad_levelling_is_a_422_naming_the_field(tmp_path: Path) -> None:
    app = TestClient(create_app(Settings(data_dir=tmp_path, api_token=TOKEN, max_cases=100)))
    auth = {"Authorization": f"Bearer {TOKEN}"}
    for data, loc_end, words in (
        (mounts_levelling({"time_constant": "0 s"}, None, None, None), "time_constant", "greater than 0"),
        (mounts_levelling(LEV, LEV, LEV, LEV), None, "plumb two mounts to one valve"),
    ):
        r = app.post("/scenes/check", json={"scene": data}, headers=auth)
        assert r.status_code == 422, r.text
        detail = r.json()["detail"][0]
        assert words in detail["msg"]
        if loc_end is not None:
            assert detail["loc"][-1] == loc_end


def test_the_cost_model_knows_the_valves_extra_states() -> None:
    """A study of the levelled scriber costs its measured factor (two at ltv/rk4) more per step than the
    same study without valves."""

    def study(data: dict) -> dict:
        return {
            "name": "valves",
            "scene": data,
            "parameters": [{"path": "stages.y.mass", "values": ["900 kg", "1000 kg"]}],
            "design": {"type": "grid"},
            "simulation": {"duration": "5 s"},
        }

    levelled = validate_study(study(example()))
    plain = validate_study(study(mounts_levelling(None, None, None, None)))
    per_step = [estimate_seconds_per_case(s) - CASE_OVERHEAD for s in (levelled, plain)]
    assert per_step[0] / per_step[1] == pytest.approx(LEVELLING_STEP_FACTOR[("ltv", "rk4")], rel=1e-12)


@pytest.mark.parametrize("dead_band", [None, "5 um"])
def test_the_accuracy_chooser_picks_a_pair_that_steps_the_valves(dead_band: str | None) -> None:
    """An accuracy request on a scene with levelling valves: the truth is ltv/rk4 at the finest step, the
    candidates are the pairs that model the valves (exact not under a dead band, which it does not step),
    and the chosen model's measured error on the pilot cases is within the tolerance."""
    from isolab.studies.run.accuracy import choose_for_batch, pilot_cases

    spec = LEV if dead_band is None else {**LEV, "dead_band": dead_band}
    data = mounts_levelling(spec, spec, None, None)
    data["simulation"] = {"tolerance": "2 %", "duration": "6 s"}
    scene = load_scene(data)
    assert scene.simulation.fidelity is None  # a request, not a model
    batch, _ = scene_batch(scene)
    choice = choose_for_batch(batch, 0.02, steps=(2e-4, 1e-3, 5e-3))
    tried = {(row["fidelity"], row["integrator"]) for row in choice.pilot}
    allowed = {("lti", "rk4"), ("ltv", "rk4")} | (set() if dead_band else {("lti", "exact")})
    assert tried <= allowed and (choice.fidelity, choice.integrator) in allowed
    assert "ltv/rk4" in choice.reason and "nonlinear" not in choice.reason
    chosen = [
        r
        for r in choice.pilot
        if (r["fidelity"], r["integrator"], r["dt"]) == (choice.fidelity, choice.integrator, choice.dt)
    ]
    assert chosen and chosen[0]["meets"] and 0.0 <= chosen[0]["error"] <= 0.02
    # the screening run that picks a study's pilot cases steps a dead band too
    study = validate_study(
        {"name": "lev", "scene": data, "parameters": [{"path": "stages.y.mass", "values": ["500 kg", "1 t"]}]}
    )
    assert pilot_cases(study) in ([0], [1], [0, 1])
