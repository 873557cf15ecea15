"""The REST API on a real app: the shared 2-worker cluster, a study store in a temporary directory.

One app serves the whole module; one small grid study (3 isolator types x 2 Y accelerations, LTI with
exact discretisation at 2 ms over 2 s) runs once and most tests read it.
"""

from __future__ import annotations

import copy
import csv
import io
import re
import time
import uuid
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest
import xarray as xr
from fastapi.testclient import TestClient

from isolab.engine import simulate
from isolab.service.api.app import create_app
from isolab.service.api.schemas import EXAMPLE_SCENE
from isolab.service.settings import Settings
from isolab.studies.inputs.study import Study
from isolab.studies.results.cases import (
    CaseColumns,
    CaseQueryError,
    filter_mask,
    parse_filter,
    select_cases,
)
from tests.service.conftest import live_app

pytestmark = pytest.mark.slow  # services, clusters or processes of their own: `make test-fast` skips them

G = 9.80665
MAX_CASES = 500


def scene(duration: str = "2 s", fidelity: str = "lti", integrator: str = "exact", dt: str = "2 ms") -> dict:
    s = copy.deepcopy(EXAMPLE_SCENE)
    s["simulation"] = {"fidelity": fidelity, "integrator": integrator, "dt": dt, "duration": duration}
    return s


GRID = {
    "name": "api-grid",
    "scene": scene(),
    "parameters": [
        {"path": "isolators.preset", "values": ["active", "air", "elastomer"]},
        {"path": "stages.y.profile.acceleration", "values": ["1 g", "2 g"]},
    ],
    "design": {"type": "grid"},
}


def wait_done(http: TestClient, study_id: str, timeout: float = 40.0) -> dict:
    deadline = time.monotonic() + timeout
    while True:
        info = http.get(f"/studies/{study_id}").json()
        if info["status"] in ("done", "failed", "cancelled"):
            return info
        assert time.monotonic() < deadline, f"study still {info['status']} after {timeout} s"
        time.sleep(0.1)


@pytest.fixture(scope="module")
def http(tmp_path_factory: pytest.TempPathFactory):
    with live_app(tmp_path_factory, workers=2, max_cases=MAX_CASES) as client:
        yield client


@pytest.fixture(scope="module")
def grid(http: TestClient) -> dict:
    """The grid study, submitted and run to the end: {id, accepted, info}."""
    r = http.post("/studies", json=GRID)
    assert r.status_code == 202, r.text
    accepted = r.json()
    info = wait_done(http, accepted["id"])
    assert info["status"] == "done", info
    return {"id": accepted["id"], "accepted": accepted, "info": info}


@pytest.fixture(scope="module")
def dataset(http: TestClient, grid: dict, tmp_path_factory: pytest.TempPathFactory) -> xr.Dataset:
    r = http.get(f"/studies/{grid['id']}/dataset")
    assert r.status_code == 200
    assert r.headers["content-type"] == "application/x-netcdf"
    path = tmp_path_factory.mktemp("download") / "grid.nc"
    path.write_bytes(r.content)
    with xr.open_dataset(path) as ds:
        return ds.load()


def direct_run(definition: dict, cases: list[int], record: list[int] | None = None):
    """The engine run of some cases, in this process, straight from the definition."""
    study = Study.model_validate(definition)
    sim = study.simulation
    return study, simulate(
        study.batch(cases),
        fidelity=sim.fidelity,
        integrator=sim.integrator,
        dt=sim.dt,
        auto_step=sim.auto_step,
        record=record,
    )


