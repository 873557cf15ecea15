"""Design criteria: parsing with units, per-case margins read from the stored outputs, the engine's
per-point settling tolerance, filtering on ``meets_criteria``, and the recommended isolator type."""

from __future__ import annotations

import copy

import numpy as np
import pytest
from pydantic import ValidationError

from isolab.engine import simulate
from isolab.service.api.schemas import EXAMPLE_SCENE
from isolab.studies.answers.comparisons import COST_ORDER, compare, comparison_frame, recommend
from isolab.studies.inputs.schema import error_messages
from isolab.studies.inputs.study import load_scene, scene_batch, study_labels, validate_study
from isolab.studies.questions.criteria import (
    Criteria,
    add_criteria,
    criterion_margin,
    judged_criteria,
    margins,
)
from isolab.studies.results.cases import case_table, filter_mask, parse_filter
from isolab.studies.results.dataset import to_dataset


def scene(**criteria) -> dict:
    s = copy.deepcopy(EXAMPLE_SCENE)
    s["simulation"] = {"fidelity": "lti", "integrator": "exact", "dt": "2 ms", "duration": "2.5 s"}
    if criteria:
        s["criteria"] = criteria
    return s


def messages(err: pytest.ExceptionInfo) -> list[str]:
    return error_messages(err.value)


# ---------------------------------------------------------------------------------------------- parsing
def test_criteria_read_units_and_name_each_limit() -> None:
    sc = load_scene(
        scene(
            tool={"displacement": "10 um", "settle": {"within": "5 um", "after": "500 ms"}},
            isolators={"no_liftoff": True, "max_force": "20 kN", "max_deflection": "5 mm"},
        )
    )
    c = sc.criteria
    assert c is not None
    assert c.points["tool"].displacement == pytest.approx(10e-6)
    assert c.points["tool"].settle.within == pytest.approx(5e-6)
    assert c.points["tool"].settle.after == pytest.approx(0.5)
    assert c.isolators.max_force == pytest.approx(20e3)
    assert c.isolators.max_deflection == pytest.approx(5e-3)
    assert c.names() == [
        "tool_displacement",
        "tool_settle",
        "isolators_no_liftoff",
        "isolators_max_force",
        "isolators_max_deflection",
    ]
    assert c.settle_tolerances() == {"tool": pytest.approx(5e-6)}
    # each described in words, the settling band in a unit that reads at its size
    assert [j.description for j in judged_criteria(c)][:2] == [
        "peak displacement of tool",
        "tool back within 5 um of rest after each move",
    ]


@pytest.mark.parametrize(
    ("criteria", "expected"),
    [
        ({"tol": {"displacement": "10 um"}}, "criteria.tol: no point of interest named 'tol'"),
        ({"tool": {"displacement": "10 kg"}}, "criteria.tool.displacement: expected a length"),
        ({"tool": {"displacement": "-1 um"}}, "criteria.tool.displacement: Input should be greater than 0"),
        ({"tool": {"velocity": "VC-H"}}, "criteria.tool.velocity: unknown vibration criterion 'VC-H'"),
        ({"tool": {"velocity": "VC-C"}}, "criteria.tool.velocity: judging VC-C needs the floor's vibration"),
        ({"tool": {"settle": {"within": "5 um"}}}, "criteria.tool.settle.after: Field required"),
        ({"isolators": {"max_force": "2 m"}}, "criteria.isolators.max_force: expected a force"),
        ({"isolators": {"lift": True}}, "criteria.isolators.lift: Extra inputs are not permitted"),
    ],
)
def test_bad_criteria_name_the_field(criteria: dict, expected: str) -> None:
    with pytest.raises(ValidationError) as err:
        load_scene(scene(**criteria))
    assert any(m.startswith(expected) for m in messages(err)), messages(err)


def test_a_study_replaces_the_scene_criteria_and_checks_its_points() -> None:
    body = {
        "name": "c",
        "scene": scene(tool={"displacement": "1 um"}),
        "criteria": {"tool": {"displacement": "2 mm"}},
    }
    study = validate_study(body)
    assert study.criteria.points["tool"].displacement == pytest.approx(2e-3)
    # every case carries the block it is judged by
    assert study.case_scene(0).criteria.points["tool"].displacement == pytest.approx(2e-3)
    body["criteria"] = {"camera": {"displacement": "2 mm"}}
    with pytest.raises(ValidationError) as err:
        validate_study(body)
    assert "criteria.camera: no point of interest named 'camera' (points: tool)" in str(err.value)


