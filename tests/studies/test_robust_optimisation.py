"""Robust optimisation: candidates judged on their tolerance clouds. The draws are common random numbers
(two candidates see the same points, a candidate judged twice gets the same answer), the chance
constraint decides feasibility whatever the nominal margin says (a two-sided bound on a static mount load,
linear in the block's density), the statistic is the mean or quantile of the stored cloud, a resumed run
ends as the uninterrupted one, and the robust block's mistakes are refused naming the field."""

from __future__ import annotations

import copy
import json
import threading
from pathlib import Path

import numpy as np
import pytest

from isolab.engine import simulate
from isolab.service.api.schemas import EXAMPLE_SCENE
from isolab.studies.inputs.definitions import DefinitionError, check_definition
from isolab.studies.inputs.study import parse_study, study_labels, validate_study
from isolab.studies.questions.criteria import add_criteria
from isolab.studies.questions.goals import PENALTY, Robust, goal_values, robust_values
from isolab.studies.results.cases import case_table
from isolab.studies.results.dataset import result_arrays, to_dataset
from isolab.studies.run.optimisation import Journal, optimise
from isolab.studies.run.optimum import optimum_dataset
from isolab.studies.run.robust import CloudPlan
from tests.shared_cluster import shared_scheduler

DENSITY = "machine.block.density"


def scene() -> dict:
    s = copy.deepcopy(EXAMPLE_SCENE)
    s["simulation"] = {"fidelity": "lti", "integrator": "exact", "dt": "2 ms", "duration": "1 s"}
    return s


def robust_study(constraints: list[str], tolerances: dict, samples: int = 32, **robust) -> dict:
    return {
        "name": "robust-density",
        "scene": scene(),
        "tolerances": tolerances,
        "parameters": [{"path": DENSITY, "range": {"start": "500 kg/m^3", "stop": "8000 kg/m^3"}}],
        "design": {
            "type": "optimize",
            "objective": "minimize peak_displacement.y",
            "constraints": constraints,
            "robust": {"samples": samples, "require": "95 %", **robust},
            "budget": 40,
            "population": 4,
            "seed": 2,
        },
    }


def run_cases(definition: dict, values: dict[str, np.ndarray]):
    """Simulate a list design of ``values`` on ``definition`` (its design replaced): (dataset, arrays)."""
    names = list(values)
    n = len(values[names[0]])
    body = {k: v for k, v in definition.items() if k != "design"}
    body["design"] = {"type": "list", "cases": [{k: float(values[k][i]) for k in names} for i in range(n)]}
    st = parse_study(body)
    result = simulate(st.batch(np.arange(st.n_cases)), "lti", "exact", 2e-3)
    iso, pts = study_labels(st)
    ds = add_criteria(to_dataset(result, st.design(), isolator_names=iso, point_names=pts), st.criteria)
    return ds, result_arrays(result)


def judged(definition: dict, densities: list[float]) -> tuple[CloudPlan, dict[str, np.ndarray]]:
    """The candidates ``densities`` judged on their clouds, as the runner does."""
    st = validate_study(definition)
    plan = CloudPlan.of(st)
    assert plan is not None and st.goals is not None
    cases = plan.cases({st.goals.factors[0].name: np.array(densities)})
    ds, arrays = run_cases(plan.definition(definition), cases)
    F, G = goal_values(ds, st.goals)
    out = plan.judge(arrays, F, G)
    return plan, {**out, "x": np.array(densities)[:, None], "u": np.zeros((len(densities), 1))}