# ------------------------------------------------------------------------------------- submit / run
def test_submit_answers_202_with_links_and_the_study_runs_to_done(http: TestClient, grid: dict) -> None:
    sid = grid["id"]
    accepted = grid["accepted"]
    assert accepted["status"] == "queued" and accepted["n_cases"] == 6
    assert re.fullmatch(r"[0-9a-f]{32}", sid), sid  # 128 random bits, lower-case hex
    assert accepted["links"] == {
        "self": f"/studies/{sid}",
        "dataset": f"/studies/{sid}/dataset",
        "cases": f"/studies/{sid}/cases",
    }
    info = grid["info"]
    assert info["progress"] == {"done": 6, "total": 6, "failed": 0}
    assert info["parameters"] == ["isolator_type", "stage_y_acceleration"]
    assert info["isolator_types"] == ["active", "air", "elastomer"]
    assert (info["fidelity"], info["integrator"]) == ("lti", "exact")
    assert info["created"] <= info["started"] <= info["finished"]
    assert info["error"] is None
    # the stored definition is the validated one, in SI
    definition = info["definition"]
    assert definition["parameters"][1]["values"] == ["1 g", "2 g"]
    assert definition["scene"]["stages"][0]["mass"] == 1000.0
    assert definition["scene"]["simulation"]["dt"] == pytest.approx(0.002)
    assert Study.model_validate(definition).n_cases == 6


def test_dataset_numbers_equal_a_direct_engine_run(dataset: xr.Dataset) -> None:
    assert dataset.peak_displacement.dims == ("isolator_type", "stage_y_acceleration", "axis")
    assert list(dataset.isolator_type.values) == ["active", "air", "elastomer"]
    np.testing.assert_allclose(dataset.stage_y_acceleration.values, [G, 2 * G], rtol=1e-12)
    # case 3 of the grid is (air, 2 g): the last parameter varies fastest
    study, direct = direct_run(GRID, [3])
    assert study.case_values(3) == {"isolator_type": "air", "stage_y_acceleration": pytest.approx(2 * G)}
    cell = dataset.sel(isolator_type="air", stage_y_acceleration=2 * G)
    np.testing.assert_allclose(
        cell.peak_displacement.values, direct.peak_displacement[0], rtol=1e-9, atol=1e-15
    )
    np.testing.assert_allclose(
        cell.peak_isolator_force.values, direct.peak_isolator_force[0], rtol=1e-9, atol=1e-9
    )
    np.testing.assert_allclose(cell.natural_frequency.values, direct.natural_frequency[0], rtol=1e-12)
    assert float(cell.settling_time) == pytest.approx(float(direct.settling_time[0]), rel=1e-9)
    # physics: of the passive mounts, the stiffer moves less under the stage's inertial force; the active
    # ones, softest of all, move less than air mounts because they feed that force forward
    y = dataset.peak_displacement.sel(axis="y", stage_y_acceleration=2 * G)
    assert float(y.sel(isolator_type="elastomer")) < float(y.sel(isolator_type="air"))
    assert float(y.sel(isolator_type="active")) < float(y.sel(isolator_type="air"))
    # the heave mode of mounts tuned to one frequency sits at the preset's vertical frequency
    for kind, fz in (("active", 1.0), ("air", 3.0), ("elastomer", 10.0)):
        f = dataset.natural_frequency.sel(isolator_type=kind, stage_y_acceleration=G).values
        assert np.min(np.abs(f - fz)) < 1e-6 * fz, (kind, f)


def test_parameters_carry_the_unit_they_were_written_in(dataset: xr.Dataset) -> None:
    acc = dataset.stage_y_acceleration
    assert acc.attrs["units"] == "m/s^2" and acc.attrs["display_units"] == "g"  # written "1 g", "2 g"
    assert acc.attrs["scale"] == "linear" and acc.values.tolist() == [G, 2 * G]
    assert "display_units" not in dataset.isolator_type.attrs  # text: nothing to convert


