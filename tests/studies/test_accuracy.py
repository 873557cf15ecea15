"""Accuracy requests: the schema, the chooser's measurements and choices, and the error estimate every
stored study carries."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import xarray as xr
from dask.distributed import Client
from pydantic import ValidationError

from isolab.engine import simulate
from isolab.engine.results import OK
from isolab.studies.inputs.schema import Simulation, error_messages, parse_tolerance
from isolab.studies.inputs.study import Study, load_scene, load_study, scene_batch
from isolab.studies.results.dataset import error_estimate
from isolab.studies.results.store import Store
from isolab.studies.run import accuracy
from isolab.studies.run.accuracy import choose, choose_for_batch, pilot_cases, resolved_simulation
from isolab.studies.run.costs import STEP_COST
from isolab.studies.run.error_estimate import ESTIMATED_OUTPUTS, error_sample, output_errors, sizing_error
from tests.shared_cluster import shared_scheduler

STEPS = (5e-4, 1e-3, 2e-3, 5e-3)  # a short ladder: the truth at 0.5 ms keeps the tests fast


def scene(
    stage_mass: str,
    travel: str,
    accel: str,
    velocity: str,
    preset: str = "air",
    duration: str = "2 s",
    simulation: dict | None = None,
) -> dict:
    """The article's granite base (10 t, 0.5 m above its mounts) with one Y stage doing one move."""
    return {
        "machine": {"block": {"size": ["2.6 m", "4.2 m", "0.34 m"], "density": "2700 kg/m^3"}},
        "isolators": {"preset": preset, "layout": {"span_x": "2.2 m", "span_y": "3.6 m", "height": "0.5 m"}},
        "stages": [
            {
                "name": "y",
                "mass": stage_mass,
                "home": ["1.3 m", "0.6 m", "0.47 m"],
                "axis": [0, 1, 0],
                "profile": {
                    "type": "trapezoid",
                    "travel": travel,
                    "velocity": velocity,
                    "acceleration": accel,
                },
            }
        ],
        "points": {"tool": ["1.3 m", "0.6 m", "0.6 m"]},
        "simulation": {"duration": duration, **(simulation or {})},
    }


LIGHT_SHORT = scene("20 kg", "0.1 m", "0.5 g", "0.5 m/s")  # rotations of 2e-5 rad: nothing to model
HEAVY_LONG = scene("1500 kg", "3 m", "1 g", "2 m/s")  # the composite c.g. moves 0.4 m: pitch drives heave


def batch_of(data: dict):
    return scene_batch(load_scene(data))[0]


# ------------------------------------------------------------------------------------------------ schema
def test_accuracy_and_an_explicit_model_exclude_each_other() -> None:
    with pytest.raises(ValidationError) as err:
        Simulation.model_validate({"accuracy": "fast", "fidelity": "lti"})
    (msg,) = error_messages(err.value)
    assert msg.startswith("simulation.accuracy:") and "fidelity 'lti'" in msg and "not both" in msg
    with pytest.raises(ValidationError) as err:
        Simulation.model_validate({"tolerance": "1 %", "integrator": "rk4"})
    assert error_messages(err.value)[0].startswith("simulation.accuracy:")
    with pytest.raises(ValidationError) as err:
        Simulation.model_validate({"accuracy": "fast", "tolerance": "1 %"})
    assert "give accuracy or tolerance, not both" in error_messages(err.value)[0]
    # a step is allowed: it caps the steps the chooser may pick
    sim = Simulation.model_validate({"accuracy": "balanced", "dt": "2 ms"})
    assert (sim.fidelity, sim.integrator, sim.dt, sim.request) == (None, None, 2e-3, "balanced")
    assert accuracy.candidate_steps(sim.dt) == (1e-4, 2e-4, 5e-4, 1e-3, 2e-3)
    # without a request the defaults stand, and they are not inputs (a study-level block leaves the scene's)
    plain = Simulation.model_validate({"dt": "2 ms"})
    assert (plain.fidelity, plain.integrator, plain.request) == ("ltv", "rk4", None)
    assert plain.model_fields_set == {"dt"}