def test_settle_criterion_sets_the_point_tolerance_the_engine_measures_to() -> None:
    long = scene(tool={"settle": {"within": "3 um", "after": "1 s"}})
    long["simulation"]["duration"] = "8 s"  # long enough to settle to either tolerance
    judged, _ = scene_batch(load_scene(long))
    del long["criteria"]
    plain, _ = scene_batch(load_scene(long))
    assert plain.point_settle_tol[0, 0] == pytest.approx(plain.settle_tol[0])
    assert judged.point_settle_tol[0, 0] == pytest.approx(3e-6)
    # a tighter tolerance takes longer to reach: the engine measured to the criterion's tolerance
    r_plain = simulate(plain, "lti", "exact", 2e-3)
    r_judged = simulate(judged, "lti", "exact", 2e-3)
    t_plain, t_judged = r_plain.point_settling_time[0, 0], r_judged.point_settling_time[0, 0]
    rest = 8.0 - plain.last_move_end()[0]
    assert 0 < t_plain < t_judged < rest - 0.1


# ---------------------------------------------------------------------------------------------- margins
@pytest.fixture(scope="module")
def grid_dataset():
    """A grid over isolator type and Y acceleration with criteria at the tool and on the mounts."""
    body = {
        "name": "criteria-grid",
        "scene": scene(
            tool={"displacement": "1 mm", "settle": {"within": "20 um", "after": "1 s"}},
            isolators={"no_liftoff": True, "max_force": "35 kN", "max_deflection": "4 mm"},
        ),
        "parameters": [
            {"path": "isolators.preset", "values": ["active", "air", "elastomer"]},
            {"path": "stages.y.profile.acceleration", "values": ["0.5 g", "2 g"]},
        ],
        "design": {"type": "grid"},
    }
    body["scene"]["simulation"]["duration"] = "5 s"
    study = validate_study(body)
    result = simulate(study.batch(np.arange(study.n_cases)), "lti", "exact", 2e-3)
    iso, pts = study_labels(study)
    ds = to_dataset(result, study.design(), isolator_names=iso, point_names=pts)
    return add_criteria(ds, study.criteria), study


def test_margins_are_the_stored_outputs_against_the_limits(grid_dataset) -> None:
    ds, _ = grid_dataset
    m = ds["criterion_margin"]
    assert m.attrs["units"] == "1" and "positive: met" in m.attrs["long_name"]
    peak = ds["peak_point_displacement"].sel(point="tool").max("axis")
    np.testing.assert_allclose(m.sel(criterion="tool_displacement"), 1 - peak / 1e-3, rtol=1e-12)
    settle = ds["point_settling_time"].sel(point="tool")
    np.testing.assert_allclose(m.sel(criterion="tool_settle"), 1 - settle / 1.0, rtol=1e-12)
    keep = (ds["min_isolator_load"] / ds["static_isolator_load"]).min("isolator")
    np.testing.assert_allclose(m.sel(criterion="isolators_no_liftoff"), keep, rtol=1e-12)
    load = ds["max_isolator_load"].max("isolator")
    np.testing.assert_allclose(m.sel(criterion="isolators_max_force"), 1 - load / 35e3, rtol=1e-12)
    defl = ds["peak_isolator_deflection"].max(["isolator", "axis"])
    np.testing.assert_allclose(m.sel(criterion="isolators_max_deflection"), 1 - defl / 4e-3, rtol=1e-12)
    meets = (m >= 0).all("criterion")
    np.testing.assert_array_equal(ds["meets_criteria"].values == 1, meets.values)
    # harder acceleration: larger motion, smaller displacement margin, for every isolator type
    d = m.sel(criterion="tool_displacement")
    assert (d.isel(stage_y_acceleration=1) < d.isel(stage_y_acceleration=0)).all()
    # the max load includes the preload: a quarter of the weight at least on the heaviest mount
    assert (load > ds["static_isolator_load"].max("isolator")).all()
    assert criterion_margin(
        ds, {"isolator_type": "air", "stage_y_acceleration": 2 * 9.80665}, "tool_settle"
    ) == (
        pytest.approx(float(m.sel(criterion="tool_settle", isolator_type="air").isel(stage_y_acceleration=1)))
    )
    with pytest.raises(KeyError, match="no such criterion"):
        criterion_margin(ds, {"isolator_type": "air", "stage_y_acceleration": 4.903325}, "tool_speed")