# ------------------------------------------------------------------------------------------ cases
def test_cases_table_has_one_row_per_case_in_case_order(
    http: TestClient, grid: dict, dataset: xr.Dataset
) -> None:
    body = http.get(f"/studies/{grid['id']}/cases").json()
    assert body["n_cases"] == 6 and body["n_matched"] == 6
    rows = body["rows"]
    assert [r["case"] for r in rows] == list(range(6))
    assert [r["isolator_type"] for r in rows] == ["active", "active", "air", "air", "elastomer", "elastomer"]
    assert body["units"]["peak_displacement_y"] == "m" and body["units"]["natural_frequency_1"] == "Hz"
    for r in rows:
        cell = dataset.sel(isolator_type=r["isolator_type"], stage_y_acceleration=r["stage_y_acceleration"])
        assert r["peak_displacement_y"] == float(cell.peak_displacement.sel(axis="y"))
        assert r["min_isolator_load_min"] == float(cell.min_isolator_load.min())
        assert r["liftoff_any"] is bool(cell.liftoff.max())
        assert r["peak_isolator_force_z"] == float(cell.peak_isolator_force.sel(axis="z").max())
        assert [r[f"natural_frequency_{m}"] for m in range(1, 7)] == cell.natural_frequency.values.tolist()
        assert r["status"] == "ok"


def test_cases_filter_sort_columns_and_csv(http: TestClient, grid: dict) -> None:
    url = f"/studies/{grid['id']}/cases"
    everything = http.get(url).json()["rows"]
    y = {r["case"]: r["peak_displacement_y"] for r in everything}
    threshold = sorted(y.values())[3]  # strictly below: three cases
    body = http.get(
        url,
        params={
            "filter": f"peak_displacement_y<{threshold!r},liftoff_any==false",
            "sort": "-peak_displacement_y",
        },
    ).json()
    expected = sorted((c for c in y if y[c] < threshold), key=lambda c: -y[c])
    assert [r["case"] for r in body["rows"]] == expected and body["n_matched"] == 3
    # units in the filter: mm against a column in m
    in_mm = http.get(url, params={"filter": f"peak_displacement_y<{threshold * 1e3!r} mm"}).json()
    assert sorted(r["case"] for r in in_mm["rows"]) == sorted(expected)
    # text equality, AND of two clauses, descending on a parameter
    air = http.get(url, params={"filter": "isolator_type==air,stage_y_acceleration>=1.5 g"}).json()
    assert [r["case"] for r in air["rows"]] == [3]
    sorted_rows = http.get(url, params={"sort": "-stage_y_acceleration,isolator_type"}).json()["rows"]
    assert [r["case"] for r in sorted_rows] == [1, 3, 5, 0, 2, 4]
    # columns, limit and offset
    page = http.get(
        url,
        params={
            "columns": "case,isolator_type,peak_displacement_y",
            "limit": 2,
            "offset": 1,
            "sort": "peak_displacement_y",
        },
    ).json()
    assert page["columns"] == ["case", "isolator_type", "peak_displacement_y"]
    assert [list(r) for r in page["rows"]] == [page["columns"]] * 2
    by_y = sorted(y, key=lambda c: y[c])
    assert [r["case"] for r in page["rows"]] == by_y[1:3] and page["n_matched"] == 6
    # CSV carries the same numbers
    r = http.get(
        url, params={"format": "csv", "columns": "case,isolator_type,peak_displacement_y,liftoff_any"}
    )
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/csv")
    table = list(csv.DictReader(io.StringIO(r.text)))
    # the header carries each column's SI unit; the JSON answer keeps bare names and its units map
    assert list(table[0]) == ["case", "isolator_type", "peak_displacement_y [m]", "liftoff_any"]
    assert [int(row["case"]) for row in table] == list(range(6))
    assert [float(row["peak_displacement_y [m]"]) for row in table] == [y[c] for c in range(6)]
    assert {row["liftoff_any"] for row in table} <= {"true", "false"}