def test_tolerance_is_a_length_or_a_relative_error() -> None:
    assert parse_tolerance("10 um") == (pytest.approx(1e-5), False)
    assert parse_tolerance("1 %") == (pytest.approx(0.01), True)
    assert Simulation.model_validate({"tolerance": "10 um"}).tolerance == "1e-05 m"
    assert Simulation.model_validate({"tolerance": "0.5 %"}).tolerance == "0.5 %"
    for bad, reason in (
        (0.01, "give a length"),
        ("0.01", "has no unit"),
        ("1 s", "cannot read"),
        ("150 %", "(0, 100 %]"),
        ("-1 um", "(0, 1 m]"),
    ):
        with pytest.raises(ValidationError) as err:
            Study.model_validate({"name": "s", "scene": LIGHT_SHORT, "simulation": {"tolerance": bad}})
        (msg,) = error_messages(err.value)
        assert msg.startswith("simulation.tolerance:") and reason in msg, msg


def test_a_study_request_replaces_the_scene_model_and_back() -> None:
    explicit = scene(
        "20 kg",
        "0.1 m",
        "0.5 g",
        "0.5 m/s",
        simulation={"fidelity": "lti", "integrator": "exact", "dt": "1 ms"},
    )
    study = load_study({"name": "s", "scene": explicit, "simulation": {"accuracy": "fast"}})
    assert (study.simulation.fidelity, study.simulation.accuracy, study.simulation.dt) == (None, "fast", None)
    requested = scene("20 kg", "0.1 m", "0.5 g", "0.5 m/s", simulation={"tolerance": "5 um"})
    back = load_study({"name": "s", "scene": requested, "simulation": {"integrator": "euler"}})
    assert (back.simulation.fidelity, back.simulation.integrator, back.simulation.tolerance) == (
        "ltv",
        "euler",
        None,
    )
    with pytest.raises(ValueError, match="simulation.accuracy"):
        load_study({"name": "s", "scene": requested, "simulation": {"accuracy": "fast", "fidelity": "ltv"}})
    # the definition round-trips (the fan-out rebuilds studies from it)
    again = type(study).model_validate(json.loads(json.dumps(study.model_dump(mode="json"))))
    assert again.simulation == study.simulation


# ------------------------------------------------------------------------------------------------ errors
def _result(disp, rot, force, min_load, settle, static, points=None, status=OK):
    return SimpleNamespace(
        status=np.array([status]),
        peak_displacement=np.array([disp]),
        peak_rotation=np.array([rot]),
        peak_isolator_force=np.array([force]),
        min_isolator_load=np.array([min_load]),
        settling_time=np.array([settle]),
        static_isolator_load=np.array([static]),
        peak_point_displacement=np.zeros((1, 0, 3)) if points is None else np.array([points]),
    )