def test_a_case_that_did_not_end_ok_has_no_margin_and_does_not_meet(grid_dataset) -> None:
    ds, study = grid_dataset
    broken = ds.copy(deep=True)
    broken["status"][{"isolator_type": 0, "stage_y_acceleration": 0}] = 1  # unstable
    m = margins(broken, study.criteria)
    assert np.isnan(m.isel(isolator_type=0, stage_y_acceleration=0)).all()
    again = add_criteria(broken.drop_vars(["criterion_margin", "meets_criteria"]), study.criteria)
    assert np.isnan(float(again["meets_criteria"].isel(isolator_type=0, stage_y_acceleration=0)))


def test_meets_criteria_is_a_case_table_column_to_filter_on(grid_dataset) -> None:
    ds, _ = grid_dataset
    table = case_table(ds)
    assert table.kinds["meets_criteria"] == "bool"
    assert table.units["margin_tool_displacement"] == "1"
    rows = filter_mask(table, parse_filter("meets_criteria==true", table))
    expected = ds["meets_criteria"].values.reshape(-1) == 1
    np.testing.assert_array_equal(rows, expected)
    assert 0 < rows.sum() < rows.size  # the limits were chosen so that some cases pass and some fail


def test_criteria_round_trip_through_netcdf(grid_dataset, tmp_path) -> None:
    import xarray as xr

    from isolab.studies.results.store import netcdf_encoding

    ds, _ = grid_dataset
    path = tmp_path / "c.nc"
    ds.to_netcdf(path, encoding=netcdf_encoding(ds))
    back = xr.load_dataset(path)
    np.testing.assert_allclose(back["criterion_margin"], ds["criterion_margin"])
    assert Criteria.model_validate_json(back.attrs["criteria"]).names() == list(ds["criterion"].values)


# ------------------------------------------------------------------------------------- recommendation
def rows(**meets: tuple[bool, float]) -> dict:
    return {
        t: {"meets_criteria": ok, "margin_tool_displacement": m, "status": "ok"}
        for t, (ok, m) in meets.items()
    }


def test_recommend_the_cheapest_type_that_meets_every_criterion() -> None:
    r = recommend(rows(active=(True, 0.5), air=(True, 0.1), elastomer=(False, -0.2)), ["tool_displacement"])
    assert r["isolator_type"] == "air"
    assert "cheapest" in r["reason"] and "elastomer fails tool_displacement (-20%)" in r["reason"]
    # the user's own cost order
    r = recommend(
        rows(active=(True, 0.5), air=(True, 0.1), elastomer=(False, -0.2)),
        ["tool_displacement"],
        ["active", "air", "elastomer"],
    )
    assert r["isolator_type"] == "active"
    r = recommend(rows(active=(False, -0.1), air=(False, -0.5)), ["tool_displacement"])
    assert r["isolator_type"] is None and "Closest: active" in r["reason"]
    r = recommend(rows(active=(True, 0.5)), [])
    assert r["isolator_type"] is None and "no criteria" in r["reason"]
    assert COST_ORDER == ("elastomer", "air", "active")


def test_compare_answers_margins_and_one_recommendation() -> None:
    s = scene(
        tool={"settle": {"within": "50 um", "after": "1.5 s"}},
        isolators={"no_liftoff": True, "max_deflection": "5 mm"},
    )
    answer = compare(s, ["active", "air", "elastomer"])
    df = comparison_frame(answer)
    assert list(df.index) == ["active", "air", "elastomer"]
    assert {"meets_criteria", "margin_tool_settle", "margin_isolators_max_deflection"} <= set(df.columns)
    rec = df.attrs["recommendation"]
    meeting = [t for t in COST_ORDER if df.at[t, "meets_criteria"]]
    assert rec["isolator_type"] == (meeting[0] if meeting else None)
    assert [r["name"] for r in df.attrs["requirements"]] == [
        "tool_settle",
        "isolators_no_liftoff",
        "isolators_max_deflection",
    ]
    # the margins agree with the outputs in the same table
    assert df.at["air", "margin_tool_settle"] == pytest.approx(
        1 - df.at["air", "point_settling_time_tool"] / 1.5
    )