@pytest.mark.parametrize(
    ("params", "field", "words"),
    [
        ({"filter": "peak_displacment_y<0.01"}, "filter", "peak_displacment_y"),
        ({"sort": "-nope"}, "sort", "nope"),
        ({"columns": "case,bogus"}, "columns", "bogus"),
        ({"filter": "isolator_type<air"}, "filter", "isolator_type is text"),
        ({"filter": "peak_displacement_y<<1"}, "filter", "peak_displacement_y"),
        ({"filter": "peak_displacement_y<3 s"}, "filter", "length"),
        ({"filter": "liftoff_any==maybe"}, "filter", "true or false"),
        ({"filter": "case>1,,case<4"}, "filter", "empty clause"),
        ({"filter": "__import__('os')"}, "filter", "cannot read"),
    ],
)
def test_cases_query_errors_name_the_field(
    http: TestClient, grid: dict, params: dict, field: str, words: str
) -> None:
    r = http.get(f"/studies/{grid['id']}/cases", params=params)
    assert r.status_code == 422, r.text
    detail = r.json()["detail"][0]
    assert detail["loc"] == ["query", field]
    assert words in detail["msg"]


def test_filter_language_on_missing_values_and_text() -> None:
    table = CaseColumns()
    table.add("case", np.arange(4), "1", "number", True)
    table.add("kind", np.array(["a", "b", "a", "it's"]), "", "text", True)
    table.add("peak", np.array([1e-3, np.nan, 3e-3, 2e-3]), "m", "number", True)
    table.add("flag", np.array([1.0, 0.0, np.nan, 0.0]), "1", "bool", True)

    def cases(text: str) -> list[int]:
        return np.flatnonzero(filter_mask(table, parse_filter(text, table))).tolist()

    assert cases("peak>=1 mm") == [0, 2, 3]  # the missing value never matches a comparison
    assert cases("peak!=0.002") == [0, 2]
    assert cases("peak==null") == [1]
    assert cases("peak!=null,flag==false") == [3]
    assert cases("flag!=true") == [1, 3]  # missing is neither true nor false
    assert cases("kind=='a',peak<0.0025") == [0]
    assert cases('kind=="it\'s"') == [3]
    assert cases("peak<=2e-3,peak>1e-3") == [3]
    with pytest.raises(CaseQueryError, match="null takes only"):
        parse_filter("peak<null", table)
    with pytest.raises(CaseQueryError, match="not closed"):
        parse_filter("kind=='a", table)
    cols, rows, matched = select_cases(table, "peak!=null", "-peak", "case,peak", 10, 0)
    assert cols == ["case", "peak"] and rows.tolist() == [2, 3, 0] and matched == 3
    _, rows, _ = select_cases(table, None, "peak", None, 10, 0)
    assert rows.tolist() == [0, 3, 2, 1]  # missing last, also when ascending


# ------------------------------------------------------------------------------------- time series
def test_timeseries_recomputes_the_case(
    http: TestClient, grid: dict, dataset: xr.Dataset, tmp_path: Path
) -> None:
    r = http.get(f"/studies/{grid['id']}/cases/3/timeseries")
    assert r.status_code == 200
    body = r.json()
    assert body["parameters"] == {"isolator_type": "air", "stage_y_acceleration": pytest.approx(2 * G)}
    assert body["status"] == "ok"
    assert body["units"] == {
        "time": "s",
        "displacement": "m",
        "rotation": "rad",
        "isolator_force": "N",
        "point_displacement": "m",
        "stage_position": "m",
        "stage_velocity": "m/s",
        "stage_acceleration": "m/s^2",
        "natural_frequency": "Hz",
        "settling_time": "s",
    }
    t = np.array(body["time"])
    assert t[0] == 0.0 and t[-1] == pytest.approx(2.0) and np.allclose(np.diff(t), 0.002)
    cell = dataset.sel(isolator_type="air", stage_y_acceleration=2 * G)
    for k, axis in enumerate("xyz"):
        # the stored peak is the extremum between output samples too: the samples reach it within 0.5 %
        trace = np.abs(np.array(body["displacement"][axis]))
        peak = float(cell.peak_displacement[k])
        assert peak * (1 - 5e-3) - 1e-15 <= trace.max() <= peak * (1 + 1e-12) + 1e-15
    assert sorted(body["isolator_force"]) == ["mount_0", "mount_1", "mount_2", "mount_3"]
    fz = np.array([body["isolator_force"][m]["z"] for m in sorted(body["isolator_force"])])
    peak_fz = cell.peak_isolator_force.sel(axis="z").values
    assert (np.abs(fz).max(axis=1) <= peak_fz * (1 + 1e-12)).all()
    np.testing.assert_allclose(np.abs(fz).max(axis=1), peak_fz, rtol=5e-3)
    assert list(body["point_displacement"]) == ["tool"]
    # the stage profile on the same time axis, the modes and the settling of the same run
    accel = np.array(body["stages"]["y"]["acceleration"])
    assert accel.size == t.size and np.abs(accel).max() == pytest.approx(2 * G)
    np.testing.assert_allclose(
        [m["frequency"] for m in body["modes"]], cell.natural_frequency.values, rtol=1e-9
    )
    assert {m["name"] for m in body["modes"]} >= {"heave"}
    assert body["settling_time"] == pytest.approx(float(cell.settling_time), rel=1e-9)
    # every 10th sample, as netCDF
    r = http.get(f"/studies/{grid['id']}/cases/3/timeseries", params={"format": "netcdf", "every": 10})
    assert r.status_code == 200 and r.headers["content-type"] == "application/x-netcdf"
    (tmp_path / "case.nc").write_bytes(r.content)
    with xr.open_dataset(tmp_path / "case.nc") as ts:
        assert ts.sizes["time"] == 101 and ts.displacement.attrs["units"] == "m"
        np.testing.assert_allclose(ts.displacement.sel(axis="y").values, body["displacement"]["y"][::10])
        assert list(ts.isolator.values) == ["mount_0", "mount_1", "mount_2", "mount_3"]