def test_errors_are_relative_to_the_largest_reference_peak() -> None:
    static = [1000.0, 1000.0, 2000.0]
    ref = _result(
        [1e-3, 4e-3, 2e-3],
        [1e-4, 0.0, 0.0],
        [[10, 10, 50], [5, 5, 5], [1, 1, 1]],
        [900, 950, 1500],
        0.50,
        static,
    )
    got = _result(
        [1.1e-3, 4e-3, 2.2e-3],
        [1e-4, 1e-10, 0.0],
        [[10, 10, 45], [5, 5, 5], [1, 1, 1]],
        [880, 950, 1500],
        0.53,
        static,
    )
    e = output_errors(got, ref)
    assert e["peak_displacement"][0] == pytest.approx(0.2e-3 / 4e-3)  # Z is off by 0.2 mm of a 4 mm peak
    assert e["peak_rotation"][0] == pytest.approx(1e-10 / 1e-4)
    assert e["peak_isolator_force"][0] == pytest.approx(5 / 50)
    assert e["min_isolator_load"][0] == pytest.approx(20 / 2000)  # relative to the largest preload
    assert e["settling_time"][0] == pytest.approx(0.03)
    assert e["displacement_m"][0] == pytest.approx(0.2e-3)
    assert sizing_error(e, relative=True)[0] == pytest.approx(0.1)
    assert sizing_error(e, relative=False)[0] == pytest.approx(0.2e-3)
    # no rotation at all in the reference: rotations below 1 nrad count as nothing, not as infinite error
    still = _result([1e-3, 4e-3, 2e-3], [0.0, 0.0, 0.0], [[10, 10, 50]] * 3, [900] * 3, 0.5, static)
    wobble = _result([1e-3, 4e-3, 2e-3], [1e-12, 0.0, 0.0], [[10, 10, 50]] * 3, [900] * 3, 0.5, static)
    assert output_errors(wobble, still)["peak_rotation"][0] == pytest.approx(1e-3)
    # a case that is not OK has no error, not a number
    failed = _result([np.nan] * 3, [np.nan] * 3, [[np.nan] * 3] * 3, [np.nan] * 3, np.nan, static, status=1)
    assert all(np.isnan(v[0]) for v in output_errors(failed, ref).values())


# ------------------------------------------------------------------------------------------------ chooser
def test_tiny_rotations_pick_the_time_invariant_model() -> None:
    b = batch_of(LIGHT_SHORT)
    for tol in (0.05, 0.005):
        c = choose_for_batch(b, tol, steps=STEPS)
        assert c.fidelity == "lti", (tol, c.reason)
        _check_measured(b, c, tol, relative=True)


def test_a_long_heavy_stroke_needs_the_time_varying_model() -> None:
    b = batch_of(HEAVY_LONG)
    c = choose_for_batch(b, 0.05, steps=STEPS)
    assert c.fidelity == "ltv", c.reason
    lti = [row for row in c.pilot if row["fidelity"] == "lti"]
    # the frozen-mass model misses over 5 % of the peaks at every step it was tried at
    assert lti and all(row["error"] > 0.05 for row in lti)
    _check_measured(b, c, 0.05, relative=True)
    tight = choose_for_batch(b, 0.005, steps=STEPS)
    assert tight.fidelity != "lti" and _cost(b, tight) >= _cost(b, c)
    _check_measured(b, tight, 0.005, relative=True)


def test_an_absolute_tolerance_bounds_the_peak_displacement_error() -> None:
    b = batch_of(HEAVY_LONG)
    loose = choose_for_batch(b, 200e-6, relative=False, steps=STEPS)
    tight = choose_for_batch(b, 5e-6, relative=False, steps=STEPS)
    _check_measured(b, loose, 200e-6, relative=False)
    _check_measured(b, tight, 5e-6, relative=False)
    assert _cost(b, tight) > _cost(b, loose)


def test_a_tolerance_no_candidate_meets_falls_back_to_the_reference() -> None:
    b = batch_of(LIGHT_SHORT)
    c = choose_for_batch(b, 1e-9, steps=(2e-3, 5e-3))
    assert (c.fidelity, c.integrator, c.dt) == ("nonlinear", "reference", 2e-3)
    assert "no candidate meets" in c.reason
    # every candidate was measured and missed, but RK4's: its damping of the fastest mode per cycle
    # exceeds 1e-9 at either step, so the step rule rules it out before measuring
    rk4 = sum(1 for _, integrator in accuracy.CANDIDATE_PAIRS if integrator == "rk4")
    assert len(c.pilot) == 2 * (len(accuracy.CANDIDATE_PAIRS) - rk4)
    assert all(row["integrator"] != "rk4" for row in c.pilot)
    assert all(not row["meets"] and row["error"] > 1e-9 for row in c.pilot)


def _cost(b, c) -> float:
    return next(
        row["cost_s"]
        for row in c.pilot
        if (row["fidelity"], row["integrator"], row["dt"]) == (c.fidelity, c.integrator, c.dt)
    )


