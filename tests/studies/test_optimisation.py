"""Optimisation studies: the ask-and-tell loop on closed-form problems, a real scene on a Dask cluster,
resume after an interruption, and bad goals refused naming the field."""

from __future__ import annotations

import json
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from distributed import Client
from fastapi.testclient import TestClient

from isolab.service.api.app import create_app
from isolab.service.api.jobs import JobQueue
from isolab.service.settings import Settings
from isolab.studies.answers.tuning import TUNING_RANGES
from isolab.studies.inputs.definitions import DefinitionError, check_definition, stored_definition
from isolab.studies.inputs.study import load_study, validate_study
from isolab.studies.quantities import output_values
from isolab.studies.questions.designs import Design, Factor
from isolab.studies.questions.goals import (
    PENALTY,
    Constraint,
    Goals,
    Objective,
    goal_values,
)
from isolab.studies.results.cases import case_table, filter_mask, parse_filter
from isolab.studies.results.dataset import failed_arrays, from_chunks, to_dataset
from isolab.studies.results.store import Store
from isolab.studies.run.optimisation import GENERATION_FILE, Journal, non_dominated, optimise
from isolab.studies.run.runner import run_study
from tests.shared_cluster import shared_scheduler

sys.path.insert(0, str(Path(__file__).parent))
from test_fanout import small_study  # noqa: E402  (the fan-out tests' cut-down scriber)


# ------------------------------------------------------------------------------- closed-form problems
def goals(algorithm: str = "ga", budget: int = 1200, population: int = 24, seed: int = 7, n_obj: int = 1):
    """x in [-2, 3] (linear), y in [0.01, 100] (log): the optimiser's unit box maps y through log10."""
    factors = (Factor("x", "x", low=-2.0, high=3.0), Factor("y", "y", low=0.01, high=100.0, scale="log"))
    objectives = tuple(Objective(f"f{k}", "minimize") for k in range(n_obj))
    return Goals(
        objectives,
        (Constraint("x", ">=", 1.5),),
        algorithm,
        budget,
        population,
        seed,
        ("case_ok", "x >= 1.5"),
        factors,
    )