def test_a_study_asking_for_an_accuracy_recomputes_its_cases_with_the_chosen_model(
    http: TestClient, tmp_path: Path
) -> None:
    s = scene(duration="1.5 s")
    s["simulation"] = {"accuracy": "fast", "duration": "1.5 s"}
    study = {
        "name": "api-accuracy",
        "scene": s,
        "parameters": [{"path": "isolators.preset", "values": ["air", "elastomer"]}],
    }
    r = http.post("/studies", json=study)
    assert r.status_code == 202, r.text
    info = wait_done(http, r.json()["id"], timeout=120)
    assert info["status"] == "done", info
    assert info["fidelity"] in ("lti", "ltv", "nonlinear") and info["integrator"] and info["dt"] > 0
    (tmp_path / "a.nc").write_bytes(http.get(f"/studies/{info['id']}/dataset").content)
    with xr.open_dataset(tmp_path / "a.nc") as ds:
        assert (ds.attrs["fidelity"], ds.attrs["integrator"]) == (info["fidelity"], info["integrator"])
        peak_y = float(ds.peak_displacement.sel(isolator_type="elastomer", axis="y"))
    body = http.get(f"/studies/{info['id']}/cases/1/timeseries").json()
    assert body["status"] == "ok", body["message"]
    t = np.array(body["time"])
    assert np.allclose(np.diff(t), info["dt"])
    # the recomputed trace is the stored case: same model, same step; its samples reach the stored peak
    # (an extremum between samples) within 0.5 %
    assert peak_y * (1 - 5e-3) <= np.abs(body["displacement"]["y"]).max() <= peak_y * (1 + 1e-12)
    # a comparison asking for an accuracy reports and runs the model chosen for it
    r = http.post("/comparisons", json={"scene": s, "isolator_types": ["air", "elastomer"]})
    assert r.status_code == 200, r.text
    sim = r.json()["simulation"]
    assert sim["fidelity"] in ("lti", "ltv", "nonlinear") and sim["accuracy"] is None and sim["dt"] > 0
    assert {row["status"] for row in r.json()["rows"].values()} == {"ok"}


def test_case_plot_is_a_real_png(http: TestClient, grid: dict) -> None:
    r = http.get(f"/studies/{grid['id']}/cases/2/plot.png")
    assert r.status_code == 200 and r.headers["content-type"] == "image/png"
    img = matplotlib.image.imread(io.BytesIO(r.content), format="png")
    assert img.shape[0] > 800 and img.shape[1] > 600
    assert float(img[..., :3].std()) > 0.05  # not blank


