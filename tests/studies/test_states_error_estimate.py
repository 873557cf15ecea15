"""The error estimate of a scene with extra linear states (a flexible base, mounts' internal states, a stage
on a servo), which the nonlinear level and the reference integrator do not model: its reference reruns run
at the best pair that models them, and the estimate says so."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
import yaml
from dask.distributed import Client

from isolab.engine.results import OK
from isolab.studies.inputs.study import load_scene, load_study, scene_batch
from isolab.studies.results.dataset import error_estimate
from isolab.studies.results.store import Store
from isolab.studies.run.error_estimate import (
    REFERENCE_PAIR,
    SERVO_REFERENCE_PAIR,
    STATES_REFERENCE_PAIR,
    estimate_errors,
    exact_estimate,
    reference_method,
    reference_pair,
    sample_arrays,
)
from tests.shared_cluster import shared_scheduler

EXAMPLES = Path(__file__).parents[2] / "studies" / "examples"


def example(name: str) -> dict:
    return yaml.safe_load((EXAMPLES / f"{name}.yaml").read_text())


def flexible_study(simulation: dict) -> dict:
    """The flexible scriber over 1.5 s, its block's Young's modulus varied."""
    scene = example("scriber-flexible-base")
    scene["simulation"] = {**simulation, "duration": "1.5 s"}
    return {
        "name": "flexible block",
        "scene": scene,
        "parameters": [{"path": "machine.flexible.young_modulus", "values": ["40 GPa", "60 GPa"]}],
        "design": {"type": "grid"},
    }


def test_each_scene_is_measured_against_the_best_pair_that_models_it() -> None:
    zener = example("article-scriber")
    zener["isolators"]["air"] = {
        "effective_area": "0.03 m^2",
        "volume": "20 l",
        "reservoir_volume": "40 l",
        "orifice": {"area": "2 mm^2", "length": "50 mm", "model": "zener"},
    }
    expected = {
        "article-scriber": REFERENCE_PAIR,
        "scriber-flexible-base": STATES_REFERENCE_PAIR,
        "scriber-servo": SERVO_REFERENCE_PAIR,
    }
    for name, pair in expected.items():
        assert reference_pair(scene_batch(load_scene(example(name)))[0]) == pair, name
    assert reference_pair(scene_batch(load_scene(zener))[0]) == STATES_REFERENCE_PAIR
    assert STATES_REFERENCE_PAIR == ("ltv", "rk4")


def test_a_flexible_base_is_estimated_at_ltv_rk4_and_the_estimate_says_so() -> None:
    study = load_study(flexible_study({"fidelity": "lti", "integrator": "exact", "dt": "1 ms"}))
    parts = [sample_arrays(json.dumps(study.model_dump(mode="json")), c) for c in range(2)]
    ours = {k: np.concatenate([p["ours"][k] for p in parts]) for k in parts[0]["ours"]}
    ref = {k: np.concatenate([p["reference"][k] for p in parts]) for k in parts[0]["reference"]}
    assert (ref["status"] == OK).all(), ref["message"]
    method = reference_method(STATES_REFERENCE_PAIR)
    est = estimate_errors(ours, ref, [0, 1], method=method, integrator="exact")
    assert not est.excluded
    # the frozen-mass lti level against the ltv level: a small, real, measured error
    assert 0.0 < est.values["peak_displacement"] < 0.05
    assert "ltv level, rk4 integrator" in est.method and "do not model" in est.method
    assert "nonlinear level, reference integrator" in reference_method(REFERENCE_PAIR)
    assert "(ltv, rk4)" in exact_estimate([0], pair=STATES_REFERENCE_PAIR).method


@pytest.fixture(scope="module")
def client():
    with Client(shared_scheduler(1)) as c:
        yield c


def test_a_stored_flexible_base_study_carries_its_measured_error(client: Client, tmp_path: Path) -> None:
    from isolab.studies.run.runner import run_study

    study = load_study(flexible_study({"fidelity": "lti", "integrator": "exact", "dt": "1 ms"}))
    store = Store(tmp_path)
    with xr.open_dataset(store.path(run_study(study, store, client))) as f:
        ds = f.load()
    est = error_estimate(ds)
    assert np.isfinite(est["peak_displacement"]) and est["peak_displacement"] > 0.0
    assert "ltv level, rk4 integrator" in ds.attrs["error_estimate_method"]


def test_the_accuracy_chooser_measures_a_servo_stage_against_lti_exact() -> None:
    """Only the lti level models a stage on a servo: the truth is lti/exact, the candidates lti pairs."""
    from isolab.studies.run.accuracy import choose_for_batch

    data = example("scriber-servo")
    data["simulation"]["duration"] = "2.5 s"
    batch, _ = scene_batch(load_scene(data))
    choice = choose_for_batch(batch, 0.01, True, steps=(5e-4, 1e-3, 2e-3))
    assert choice.fidelity == "lti" and "against lti/exact" in choice.reason
