"""Levelling valves beside the other extra linear states: with the mounts' internal states (an orifice of
``model: zener``) and with a stage on a servo both sets of states run in ``z`` and the exact and RK4
integrators agree; with a flexible base they are refused naming the field. A stored study of the levelled
scriber carries its error estimate measured at ltv/rk4, the reference of scenes with extra linear states."""

from __future__ import annotations

import copy
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
import yaml
from dask.distributed import Client
from pydantic import ValidationError

from isolab.engine import model, simulate
from isolab.engine.results import OK
from isolab.engine.scene import SceneError
from isolab.studies.inputs.study import load_scene, load_study, scene_batch
from isolab.studies.results.dataset import error_estimate
from isolab.studies.results.store import Store
from isolab.studies.run.error_estimate import (
    SERVO_DEAD_BAND_REFERENCE_PAIR,
    SERVO_REFERENCE_PAIR,
    STATES_REFERENCE_PAIR,
    reference_pair,
)
from tests.shared_cluster import shared_scheduler

EXAMPLES = Path(__file__).parents[2] / "studies" / "examples"
ZENER = {
    "effective_area": "0.03 m^2",
    "volume": "1 l",
    "reservoir_volume": "1 l",
    "orifice": {"area": "2 mm^2", "length": "50 mm", "model": "zener"},
}


def example(name: str) -> dict:
    return yaml.safe_load((EXAMPLES / f"{name}.yaml").read_text())


def levelled(name: str, simulation: dict) -> dict:
    """Example ``name`` on the levelled scriber's four mounts (three valves, tau = 2 s)."""
    data = example(name)
    data["isolators"] = copy.deepcopy(example("scriber-levelling")["isolators"])
    data["simulation"] = simulation
    return data


def agree(batch, pairs: list[tuple[str, str]]) -> None:
    """Every pair runs the batch and their peaks agree to 1e-6 of the largest."""
    runs = [simulate(batch, *p, dt=1e-3) for p in pairs]
    for p, r in zip(pairs, runs, strict=True):
        assert (r.status == OK).all(), (p, r.message)
    for name in ("peak_displacement", "peak_rotation", "peak_isolator_force"):
        ref = getattr(runs[0], name)
        for p, r in zip(pairs[1:], runs[1:], strict=True):
            err = np.abs(getattr(r, name) - ref).max() / np.abs(ref).max()
            assert err < 1e-6, (name, p, err)


def test_valves_and_a_zener_orifice_run_together_and_the_integrators_agree() -> None:
    data = levelled("scriber-levelling", {"fidelity": "lti", "integrator": "exact", "dt": "1 ms"})
    data["simulation"]["duration"] = "3 s"
    data["isolators"]["air"] = ZENER
    batch, _ = scene_batch(load_scene(data))
    assert batch.iso_valve[0].tolist() == [0, 0, 1, 2]
    assert model.linear_slot(batch).A.shape[1] == 4 + 3  # four orifices, then three valves
    assert reference_pair(batch) == STATES_REFERENCE_PAIR
    agree(batch, [("lti", "exact"), ("lti", "rk4")])
    ltv = simulate(batch, "ltv", "rk4", dt=1e-3)
    assert (ltv.status == OK).all(), ltv.message


def test_valves_and_a_servo_stage_run_together_at_lti() -> None:
    data = levelled(
        "scriber-servo", {"fidelity": "lti", "integrator": "exact", "dt": "1 ms", "duration": "3 s"}
    )
    batch, _ = scene_batch(load_scene(data))
    assert len(batch.servo_stages) == 1 and batch.iso_valve[0].max() == 2
    assert model.linear_slot(batch).A.shape[1] == 2 + 3  # the following error, then three valves
    assert reference_pair(batch) == SERVO_REFERENCE_PAIR
    agree(batch, [("lti", "exact"), ("lti", "rk4")])
    data["isolators"]["list"][2]["levelling"]["dead_band"] = "5 um"
    data["simulation"]["integrator"] = "rk4"
    banded, _ = scene_batch(load_scene(data))
    assert reference_pair(banded) == SERVO_DEAD_BAND_REFERENCE_PAIR == ("lti", "rk4")
    with pytest.raises(SceneError, match="iso_level_band"):
        simulate(banded, *SERVO_REFERENCE_PAIR, dt=1e-3)


def test_valves_and_a_flexible_base_are_refused_naming_the_field() -> None:
    data = levelled("scriber-flexible-base", {"fidelity": "ltv", "integrator": "rk4", "dt": "1 ms"})
    with pytest.raises(ValidationError, match="machine.flexible: levelling valves"):
        load_scene(data)
    flexible, _ = scene_batch(load_scene(example("scriber-flexible-base")))
    valves, _ = scene_batch(load_scene(example("scriber-levelling")))
    both = replace(
        flexible, **{k: getattr(valves, k) for k in ("iso_valve", "iso_level_time", "iso_level_band")}
    )
    with pytest.raises(SceneError, match="iso_valve: levelling valves .* flexible base"):
        simulate(both, "ltv", "rk4", dt=1e-3)


@pytest.fixture(scope="module")
def client():
    with Client(shared_scheduler(1)) as c:
        yield c


def levelling_study(simulation: dict) -> dict:
    """The levelled scriber over 3 s, the far-end valve's time constant varied."""
    scene = example("scriber-levelling")
    scene["simulation"] = {**simulation, "dt": "1 ms", "duration": "3 s"}
    return {
        "name": "levelled scriber",
        "scene": scene,
        "parameters": [{"path": "isolators.list.2.levelling.time_constant", "values": ["1 s", "2 s"]}],
        "design": {"type": "grid"},
    }


def stored(study: dict, client: Client, tmp_path: Path) -> xr.Dataset:
    from isolab.studies.run.runner import run_study

    store = Store(tmp_path)
    with xr.open_dataset(store.path(run_study(load_study(study), store, client))) as f:
        return f.load()


def test_a_stored_levelling_study_carries_its_error_estimate(client: Client, tmp_path: Path) -> None:
    """The example's own pair (ltv/rk4) is the reference of its extra states: a zero estimate that says so;
    at lti/exact its sampled cases rerun at ltv/rk4 and the measured error is stored."""
    ds = stored(levelling_study({"fidelity": "ltv", "integrator": "rk4"}), client, tmp_path / "ltv")
    assert (ds["status"].values == OK).all()
    assert error_estimate(ds)["peak_displacement"] == 0.0
    assert "reference level of its extra linear states (ltv, rk4)" in ds.attrs["error_estimate_method"]
    ds = stored(levelling_study({"fidelity": "lti", "integrator": "exact"}), client, tmp_path / "lti")
    est = error_estimate(ds)
    # the frozen-mass lti level against the ltv level on a 1,000 kg stage's 3 m travel: a real error
    assert np.isfinite(est["peak_displacement"]) and 0.0 < est["peak_displacement"] < 0.5
    assert "ltv level, rk4 integrator" in ds.attrs["error_estimate_method"]
    assert "levelling valves" in ds.attrs["error_estimate_method"]