def test_study_plots(http: TestClient, grid: dict) -> None:
    url = f"/studies/{grid['id']}/plot.png"
    for params in (
        {"y": "peak_displacement_y", "x": "stage_y_acceleration"},
        {"y": "min_isolator_load_min", "x": "stage_y_acceleration", "x2": "isolator_type"},
    ):
        r = http.get(url, params=params)
        assert r.status_code == 200, r.text
        img = matplotlib.image.imread(io.BytesIO(r.content), format="png")
        assert img.size > 0 and float(img[..., :3].std()) > 0.05
    r = http.get(url, params={"y": "peak_displacement_y", "x": "peak_displacement_x"})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["query", "x"]
    assert "not a varied parameter" in r.json()["detail"][0]["msg"]
    r = http.get(url, params={"y": "peak_displacement_q", "x": "isolator_type"})
    assert r.status_code == 422 and "peak_displacement_q" in r.json()["detail"][0]["msg"]


# -------------------------------------------------------------------------------------- comparisons
def test_compare_three_isolator_types(http: TestClient) -> None:
    r = http.post("/comparisons", json={"scene": scene(), "simulation": {"duration": "1.5 s"}})
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["isolator_types"] == ["active", "air", "elastomer"]
    assert body["simulation"]["duration"] == pytest.approx(1.5)
    rows = body["rows"]
    f1 = {t: rows[t]["natural_frequency_1"] for t in body["isolator_types"]}
    assert f1["active"] < f1["air"] < f1["elastomer"]
    assert body["best"]["natural_frequency_1"] == "active"
    assert body["best"]["peak_displacement_y"] == "elastomer"
    assert body["criteria"]["min_isolator_load_min"] == "highest"
    best_load = max(rows, key=lambda t: rows[t]["min_isolator_load_min"])
    assert body["best"]["min_isolator_load_min"] == best_load
    # the same numbers as the engine gives for that scene under each preset
    _, direct = direct_run(
        {
            "name": "c",
            "scene": scene(duration="1.5 s"),
            "parameters": [{"path": "isolators.preset", "values": ["active", "air", "elastomer"]}],
        },
        [0, 1, 2],
    )
    for i, t in enumerate(body["isolator_types"]):
        assert rows[t]["peak_displacement_y"] == pytest.approx(
            float(direct.peak_displacement[i, 1]), rel=1e-9
        )
        assert rows[t]["status"] == "ok"
    # near-zero X motion of a symmetric scene is numerical noise: no best is claimed for it
    assert "peak_displacement_x" not in body["best"]


def test_compare_refuses_bad_input_naming_the_field(http: TestClient) -> None:
    r = http.post("/comparisons", json={"scene": scene(), "isolator_types": ["air", "steel"]})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"][:2] == ["body", "isolator_types"]
    bad = scene()
    bad["stages"][0]["mass"] = "-5 kg"
    r = http.post("/comparisons", json={"scene": bad})
    assert r.status_code == 422
    assert r.json()["detail"][0]["loc"] == ["body", "scene", "stages", 0, "mass"]