# ------------------------------------------------------------------------------------------------ tuning
def test_tuning_stiffens_air_mounts_to_limit_their_deflection() -> None:
    from isolab.studies.answers.tuning import TUNING_RANGES, tune, worst_margins

    s = scene(isolators={"max_deflection": "4 mm"})
    found = tune(s, "air", generations=6, population=8)
    # the stroke a stage move costs falls with stiffness: the search goes to the stiff end of the range
    fh_lo, fh_hi = TUNING_RANGES["air"]["f_horizontal"]
    assert found.values["f_horizontal"] > fh_lo + 0.8 * (fh_hi - fh_lo)
    catalogue = worst_margins(s, "air", np.array([[3.0, 3.0, 0.1]]))[0]
    assert found.worst_margin >= catalogue
    again = worst_margins(
        s, "air", np.array([[found.values[k] for k in ("f_vertical", "f_horizontal", "zeta")]])
    )
    assert again[0] == pytest.approx(found.worst_margin, rel=1e-9)
    assert found.evaluations >= 8


def test_compare_with_tuning_reports_the_values_and_judges_the_tuned_types() -> None:
    s = scene(isolators={"max_deflection": "4 mm"})
    answer = compare(s, ["air", "elastomer"], tune=True)
    assert set(answer["tuning"]) == {"air", "elastomer"}
    for t, found in answer["tuning"].items():
        assert answer["rows"][t]["margin_isolators_max_deflection"] == pytest.approx(
            found["worst_margin"], rel=1e-6
        )
    from isolab.studies.inputs.definitions import DefinitionError

    with pytest.raises(DefinitionError) as err:
        compare(scene(), ["air"], tune=True)
    assert err.value.details[0]["loc"] == ["body", "tune"]


def test_velocity_criterion_judges_the_floor_induced_velocity_against_the_vc_level() -> None:
    from isolab.studies.questions.floor import VC_LEVELS

    s = scene(tool={"velocity": "vc-c"})
    s["floor"] = {"spectrum": {"x": "VC-D", "y": "VC-D", "z": "VC-D"}}
    answer = compare(s, ["active", "air", "elastomer"])
    assert [r["limit"] for r in answer["requirements"]] == [pytest.approx(VC_LEVELS["VC-C"])]
    assert VC_LEVELS["VC-C"] == pytest.approx(12.5e-6)
    for t, row in answer["rows"].items():
        v = row["floor_point_velocity_tool"]
        assert v > 0
        assert row["margin_tool_velocity"] == pytest.approx(1 - v / 12.5e-6, rel=1e-12), t
    # soft, heavily damped active mounts pass VC-C on a VC-D floor; stiff, lightly damped elastomer
    # amplifies the floor near its 10 Hz resonance and does not
    assert answer["rows"]["active"]["meets_criteria"] is True
    assert answer["rows"]["elastomer"]["meets_criteria"] is False


def test_a_study_may_put_the_scene_on_another_floor() -> None:
    body = {
        "name": "f",
        "scene": scene(),
        "floor": {"spectrum": {"z": "VC-B"}},
        "criteria": {"tool": {"velocity": "VC-A"}},
    }
    study = validate_study(body)
    assert study.scene.has_floor_spectrum() and study.case_scene(0).has_floor_spectrum()
    batch = study.batch([0])
    assert batch.floor_band_velocity[0, 2].max() == pytest.approx(25e-6)  # VC-B in every band, along Z only
    assert batch.floor_band_velocity[0, :2].max() == 0.0
    del body["floor"]  # the velocity criterion then has no floor vibration to judge
    with pytest.raises(
        ValidationError, match=r"criteria.tool.velocity: judging VC-A needs the floor's vibration"
    ):
        validate_study(body)