def bowl(calls: list | None = None):
    """min (x - 1)^2 + (log10 y)^2 subject to x >= 1.5: the optimum is x = 1.5, y = 1, f = 0.25. Cases with
    x > 2.9 'fail' (NaN objective), as a case that does not compute would."""

    def evaluate(g: int, v: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        if calls is not None:
            calls.append(g)
        x, y = v["x"], v["y"]
        f = (x - 1.0) ** 2 + np.log10(y) ** 2
        f = np.where(x > 2.9, np.nan, f)
        g_ok = np.where(np.isnan(f), PENALTY, 0.0)
        return {"F": f[:, None], "G": np.stack([g_ok, 1.5 - x], axis=1)}

    return evaluate


def best_of(outcome) -> tuple[np.ndarray, float]:
    x = np.concatenate([a["x"] for a in outcome.generations])
    F = np.concatenate([a["F"] for a in outcome.generations])
    G = np.concatenate([a["G"] for a in outcome.generations])
    feasible = (G <= 0).all(axis=1)
    i = np.flatnonzero(feasible)[np.argmin(F[feasible, 0])]
    return x[i], float(F[i, 0])


@pytest.mark.parametrize("algorithm", ["ga", "de", "pso"])
def test_the_optimiser_finds_the_constrained_optimum(algorithm: str) -> None:
    outcome = optimise(goals(algorithm), bowl())
    assert not outcome.cancelled and outcome.n_cases == 1200  # 50 generations of 24 fit the budget
    x, f = best_of(outcome)
    assert x[0] == pytest.approx(1.5, abs=0.02) and x[1] == pytest.approx(1.0, rel=0.05)
    assert f == pytest.approx(0.25, abs=0.01)
    F = np.concatenate([a["F"] for a in outcome.generations])
    assert np.isfinite(F).all()  # the failed cases reached pymoo as the penalty, never NaN
    failed = np.concatenate([a["x"][:, 0] > 2.9 for a in outcome.generations])
    assert failed.any() and (F[failed] == PENALTY).all()


def test_the_pattern_search_converges_and_is_reproducible() -> None:
    a = optimise(goals("pattern", budget=300), bowl())
    b = optimise(goals("pattern", budget=300), bowl())
    xa, fa = best_of(a)
    assert fa == pytest.approx(0.25, abs=0.01) and xa[0] == pytest.approx(1.5, abs=0.02)
    np.testing.assert_array_equal(
        np.concatenate([g["u"] for g in a.generations]), np.concatenate([g["u"] for g in b.generations])
    )


def test_the_budget_bounds_the_cases() -> None:
    outcome = optimise(goals(budget=100, population=24), bowl())
    assert outcome.n_cases == 96  # the fifth generation of 24 would exceed 100
    assert [len(g["u"]) for g in outcome.generations] == [24] * 4


def test_non_dominated_is_the_pareto_front() -> None:
    F = np.array([[1, 5], [2, 2], [5, 1], [3, 3], [2, 2], [6, 6], [1, 6]], dtype=float)
    # (3, 3) and (6, 6) are dominated by (2, 2); (1, 6) by (1, 5); the equal (2, 2) rows both stay
    np.testing.assert_array_equal(non_dominated(F), [True, True, True, False, True, False, False])


def test_nsga2_front_lies_between_the_two_optima() -> None:
    """min x^2 and (x - 2)^2 over x in [-2, 3]: the Pareto set is 0 <= x <= 2."""
    g = Goals(
        (Objective("a", "minimize"), Objective("b", "minimize")),
        (),
        "nsga2",
        600,
        30,
        1,
        ("case_ok",),
        (Factor("x", "x", low=-2.0, high=3.0), Factor("y", "y", low=0.0, high=1.0)),
    )

    def evaluate(_g: int, v: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        x = v["x"]
        return {"F": np.stack([x**2, (x - 2.0) ** 2], axis=1), "G": np.zeros((len(x), 1))}

    outcome = optimise(g, evaluate)
    last = outcome.generations[-1]
    front = non_dominated(np.concatenate([a["F"] for a in outcome.generations]))
    x = np.concatenate([a["x"][:, 0] for a in outcome.generations])
    assert front.sum() >= 20
    assert x[front].min() > -0.01 and x[front].max() < 2.01
    assert np.ptp(last["x"][:, 0]) > 1.5  # the population spreads along the front


@pytest.mark.parametrize("algorithm", ["ga", "de", "pso", "nsga2", "pattern", "nelder-mead"])
def test_an_interrupted_loop_resumes_where_it_stopped(tmp_path: Path, algorithm: str) -> None:
    g = goals(algorithm, budget=240, population=24)
    whole = optimise(g, bowl())
    cancel = threading.Event()
    journal = Journal(tmp_path)
    first_calls: list[int] = []

    def stop_after_three(done: int, _evaluated: int) -> None:
        if done == 3:
            cancel.set()

    part = optimise(g, bowl(first_calls), journal, cancel, stop_after_three)
    assert part.cancelled and len(part.generations) == 3 and first_calls == [0, 1, 2]
    calls: list[int] = []
    rest = optimise(g, bowl(calls), journal)
    assert not rest.cancelled
    assert calls and calls[0] == 3  # the saved generations are not evaluated again
    assert rest.replayed == 3  # the algorithm is rebuilt from its seed and replayed through them
    saved = sorted(p.name for p in tmp_path.iterdir())  # plain arrays of each generation, no state
    assert saved == sorted(GENERATION_FILE.format(k) for k in range(len(rest.generations)))
    np.testing.assert_array_equal(
        np.concatenate([a["u"] for a in rest.generations]),
        np.concatenate([a["u"] for a in whole.generations]),
    )
    assert best_of(rest)[1] == best_of(whole)[1]


class _Planted:
    """An object whose unpickling writes a file: what a crafted state file in the data directory does."""

    def __init__(self, mark: Path):
        self.mark = mark

    def __reduce__(self):
        return (Path.write_text, (self.mark, "ran"))


def test_a_planted_state_file_runs_nothing_and_the_run_resumes_as_the_clean_one(tmp_path: Path) -> None:
    """A pickle planted as the optimiser's state (its name in older versions) is removed unread: nothing it
    holds runs, and the run replays the saved generations to the clean run's cases and optimum."""
    import pickle

    g = goals("ga", budget=240, population=24)
    whole = optimise(g, bowl())
    cancel = threading.Event()
    journal = Journal(tmp_path / "chunks")
    journal.directory.mkdir()
    optimise(g, bowl(), journal, cancel, lambda done, _n: cancel.set() if done == 3 else None)
    mark = tmp_path / "planted-code-ran"
    planted = journal.directory / "optimiser.pkl"
    planted.write_bytes(pickle.dumps({"generations": 3, "algorithm": _Planted(mark)}))
    calls: list[int] = []
    rest = optimise(g, bowl(calls), journal)
    assert not mark.exists() and not planted.exists()
    assert rest.replayed == 3 and calls[0] == 3
    np.testing.assert_array_equal(
        np.concatenate([a["u"] for a in rest.generations]),
        np.concatenate([a["u"] for a in whole.generations]),
    )
    assert best_of(rest)[1] == best_of(whole)[1]


def test_a_crafted_generation_file_is_not_unpickled_and_its_cases_run_again(tmp_path: Path) -> None:
    """A generation file holding a pickled object array is not unpickled: it is set aside and its cases run
    again, to the clean run's cases."""
    g = goals("ga", budget=96, population=24)
    whole = optimise(g, bowl())
    journal = Journal(tmp_path)
    mark = tmp_path / "planted-code-ran"
    with open(tmp_path / GENERATION_FILE.format(0), "wb") as f:
        np.savez(f, u=np.array([_Planted(mark)], dtype=object))
    calls: list[int] = []
    rest = optimise(g, bowl(calls), journal)
    assert not mark.exists()
    assert calls == [0, 1, 2, 3] and rest.replayed == 0
    np.testing.assert_array_equal(
        np.concatenate([a["u"] for a in rest.generations]),
        np.concatenate([a["u"] for a in whole.generations]),
    )


# ---------------------------------------------------------------------------------- definitions
def optimize_study(**design) -> dict:
    d = small_study(integrator="exact", duration="3 s")
    d["name"] = "optimise-small"
    d["parameters"] = [
        {"path": "isolators.f_vertical", "range": {"start": "2 Hz", "stop": "6 Hz"}},
        {"path": "isolators.zeta", "range": {"start": "2 %", "stop": "40 %", "scale": "log"}},
    ]
    d["design"] = {
        "type": "optimize",
        "objective": "minimize settling_time.tool",
        "constraints": ["peak_point_displacement.tool.y <= 4 mm"],
        "budget": 60,
        "population": 12,
        "seed": 3,
        **design,
    }
    return d


@pytest.mark.parametrize(
    ("design", "loc", "words"),
    [
        ({"objective": "minimize settling_tim.tool"}, ["body", "design", "objective"], "settling_time"),
        ({"objective": "minimize settling_time.tol"}, ["body", "design", "objective"], "tool, camera"),
        ({"objective": "lower settling_time"}, ["body", "design", "objective"], "minimize <quantity>"),
        ({"constraints": ["criteria"]}, ["body", "design", "constraints", 0], "criteria block"),
        ({"constraints": ["x", "liftof >= 0"]}, ["body", "design", "constraints", 0], "'criteria'"),
        ({"constraints": ["min_isolator_load >= 3 kg"]}, ["body", "design", "constraints", 0], "force"),
        ({"algorithm": "simplex"}, ["body", "design", "algorithm"], "nsga2"),
        (
            {"objective": ["minimize settling_time", "minimize peak_displacement.y"], "algorithm": "ga"},
            ["body", "design", "algorithm"],
            "one objective",
        ),
        ({"budget": None}, ["body", "design", "budget"], "budget"),
        ({"population": 80}, ["body", "design", "population"], "exceed the budget"),
    ],
)
def test_bad_goals_name_the_field(design: dict, loc: list, words: str) -> None:
    with pytest.raises(DefinitionError) as err:
        check_definition(optimize_study(**design), 1000)
    assert any(d["loc"][: len(loc)] == loc and words in d["msg"] for d in err.value.details), (
        err.value.details
    )


def test_a_listed_or_categorical_parameter_is_refused_by_name() -> None:
    d = optimize_study()
    d["parameters"].append({"path": "isolators.preset", "values": ["air", "active"]})
    with pytest.raises(DefinitionError) as err:
        check_definition(d, 1000)
    assert err.value.details[0]["loc"][:4] == ["body", "parameters", 2, "values"]
    assert "isolators.preset" in err.value.details[0]["msg"] and "range" in err.value.details[0]["msg"]


def test_the_budget_is_what_the_case_limit_counts() -> None:
    with pytest.raises(DefinitionError) as err:
        check_definition(optimize_study(budget=5000), 1000)
    assert err.value.details[0]["loc"] == ["body", "design", "budget"]
    assert check_definition(optimize_study(), 1000).planned_cases == 60


def test_bad_objective_is_422_through_rest(tmp_path: Path) -> None:
    app = create_app(Settings(data_dir=tmp_path, max_cases=1000))
    jobs = JobQueue(Store(tmp_path), client=None)  # not started, no cluster: submitted studies just queue
    app.state.jobs = jobs
    plain = TestClient(app)
    r = plain.post("/studies", json=optimize_study(objective="maximize natural_frequency.9"))
    assert r.status_code == 422, r.text
    detail = r.json()["detail"]
    assert any(d["loc"] == ["body", "design", "objective"] and "mode: 1, 2" in d["msg"] for d in detail), (
        detail
    )
    r = plain.post("/studies", json=optimize_study(constraints=["peak_isolator_force.q <= 3 kN"]))
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "design", "constraints", 0]
    assert jobs.queued() == []
    r = plain.post("/studies", json=optimize_study())  # a good one is accepted with its budget as n_cases
    assert r.status_code == 202 and r.json()["n_cases"] == 60 and jobs.queued() == [r.json()["id"]]
    info = plain.get(f"/studies/{r.json()['id']}").json()
    assert info["status"] == "queued" and info["progress"]["total"] == 60 and info["generation"] is None


# ------------------------------------------------------------------------------ on a Dask cluster


@pytest.fixture(scope="module")
def client():
    with Client(shared_scheduler(2)) as c:
        yield c


@pytest.fixture(scope="module")
def whole(client: Client, tmp_path_factory: pytest.TempPathFactory) -> tuple[Store, str, xr.Dataset]:
    """The tiny optimisation run uninterrupted: (store, id, dataset)."""
    store = Store(tmp_path_factory.mktemp("whole"))
    sid = run_study(validate_study(optimize_study()), store, client)
    return store, sid, store.open_dataset(sid)


@pytest.mark.slow
def test_the_stored_dataset_marks_the_optimum(whole) -> None:
    store, sid, ds = whole
    row = store.get(sid)
    assert row["status"] == "done" and row["n_done"] == row["n_cases"] == 60
    assert row["generation"] == row["generations"] == 5
    for name in ("generation", "feasible", "pareto", "best"):
        assert ds[name].dims == ("case",) and {"units", "long_name"} <= set(ds[name].attrs)
    np.testing.assert_array_equal(ds["generation"].values, np.repeat(np.arange(5), 12))
    settle = output_values(ds, "settling_time.tool").values
    tool_y = output_values(ds, "peak_point_displacement.tool.y").values
    ok = ds["status"].values == 0
    # feasible is exactly: ran ok and the tool's Y peak within 4 mm
    np.testing.assert_array_equal(ds["feasible"].values, ok & (tool_y <= 4e-3))
    assert 0 < ds["feasible"].sum() < 60  # the constraint binds
    assert ds["best"].sum() == 1
    b = int(np.flatnonzero(ds["best"].values)[0])
    assert ds["feasible"].values[b] and ds["pareto"].values[b]
    assert settle[b] <= settle[ds["feasible"].values].min()
    summary = json.loads(ds.attrs["optimisation"])
    assert summary["best_case"] == b and summary["algorithm"] == "ga" and summary["generations"] == 5
    assert summary["best_objectives"]["settling_time.tool"] == pytest.approx(settle[b])
    assert summary["best_parameters"]["isolator_f_vertical"] == pytest.approx(
        float(ds["isolator_f_vertical"].values[b])
    )
    # the parameters stay in their ranges (zeta drawn on a log scale)
    assert 2.0 <= ds["isolator_f_vertical"].min() and ds["isolator_f_vertical"].max() <= 6.0
    assert 0.02 <= ds["isolator_zeta"].min() and ds["isolator_zeta"].max() <= 0.4
    table = case_table(ds)  # the case table filters on them: GET /studies/{id}/cases?filter=pareto==true
    assert table.kinds["pareto"] == "bool" and "best" in table.default
    mask = filter_mask(table, parse_filter("pareto==true", table))
    np.testing.assert_array_equal(mask, ds["pareto"].values)
    np.testing.assert_array_equal(filter_mask(table, parse_filter("best==true", table)), ds["best"].values)
    assert not store.chunk_dir(sid).exists()  # the journal is gone once the dataset is written


@pytest.mark.slow
def test_a_cancelled_optimisation_resumes_to_the_same_optimum(client: Client, whole, tmp_path: Path) -> None:
    _, _, uninterrupted = whole
    store = Store(tmp_path)
    study = validate_study(optimize_study())
    cancel = threading.Event()

    def progress(done: int, _total: int) -> None:
        if done > 26:  # in the third generation
            cancel.set()

    sid = run_study(study, store, client, progress=progress, cancel=cancel)
    row = store.get(sid)
    # stopped in the third generation, or just after it when its last chunks arrived together
    g = row["generation"]
    assert row["status"] == "cancelled" and g in (2, 3) and row["n_done"] >= 12 * g
    journal = Journal(store.chunk_dir(sid))
    saved = journal.load_generations()
    assert sorted(saved) == list(range(g))
    assert sorted(p.suffix for p in store.chunk_dir(sid).iterdir()) == [".npz"] * g  # arrays, no state
    # mark the saved cases: a resumed run keeps them, one that recomputed them would not
    for k, arrays in saved.items():
        journal.save_generation(k, {**arrays, "message": np.array(["kept"] * len(arrays["status"]))})
    assert (store.chunk_dir(sid) / GENERATION_FILE.format(0)).is_file()

    assert run_study(study, store, client, study_id=sid) == sid
    row = store.get(sid)
    assert row["status"] == "done" and row["generation"] == 5
    ds = store.open_dataset(sid)
    kept = ds["message"].values == "kept"
    assert kept[: 12 * g].all() and not kept[12 * g :].any()
    for name in ("isolator_f_vertical", "isolator_zeta"):
        np.testing.assert_array_equal(ds[name].values, uninterrupted[name].values)
    np.testing.assert_array_equal(ds["best"].values, uninterrupted["best"].values)
    assert (
        json.loads(ds.attrs["optimisation"])["best_case"]
        == json.loads(uninterrupted.attrs["optimisation"])["best_case"]
    )
    np.testing.assert_array_equal(ds["feasible"].values, uninterrupted["feasible"].values)


@pytest.mark.slow
def test_a_service_restart_resumes_the_optimisation(client: Client, whole, tmp_path: Path) -> None:
    """The job queue stops mid-run (the study goes back to queued), the next queue takes it up again and
    it ends as the uninterrupted run did."""
    _, _, uninterrupted = whole
    store = Store(tmp_path)
    study = check_definition(optimize_study(), 1000)
    sid = store.create(stored_definition(study), name=study.name, n_cases=study.planned_cases)
    jobs = JobQueue(store, client, concurrency=1)
    jobs.start()
    jobs.submit(sid)
    deadline = time.monotonic() + 120
    while (store.get(sid)["generation"] or 0) < 1:
        assert time.monotonic() < deadline, store.get(sid)
        time.sleep(0.05)
    jobs.stop()
    row = store.get(sid)
    assert row["status"] == "queued" and 1 <= row["generation"] < 5, row
    again = JobQueue(store, client, concurrency=1)
    assert again.start() == [sid]
    deadline = time.monotonic() + 120
    while store.get(sid)["status"] in ("queued", "running"):
        assert time.monotonic() < deadline, store.get(sid)
        time.sleep(0.1)
    again.stop()
    assert store.get(sid)["status"] == "done"
    ds = store.open_dataset(sid)
    np.testing.assert_array_equal(ds["isolator_zeta"].values, uninterrupted["isolator_zeta"].values)
    np.testing.assert_array_equal(ds["best"].values, uninterrupted["best"].values)


def test_the_air_mount_example_is_checked_as_written() -> None:
    study = load_study(Path(__file__).resolve().parents[2] / "studies" / "examples" / "tune-air-mounts.yaml")
    g = study.goals
    assert g.algorithm == "ga" and g.budget == 1200 and g.population == 40 and study.planned_cases == 1200
    assert g.constraint_names == (
        "case_ok",
        "criterion tool_velocity",
        "criterion isolators_no_liftoff",
        "criterion isolators_max_deflection",
    )
    ranges = {f.name: (f.low, f.high, f.scale) for f in g.factors}
    # the air mounts' physical range, as a comparison's tuning searches it
    air = TUNING_RANGES["air"]
    assert ranges["isolator_f_vertical"] == (*air["f_vertical"], "linear")
    assert ranges["isolator_f_horizontal"] == (*air["f_horizontal"], "linear")
    assert ranges["isolator_zeta"] == (pytest.approx(air["zeta"][0]), pytest.approx(air["zeta"][1]), "log")
    # the three check cases: every parameter at its low, high and (log-)middle
    np.testing.assert_allclose(study.design().values["isolator_zeta"], [0.05, 0.3, np.sqrt(0.05 * 0.3)])
    assert study.scene.has_floor_spectrum()  # the study's own floor, which the VC-C criterion judges


@pytest.mark.slow
def test_an_optimisation_through_rest_reports_generations_and_filters_its_front(tmp_path: Path) -> None:
    with TestClient(
        create_app(Settings(data_dir=tmp_path, scheduler_address=shared_scheduler(2), max_cases=1000))
    ) as http:
        r = http.post("/studies", json=optimize_study(budget=24, population=12))
        assert r.status_code == 202 and r.json()["n_cases"] == 24, r.text
        sid = r.json()["id"]
        deadline = time.monotonic() + 120
        while (info := http.get(f"/studies/{sid}").json())["status"] in ("queued", "running"):
            assert time.monotonic() < deadline, info
            time.sleep(0.1)
        assert info["status"] == "done" and info["generation"] == info["generations"] == 2, info
        assert info["progress"] == {"done": 24, "total": 24, "failed": 0}
        front = http.get(f"/studies/{sid}/cases", params={"filter": "pareto==true", "limit": 100}).json()
        every = http.get(f"/studies/{sid}/cases", params={"limit": 100}).json()
        assert every["n_cases"] == 24
        assert {"generation", "feasible", "pareto", "best"} <= set(every["columns"])
        assert front["n_matched"] == sum(row["pareto"] for row in every["rows"]) >= 1
        assert all(row["pareto"] and row["feasible"] for row in front["rows"])
        (best,) = http.get(f"/studies/{sid}/cases", params={"filter": "best==true"}).json()["rows"]
        assert best["pareto"] and best["case"] in [row["case"] for row in front["rows"]]
        assert [row["generation"] for row in every["rows"]] == [0] * 12 + [1] * 12


def test_a_failed_case_is_infeasible_with_the_penalty_never_nan() -> None:
    study = check_definition(optimize_study(), 1000)
    g = study.goals
    failed = from_chunks({0: failed_arrays(1, "failed")}, [np.arange(1)], n_isolators=4, n_points=2)
    factors = list(g.factors)
    design = Design(
        "sampled",
        [f.name for f in factors],
        {f.name: np.array([f.low]) for f in factors},
        {},
        {f.name: f.path for f in factors},
        {f.name: f.unit for f in factors},
    )
    ds = to_dataset(failed, design, isolator_names=["m0", "m1", "m2", "m3"], point_names=["tool", "camera"])
    F, G = goal_values(ds, g)
    assert F.shape == (1, 1) and G.shape == (1, 2)
    assert (F == PENALTY).all() and (G == PENALTY).all()


@pytest.mark.slow
def test_constraint_values_are_relative_to_their_bound(whole) -> None:
    _, sid, ds = whole
    study = check_definition(optimize_study(), 1000)
    F, G = goal_values(ds, study.goals)
    tool_y = output_values(ds, "peak_point_displacement.tool.y").values
    np.testing.assert_allclose(F[:, 0], output_values(ds, "settling_time.tool").values)
    np.testing.assert_allclose(G[:, 0], 0.0)  # every case ran ok
    np.testing.assert_allclose(G[:, 1], (tool_y - 4e-3) / 4e-3)


def test_goals_read_the_quantities_a_dataset_will_hold_from_the_catalogue() -> None:
    from isolab.studies.quantities import quantity_names
    from isolab.studies.questions.criteria import Criteria, add_criteria
    from isolab.studies.questions.goals import quantity_layout

    criteria = Criteria.model_validate({"tool": {"displacement": "10 um"}, "isolators": {"no_liftoff": True}})
    failed = from_chunks({0: failed_arrays(1, "failed")}, [np.arange(1)], n_isolators=2, n_points=1)
    design = Design("sampled", ["x"], {"x": np.array([0.0])}, {}, {"x": "stages.y.mass"}, {"x": "kg"})
    ds = add_criteria(to_dataset(failed, design, isolator_names=["m0", "m1"], point_names=["tool"]), criteria)
    layout = quantity_layout(["m0", "m1"], ["tool"], criteria)
    assert list(layout) == quantity_names(ds)
    for name, dims in layout.items():
        assert list(dims) == [str(d) for d in ds[name].dims if d != "case"]
        for dim, labels in dims.items():
            assert labels == [str(v) for v in ds[dim].values]