# ------------------------------------------------------------------------------ common random numbers
def test_two_candidates_see_the_same_draws_and_a_candidate_judged_twice_the_same_answer() -> None:
    tol = {
        DENSITY: {"distribution": "uniform", "within": "20 %"},  # a share of each candidate's density
        "stages.y.mass": {"distribution": "normal", "sigma": "50 kg"},  # the same kilograms for every one
    }
    d = robust_study(["peak_displacement.y <= 5 mm"], tol, samples=16)
    st = validate_study(d)
    plan = CloudPlan.of(st)
    assert plan is not None and plan.unit.shape == (16, 2)
    again = CloudPlan.of(validate_study(d))
    assert again is not None
    np.testing.assert_array_equal(plan.unit, again.unit)  # the seed fixes the points
    name = st.goals.factors[0].name if st.goals else ""
    cases = plan.cases({name: np.array([2000.0, 3000.0])})
    rho = cases[name].reshape(2, 17)
    mass = cases["stage_y_mass"].reshape(2, 17)
    assert rho[0, 0] == 2000.0 and rho[1, 0] == 3000.0 and (mass[:, 0] == 1000.0).all()  # nominal first
    np.testing.assert_allclose(rho[0, 1:] / 2000.0, rho[1, 1:] / 3000.0, rtol=1e-12)  # the same shares
    np.testing.assert_array_equal(mass[0, 1:], mass[1, 1:])  # the same draws of the stage mass
    assert np.ptp(rho[0, 1:] / 2000.0) > 0.3 and np.abs(rho[0, 1:] / 2000.0 - 1).max() <= 0.2 + 1e-12
    # a candidate judged beside different companions gets the same probability and statistic
    _, first = judged(d, [2000.0, 3000.0])
    _, second = judged(d, [6000.0, 2000.0])
    assert first["n_meets"][0] == second["n_meets"][1]
    assert first["F"][0, 0] == second["F"][1, 0] and first["G"][0, 0] == second["G"][1, 0]
    np.testing.assert_array_equal(first["cloud"][0], second["cloud"][1])


# ------------------------------------------------------------------------------ the chance constraint
@pytest.fixture(scope="module")
def band() -> tuple[dict, CloudPlan, dict[str, np.ndarray]]:
    """The static load of mount_0 held between its values at 1,000 and 6,000 kg/m^3 (linear in the
    density), the density within +-50 % of each candidate's. A at 3,500 kg/m^3 draws 1,750-5,250: inside,
    p = 1, but only 40 % below the upper bound. B at 1,600 draws 800-2,400: 12.5 % of them fall below
    1,000 (p = 0.875 < 0.95), though B is 47 % above the lower bound and further inside than A."""
    probe = robust_study([], {})
    probe.pop("tolerances")
    probe["design"] = {"type": "grid"}
    probe["parameters"] = [{"path": DENSITY, "values": [1000.0, 6000.0]}]
    ds, _ = run_cases(probe, {"machine_density": np.array([1000.0, 6000.0])})
    low, high = (float(v) for v in ds["static_isolator_load"].sel(isolator="mount_0").values)
    constraints = [
        f"static_isolator_load.mount_0 >= {low!r} N",
        f"static_isolator_load.mount_0 <= {high!r} N",
    ]
    d = robust_study(constraints, {DENSITY: {"distribution": "uniform", "within": "50 %"}})
    plan, out = judged(d, [3500.0, 1600.0])
    return d, plan, out