# -------------------------------------------------------------------------------------- simulations
def test_a_single_case_run_now_matches_the_studys_case_0(http: TestClient, grid: dict) -> None:
    """POST /simulations of the scene of the grid's case 0 gives that case's stored row, to round-off."""
    row = http.get(f"/studies/{grid['id']}/cases", params={"columns": "all", "limit": 1}).json()["rows"][0]
    assert row["case"] == 0
    s = scene()
    s["isolators"]["preset"] = row["isolator_type"]
    s["stages"][0]["profile"]["acceleration"] = row["stage_y_acceleration"]  # SI, as stored
    r = http.post("/simulations", json={"scene": s, "max_points": 300})
    assert r.status_code == 200, r.text
    answer = r.json()
    summary = answer["summary"]
    compared = 0
    for column, cell in summary.items():
        if column not in row:
            continue
        if isinstance(cell["value"], float):
            assert cell["value"] == pytest.approx(row[column], rel=1e-9, abs=1e-15), column
        else:
            assert cell["value"] == row[column], column
        compared += 1
    assert compared > 30 and "peak_displacement_y" in summary and "natural_frequency_1" in summary
    assert summary["peak_displacement_y"]["unit"] == "m"
    assert "displacement" in summary["peak_displacement_y"]["long_name"]
    # 2 s at 2 ms: 1001 samples thinned to at most 300, every 4th, the first at t = 0
    assert answer["n_samples"] == 1001 and answer["every"] == 4
    traces = answer["traces"]
    assert len(traces["time"]) == 251 and traces["time"][:2] == pytest.approx([0.0, 0.008])
    assert len(traces["displacement"]["y"]) == 251 and traces["units"]["displacement"] == "m"
    # the thinned trace never exceeds the peak of every step
    assert max(abs(v) for v in traces["displacement"]["y"]) <= summary["peak_displacement_y"]["value"]
    assert answer["isolators"]["mount_0"]["place"] == "front-left"
    assert answer["isolators"]["mount_2"]["place"] == "back-right"
    assert answer["model"] == {**answer["model"], "fidelity": "lti", "integrator": "exact", "dt": 0.002}


# --------------------------------------------------------------------------------- catalog, delete
def test_list_filters(http: TestClient, grid: dict) -> None:
    items = http.get("/studies", params={"name": "api-grid", "status": "done"}).json()
    assert grid["id"] in [s["id"] for s in items["items"]] and items["total"] >= 1
    assert http.get("/studies", params={"isolator_type": "elastomer"}).json()["total"] >= 1
    assert http.get("/studies", params={"name": "api-grid", "status": "failed"}).json()["total"] == 0
    assert http.get("/studies", params={"created_after": "2999-01-01T00:00:00Z"}).json()["items"] == []
    r = http.get("/studies", params={"limit": 501})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["query", "limit"]
    r = http.get("/studies", params={"created_after": "yesterday"})
    assert r.status_code == 422 and "created_after" in r.json()["detail"][0]["msg"]


def test_delete_of_a_running_study_removes_it_for_every_route_at_once(http: TestClient) -> None:
    long = {
        "name": "api-long",
        "scene": scene(duration="6 s", fidelity="ltv", integrator="rk4", dt="1 ms"),
        "parameters": [{"path": "isolators.f_vertical", "range": {"start": "2 Hz", "stop": "6 Hz"}}],
        "design": {"type": "lhs", "samples": 400},
    }
    sid = http.post("/studies", json=long).json()["id"]
    r = http.get(f"/studies/{sid}/dataset")
    assert r.status_code == 409 and "its results exist once it is done" in r.json()["detail"]
    assert http.get(f"/studies/{sid}/cases").status_code == 409
    t0 = time.monotonic()
    assert http.delete(f"/studies/{sid}").status_code == 204
    assert time.monotonic() - t0 < 5.0  # the request does not wait for the running chunk
    for path in ("", "/dataset", "/cases", "/cases/0/timeseries", "/cases/0/plot.png"):
        assert http.get(f"/studies/{sid}{path}").status_code == 404, path
    assert http.delete(f"/studies/{sid}").status_code == 404
    jobs = http.app.state.jobs  # type: ignore[attr-defined]
    deadline = time.monotonic() + 60
    while jobs.is_active(sid):  # it stops at its next chunk, and leaves no file behind
        assert time.monotonic() < deadline
        time.sleep(0.1)
    store = jobs.store
    assert not store.chunk_dir(sid).exists() and not store.path(sid).exists()