def _check_measured(b, c, tol: float, relative: bool) -> None:
    """The chosen candidate meets the tolerance when measured again, and every candidate the cost model
    ranks cheaper was tried and missed it."""
    truth = simulate(b, "nonlinear", "reference", dt=min(STEPS))
    r = simulate(b, c.fidelity, c.integrator, dt=c.dt)
    assert r.status[0] == OK
    err = float(sizing_error(output_errors(r, truth), relative)[0])
    assert err <= tol
    assert err == pytest.approx(c.pilot[-1]["error"], rel=1e-12)
    costs = [row["cost_s"] for row in c.pilot]
    assert costs == sorted(costs)
    assert all(not row["meets"] for row in c.pilot[:-1]) and c.pilot[-1]["meets"]
    n = float(np.rint(b.duration[0] / c.dt))
    assert c.pilot[-1]["cost_s"] == pytest.approx(n * STEP_COST[(c.fidelity, c.integrator)], rel=1e-9)


# ---------------------------------------------------------------------------------------- study level
COMPARISON = {
    "name": "types",
    "scene": scene("1000 kg", "1 m", "1 g", "1 m/s", duration="1.5 s"),
    "parameters": [
        {"path": "isolators.preset", "values": ["active", "air", "elastomer"]},
        {"path": "stages.y.mass", "values": ["300 kg", "1000 kg"]},
    ],
    "design": {"type": "grid"},
}


def _with_simulation(sim: dict) -> dict:
    d = json.loads(json.dumps(COMPARISON))
    d["simulation"] = sim
    return d


def test_pilot_cases_are_the_hardest_of_each_type_and_the_stiffest() -> None:
    study = load_study(_with_simulation({"accuracy": "fast"}))
    cases = pilot_cases(study)
    # grid order: preset varies slowest; the heavier stage rotates the base more in every type
    types = study.design().values["isolator_type"]
    assert set(types[cases]) == {"active", "air", "elastomer"} and len(cases) <= accuracy.PILOT_LIMIT
    r = simulate(study.batch(np.arange(6)), "lti", "exact", dt=accuracy.SCREEN_STEP)
    for t in ("active", "air", "elastomer"):
        members = np.flatnonzero(types == t)
        hardest = members[np.argmax(r.peak_rotation[members].max(axis=1))]
        assert hardest in cases
    assert int(np.argmax(r.natural_frequency.max(axis=1))) in cases


def test_choice_is_cached_and_fills_the_simulation_block(monkeypatch) -> None:
    study = load_study(_with_simulation({"accuracy": "fast", "dt": "5 ms"}))
    c = choose(study)
    assert c.request == "fast" and c.tolerance == 0.05 and c.dt <= 5e-3
    assert c.pilot[-1]["meets"] and c.pilot[-1]["error"] <= 0.05
    ref = choose(load_study(_with_simulation({"accuracy": "reference", "dt": "2 ms"})))
    assert (ref.fidelity, ref.integrator, ref.dt, ref.pilot) == ("nonlinear", "reference", 2e-3, ())
    monkeypatch.setattr(accuracy, "_choose", lambda s: pytest.fail("measured twice"))
    assert choose(load_study(_with_simulation({"accuracy": "fast", "dt": "5 ms"}))) is c
    sim = resolved_simulation(study)
    assert (sim.fidelity, sim.integrator, sim.dt, sim.request) == (c.fidelity, c.integrator, c.dt, None)


def test_error_sample_is_seeded_and_covers_every_isolator_type() -> None:
    study = load_study(_with_simulation({"fidelity": "lti", "integrator": "exact"}))
    a = error_sample(study)
    assert a == error_sample(study) and len(a) == 4
    assert set(study.design().values["isolator_type"][a]) == {"active", "air", "elastomer"}


@pytest.fixture(scope="module")
def client():
    with Client(shared_scheduler(1)) as c:
        yield c


def _open(store: Store, sid: str) -> xr.Dataset:
    with xr.open_dataset(store.path(sid)) as f:
        return f.load()