def test_the_chance_constraint_decides_feasibility_not_the_nominal_margin(band) -> None:
    d, plan, out = band
    margin = -out["nominal_G"][:, 1:].max(axis=1)  # the smaller margin of the two bounds, as drawn
    assert margin[1] > margin[0] > 0.3  # B is further inside its bounds than A
    p = out["n_meets"] / plan.samples
    assert p[0] == 1.0
    assert p[1] == pytest.approx(0.875)  # 4 of 32 scrambled Sobol' points lie below u = 1/8
    goals = plan.goals
    ds = optimum_dataset(
        [out],
        goals,
        stopped="budget",
        isolator_names=[f"mount_{i}" for i in range(4)],
        point_names=["tool"],
        cloud=plan,
    )
    np.testing.assert_array_equal(ds["feasible"].values, [True, False])
    np.testing.assert_array_equal(ds["nominal_feasible"].values, [True, True])
    np.testing.assert_array_equal(ds["best"].values, [True, False])
    assert not ds["plateau"].values[1]  # the plateau keeps to designs that meet the chance constraint
    np.testing.assert_allclose(ds["probability_meets_criteria"].values, [1.0, 0.875])
    lo, hi = ds["probability_meets_criteria_interval"].values[1]
    assert lo < 0.875 < hi < 0.97
    assert ds["probability_meets_criteria"].attrs["units"] == "1"
    assert "within its tolerances" in ds["probability_meets_criteria"].attrs["long_name"]
    fails = ds["constraint_failure_probability"].sel(case=1).values
    np.testing.assert_allclose(fails, [0.0, 0.125, 0.0])  # case_ok, the lower bound, the upper bound
    s = json.loads(ds.attrs["optimisation"])
    assert s["robust"]["require"] == 0.95 and s["best_case"] == 0
    table = case_table(ds)  # the case table shows each candidate's probability and statistic
    np.testing.assert_allclose(table.data["probability_meets_criteria"], [1.0, 0.875])
    assert {"probability_meets_criteria", "peak_displacement_y_statistic"} <= set(table.default)
    np.testing.assert_array_equal(table.data["nominal_feasible"], [1.0, 1.0])


# ------------------------------------------------------------------------------------------ the statistic
@pytest.mark.parametrize("robust", [{"statistic": "mean"}, {"statistic": "quantile", "quantile": "80 %"}])
def test_the_statistic_is_the_mean_or_quantile_of_the_stored_cloud(robust: dict) -> None:
    tol = {
        DENSITY: {"distribution": "uniform", "within": "20 %"},
        "stages.y.mass": {"distribution": "uniform", "within": "30 %"},
    }
    d = robust_study(["peak_displacement.y <= 50 mm"], tol, samples=8, **robust)
    plan, out = judged(d, [2000.0, 5000.0])
    ds = optimum_dataset(
        [out],
        plan.goals,
        stopped="budget",
        isolator_names=[f"mount_{i}" for i in range(4)],
        point_names=["tool"],
        cloud=plan,
    )
    cloud = ds["peak_displacement_y_cloud"].values
    assert cloud.shape == (2, 8) and np.isfinite(cloud).all() and np.ptp(cloud[0]) > 0
    expected = cloud.mean(axis=1) if robust["statistic"] == "mean" else np.quantile(cloud, 0.8, axis=1)
    np.testing.assert_allclose(ds["peak_displacement_y_statistic"].values, expected, rtol=1e-12)
    np.testing.assert_allclose(out["F"][:, 0], expected, rtol=1e-12)  # what the optimiser was told
    assert ds["peak_displacement_y_cloud"].attrs["units"] == "m"
    assert ds["peak_displacement_y_statistic"].attrs["units"] == "m"
    # the nominal case is what the dataset shows for the candidate, not a draw
    nominal = ds["peak_displacement"].sel(axis="y").values
    assert not np.isin(nominal, cloud).any()
    np.testing.assert_array_equal(ds["unit_draws"].values, plan.unit)


def test_a_failed_draw_meets_nothing_and_the_statistic_skips_it() -> None:
    F = np.array([[[1.0], [3.0], [PENALTY], [5.0]]])
    G = np.array([[[0.0, -1.0], [0.0, -0.5], [PENALTY, PENALTY], [0.0, 0.2]]])
    stat, chance, meets = robust_values(F, G, Robust(4, 0.5))
    assert stat[0, 0] == pytest.approx(3.0)  # the mean of 1, 3, 5
    np.testing.assert_array_equal(meets, [[True, True, False, False]])
    assert chance[0, 0] == pytest.approx(0.0)  # p = 0.5 meets a 0.5 requirement exactly
    stat, chance, _ = robust_values(F, G, Robust(4, 0.75, "quantile", 0.5))
    assert stat[0, 0] == pytest.approx(3.0) and chance[0, 0] > 0
    none, _, _ = robust_values(F[:, 2:3], G[:, 2:3], Robust(1, 0.5))
    assert none[0, 0] == PENALTY