@pytest.mark.parametrize(
    "path",
    [
        "/studies/{id}",
        "/studies/{id}/dataset",
        "/studies/{id}/cases",
        "/studies/{id}/cases/0/timeseries",
        "/studies/{id}/cases/0/plot.png",
        "/studies/{id}/plot.png?y=peak_displacement_y&x=isolator_type",
    ],
)
def test_unknown_and_malformed_ids_are_404(http: TestClient, path: str) -> None:
    for study_id in (uuid.uuid4().hex, "not-an-id", "0" * 31 + "G", "..%2F..%2Fcatalog"):
        r = http.get(path.replace("{id}", study_id))
        assert r.status_code == 404, (path, study_id, r.status_code)
    assert http.delete(f"/studies/{uuid.uuid4().hex}").status_code == 404


def test_unknown_case_is_404(http: TestClient, grid: dict) -> None:
    r = http.get(f"/studies/{grid['id']}/cases/6/timeseries")
    assert r.status_code == 404 and "cases 0..5" in r.json()["detail"]


# ------------------------------------------------------------------------------------- bad studies
def _with(**changes) -> dict:
    d = copy.deepcopy(GRID)
    d.update(changes)
    return d


@pytest.mark.parametrize(
    ("definition", "loc", "words"),
    [
        (_with(design={"type": "lhs"}), ["body", "design", "samples"], "needs the number of samples"),
        (
            _with(parameters=[{"path": "isolators.nope", "values": [1, 2]}]),
            ["body", "parameters", 0, "path"],
            "does not exist",
        ),
        (_with(scene_file="article-scriber.yaml"), ["body", "scene_file"], "inline"),
        (_with(scene=None), ["body"], "scene"),
        (_with(colour="red"), ["body", "colour"], "Extra inputs"),
        (
            _with(
                parameters=[{"path": "stages.y.mass", "range": {"start": "1 kg", "stop": "9 kg", "num": 501}}]
            ),
            ["body", "parameters"],
            f"limit of {MAX_CASES}",
        ),
        (
            _with(
                parameters=[{"path": "stages.y.mass", "range": {"start": "1 kg", "stop": "9 kg"}}],
                design={"type": "sobol", "samples": 1024},
            ),
            ["body", "design", "samples"],
            "1024 cases",
        ),
    ],
)
def test_bad_definition_is_422_naming_the_field(
    http: TestClient, definition: dict, loc: list, words: str
) -> None:
    r = http.post("/studies", json=definition)
    assert r.status_code == 422, r.text
    details = r.json()["detail"]
    assert any(d["loc"][: len(loc)] == loc and words in d["msg"] for d in details), details


def test_bad_scene_value_names_its_path(http: TestClient) -> None:
    d = copy.deepcopy(GRID)
    d["scene"]["stages"][0]["mass"] = "-3 kg"
    r = http.post("/studies", json=d)
    assert r.status_code == 422
    assert r.json()["detail"][0]["loc"] == ["body", "scene", "stages", 0, "mass"]
    r = http.post("/studies", content=b"[1, 2]", headers={"content-type": "application/json"})
    assert r.status_code == 422


def test_openapi_has_an_example_for_every_body(http: TestClient) -> None:
    spec = http.get("/openapi.json").json()
    for path, method in (("/studies", "post"), ("/comparisons", "post")):
        content = spec["paths"][path][method]["requestBody"]["content"]["application/json"]
        assert content.get("examples"), path
    for example in spec["paths"]["/studies"]["post"]["requestBody"]["content"]["application/json"][
        "examples"
    ].values():
        assert Study.model_validate(example["value"]).n_cases > 0


def test_token_and_body_limit_without_a_cluster(tmp_path: Path) -> None:
    app = create_app(Settings(data_dir=tmp_path, api_token="s3cret", max_body_bytes=2048))
    plain = TestClient(app)  # no lifespan: no cluster needed for these answers
    assert plain.get("/studies").status_code == 401
    assert plain.get("/studies", headers={"Authorization": "Bearer wrong"}).status_code == 401
    r = plain.post("/studies", json={"name": "x" * 4096}, headers={"Authorization": "Bearer s3cret"})
    assert r.status_code == 413 and "2048" in r.json()["detail"]
    assert plain.get("/health").status_code == 503  # open, and says it has no Dask client