def test_a_requested_study_records_its_choice_and_its_measured_error(client: Client, tmp_path: Path) -> None:
    from isolab.studies.run.runner import run_study

    study = load_study(_with_simulation({"accuracy": "balanced", "dt": "5 ms"}))
    store = Store(tmp_path)
    sid = run_study(study, store, client)
    ds = _open(store, sid)
    choice = choose(study)
    assert ds.attrs["accuracy_request"] == "balanced" and ds.attrs["accuracy_tolerance"] == "0.5 %"
    assert (ds.attrs["fidelity"], ds.attrs["integrator"], ds.attrs["dt"]) == (
        choice.fidelity,
        choice.integrator,
        choice.dt,
    )
    assert choice.fidelity != "lti"  # a 1 m stroke of up to 1 t on air and active mounts
    pilot = json.loads(ds.attrs["accuracy_pilot"])
    assert pilot[-1]["meets"] and pilot[-1]["error"] <= 0.005 and "cheapest" in ds.attrs["accuracy_reason"]
    assert json.loads(ds.attrs["accuracy_pilot_cases"]) == list(choice.pilot_cases)
    row = store.get(sid)
    assert (row["fidelity"], row["integrator"]) == (choice.fidelity, choice.integrator)
    # the cases ran with the choice
    direct = simulate(study.batch(np.arange(6)), choice.fidelity, choice.integrator, dt=choice.dt)
    got = ds.peak_displacement.transpose("isolator_type", "stage_y_mass", "axis").values.reshape(6, 3)
    np.testing.assert_array_equal(got, direct.peak_displacement)
    _check_estimate(ds, study, direct, choice.dt)


def test_every_stored_study_carries_its_measured_error(client: Client, tmp_path: Path) -> None:
    from isolab.studies.run.runner import run_study

    study = load_study(_with_simulation({"fidelity": "lti", "integrator": "exact", "dt": "2 ms"}))
    store = Store(tmp_path)
    ds = _open(store, run_study(study, store, client))
    assert ds.attrs["accuracy_request"].startswith("none")
    direct = simulate(study.batch(np.arange(6)), "lti", "exact", dt=2e-3)
    est = _check_estimate(ds, study, direct, 2e-3)
    # the frozen-mass model misses part of the heave a 1 m stroke of 1 t causes: a real, visible error
    # (measured 0.97 % of the largest peak), well above the step error of exact discretisation
    assert est["peak_displacement"] > 0.005

    ref_study = load_study(_with_simulation({"accuracy": "reference", "dt": "5 ms"}))
    ref = _open(store, run_study(ref_study, store, client))
    assert (ref.attrs["fidelity"], ref.attrs["integrator"]) == ("nonlinear", "reference")
    assert all(v == 0.0 for v in error_estimate(ref).values())
    assert "reference level" in ref.attrs["error_estimate_method"]


def _check_estimate(ds: xr.Dataset, study, direct, dt: float) -> dict[str, float]:
    cases = json.loads(ds.attrs["error_estimate_cases"])
    assert cases == error_sample(study)
    est = error_estimate(ds)
    assert set(est) == {
        "peak_displacement",
        "peak_point_displacement",
        "peak_rotation",
        "peak_isolator_force",
        "min_isolator_load",
        "settling_time",
    }
    assert ds.error_estimate_settling_time.attrs["units"] == "s"
    assert ds.error_estimate_peak_rotation.attrs["units"] == "1"
    assert "reference" in ds.error_estimate_peak_rotation.attrs["long_name"]
    ref = simulate(study.batch(cases), "nonlinear", "reference", dt=dt)
    ours = SimpleNamespace(
        **{
            k: np.asarray(getattr(direct, k))[cases]
            for k in ("status", *ESTIMATED_OUTPUTS, "static_isolator_load")
        }
    )
    expected = output_errors(ours, ref)
    for name, value in est.items():
        assert value == pytest.approx(float(np.nanmax(expected[name])), rel=1e-9, abs=1e-15), name
        worst = int(ds[f"error_estimate_{name}"].attrs["case"])
        assert worst in cases
    return est