# ------------------------------------------------------------------------------------------------ resume
def test_an_interrupted_robust_loop_resumes_to_the_same_optimum(tmp_path: Path) -> None:
    """The judged generations (probabilities, clouds) are plain arrays in the journal; a resumed run
    replays them and ends with the same cases and the same optimum."""
    d = robust_study(
        ["peak_displacement.y <= 5 mm"], {DENSITY: {"distribution": "uniform", "within": "20 %"}}, samples=8
    )
    st = validate_study(d)
    plan = CloudPlan.of(st)
    assert plan is not None and st.goals is not None
    goals = st.goals

    def evaluate(_g: int, values: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        rho = plan.cases(values)["machine_density"]  # a made-up response: peak 1 mm per 1,000 kg/m^3
        F = (rho * 1e-6)[:, None]
        G = np.stack([np.zeros_like(rho), (rho * 1e-6 - 5e-3) / 5e-3], axis=1)
        arrays = {"status": np.zeros(rho.size, dtype=np.int8)}
        return plan.judge(arrays, F, G)

    whole = optimise(goals, evaluate)
    cancel = threading.Event()
    journal = Journal(tmp_path)
    part = optimise(goals, evaluate, journal, cancel, lambda done, _n: cancel.set() if done == 3 else None)
    assert part.cancelled and len(part.generations) == 3
    rest = optimise(goals, evaluate, journal)
    assert rest.replayed == 3 and len(rest.generations) == len(whole.generations)
    for a, b in zip(rest.generations, whole.generations, strict=True):
        for key in ("u", "F", "G", "n_meets", "cloud"):
            np.testing.assert_array_equal(a[key], b[key])


# ------------------------------------------------------------------------------------------- refusals
@pytest.mark.parametrize(
    ("change", "loc", "words"),
    [
        ({"robust": {"samples": 8, "require": 1.5}}, ["body", "design", "robust", "require"], "up to 100 %"),
        ({"robust": {"samples": 8, "require": "0 %"}}, ["body", "design", "robust", "require"], "above 0"),
        ({"robust": {"samples": 1, "require": 0.9}}, ["body", "design", "robust", "samples"], "2"),
        ({"robust": {"samples": 8}}, ["body", "design", "robust", "require"], "required"),
        (
            {"robust": {"samples": 8, "require": 0.9, "statistic": "median"}},
            ["body", "design", "robust", "statistic"],
            "mean",
        ),
        (
            {"robust": {"samples": 8, "require": 0.9, "quantile": 0.8}},
            ["body", "design", "robust", "quantile"],
            "statistic: quantile",
        ),
        (
            {"robust": {"samples": 8, "require": 0.9, "statistic": "quantile", "quantile": "100 %"}},
            ["body", "design", "robust", "quantile"],
            "below 100 %",
        ),
        (
            {"robust": {"samples": 8, "require": 0.9, "draws": 3}},
            ["body", "design", "robust", "draws"],
            "xtra",
        ),
        ({"constraints": []}, ["body", "design", "constraints"], "chance constraint"),
        ({"tolerances": None}, ["body", "design", "robust"], "tolerances block"),
        (
            {
                "type": "lhs",
                "samples": 8,
                "objective": None,
                "constraints": None,
                "budget": None,
                "population": None,
            },
            ["body", "design", "robust"],
            "optimize",
        ),
    ],
)
def test_a_bad_robust_block_is_refused_naming_the_field(change: dict, loc: list, words: str) -> None:
    d = robust_study(
        ["peak_displacement.y <= 5 mm"], {DENSITY: {"distribution": "uniform", "within": "20 %"}}
    )
    if "tolerances" in change:
        d.pop("tolerances")
    else:
        d["design"].update(change)
        d["design"] = {k: v for k, v in d["design"].items() if v is not None}
    with pytest.raises(DefinitionError) as err:
        check_definition(d, 100_000)
    assert any(e["loc"][: len(loc)] == loc and words in e["msg"] for e in err.value.details), (
        err.value.details
    )


def test_the_case_limit_counts_every_draw() -> None:
    d = robust_study(
        ["peak_displacement.y <= 5 mm"], {DENSITY: {"distribution": "uniform", "within": "20 %"}}
    )
    assert check_definition(d, 100_000).planned_cases == 40 * 33
    with pytest.raises(DefinitionError) as err:
        check_definition(d, 1000)
    assert (
        err.value.details[0]["loc"] == ["body", "design", "budget"] and "1320" in err.value.details[0]["msg"]
    )


def test_the_robust_air_mount_example_is_checked_as_written() -> None:
    from isolab.studies.inputs.study import load_study

    study = load_study(
        Path(__file__).resolve().parents[2] / "studies" / "examples" / "robust-air-mounts.yaml"
    )
    goals = study.goals
    assert goals is not None and goals.robust is not None
    assert (goals.robust.samples, goals.robust.require, goals.robust.statistic) == (16, 0.95, "mean")
    assert goals.told_constraints == ("probability_meets_criteria >= 0.95",)
    spreads = {s.path: s for s in study.spreads}
    assert set(spreads) == {
        "isolators.f_vertical",
        "isolators.f_horizontal",
        "isolators.zeta",
        "stages.y.mass",
        "machine.block.density",
    }
    density = spreads["machine.block.density"]
    assert (density.low, density.high) == pytest.approx((2600.0, 2800.0))
    zeta = spreads["isolators.zeta"].about(0.3)  # a share of the candidate's damping: 24-36 %
    assert (zeta.low, zeta.high) == pytest.approx((0.24, 0.36))
    assert study.planned_cases == 320 * 17


@pytest.mark.slow
def test_a_cancelled_robust_study_resumes_to_the_same_result_on_a_cluster(tmp_path: Path) -> None:
    """Through the runner on a Dask cluster: cancelled in its second generation, run again with the same
    id, it ends with the same candidates, probabilities, statistics and optimum as an uninterrupted run."""
    from distributed import Client

    from isolab.studies.results.store import Store
    from isolab.studies.run.runner import run_study

    d = robust_study(
        ["peak_displacement.y <= 8 mm"], {DENSITY: {"distribution": "uniform", "within": "30 %"}}
    )
    d["design"].update(budget=12, population=4, robust={"samples": 4, "require": "75 %"})
    study = validate_study(d)
    with Client(shared_scheduler(2)) as client:
        whole_store = Store(tmp_path / "whole")
        whole = whole_store.open_dataset(run_study(study, whole_store, client))
        store = Store(tmp_path / "resumed")
        cancel = threading.Event()

        def progress(done: int, total: int) -> None:
            assert total == 12 * 5  # every draw counts
            if done > 25:  # in the second generation
                cancel.set()

        sid = run_study(study, store, client, progress=progress, cancel=cancel)
        assert store.get(sid)["status"] == "cancelled"
        assert run_study(study, store, client, study_id=sid) == sid
    row = store.get(sid)
    assert row["status"] == "done" and row["n_cases"] == row["n_done"] == 60
    ds = store.open_dataset(sid)
    for name in (
        "machine_density",
        "probability_meets_criteria",
        "peak_displacement_y_statistic",
        "peak_displacement_y_cloud",
        "feasible",
        "best",
        "plateau",
    ):
        np.testing.assert_array_equal(ds[name].values, whole[name].values)
    assert ds.attrs["optimisation"] == whole.attrs["optimisation"]
    assert 0 < int(ds["feasible"].sum()) < 12  # the chance constraint separates the candidates
