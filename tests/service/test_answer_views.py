"""The JSON behind the page's answer views: floor spectra at every point against the VC curves (of a scene
under several isolator types, and of a stored study's case), a calibration job's decimated traces, and the
time response of an optimisation's (and a robust optimisation's) candidates, recomputed from the values
its dataset stores.
"""

from __future__ import annotations

import copy
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from fastapi.testclient import TestClient

from isolab.engine import simulate
from isolab.service.api.schemas import EXAMPLE_CALIBRATION, EXAMPLE_SCENE
from isolab.studies.answers.calibration.jobs import MAX_TRACE_POINTS
from isolab.studies.answers.floor_response import velocity_spectra
from isolab.studies.inputs.study import Study, validate_study
from isolab.studies.questions.floor import ISO_LEVELS, VC_LEVELS
from tests.service.conftest import live_app

pytestmark = pytest.mark.slow  # a service (on the shared 1-worker cluster)

SITE = {
    "bands": {
        "1 Hz": "3 um/s",
        "4 Hz": "6 um/s",
        "16 Hz": "30 um/s",
        "31.5 Hz": "30 um/s",
        "63 Hz": "10 um/s",
    }
}
DENSITY = "machine.block.density"


def scene(floor: bool = True) -> dict:
    s = copy.deepcopy(EXAMPLE_SCENE)
    s["simulation"] = {"fidelity": "lti", "integrator": "exact", "dt": "2 ms", "duration": "1 s"}
    s["points"] = {"tool": ["1.3 m", "0.6 m", "0.6 m"], "camera": ["0.4 m", "3.8 m", "0.5 m"]}
    if floor:
        s["floor"] = {"spectrum": {"x": SITE, "y": SITE, "z": SITE}}
        s["criteria"] = {"tool": {"velocity": "VC-C"}}
    return s


def optimisation(robust: bool = False) -> dict:
    design = {
        "type": "optimize",
        "objective": "minimize peak_displacement.y",
        "budget": 8 if robust else 16,
        "population": 4 if robust else 8,
        "seed": 1,
    }
    d = {
        "name": "robust-views" if robust else "optimise-views",
        "scene": scene(floor=False),
        "parameters": [
            {"path": "isolators.f_horizontal", "range": {"start": "1.5 Hz", "stop": "6 Hz"}},
            {"path": "isolators.zeta", "range": {"start": "2 %", "stop": "40 %"}},
        ],
        "design": design,
    }
    if robust:
        d["tolerances"] = {DENSITY: {"distribution": "uniform", "within": "20 %"}}
        design["robust"] = {"samples": 3, "require": "50 %"}
        design["constraints"] = ["peak_displacement.y <= 50 mm"]
    return d


def wait(http: TestClient, path: str, seconds: float = 110.0) -> dict:
    deadline = time.monotonic() + seconds
    while (info := http.get(path).json())["status"] in ("queued", "running"):
        assert time.monotonic() < deadline, info
        time.sleep(0.2)
    return info


@pytest.fixture(scope="module")
def http(tmp_path_factory: pytest.TempPathFactory):
    with live_app(tmp_path_factory, workers=1, max_cases=2000) as client:
        yield client


def submitted(http: TestClient, definition: dict) -> str:
    r = http.post("/studies", json=definition)
    assert r.status_code == 202, r.text
    info = wait(http, f"/studies/{r.json()['id']}")
    assert info["status"] == "done", info
    return r.json()["id"]


def stored(http: TestClient, study_id: str, tmp_path: Path) -> xr.Dataset:
    path = tmp_path / f"{study_id}.nc"
    path.write_bytes(http.get(f"/studies/{study_id}/dataset").content)
    with xr.open_dataset(path) as ds:
        return ds.load()


# ------------------------------------------------------------------------------------------- floor
def test_floor_spectra_of_a_comparison_are_the_point_responses_against_the_vc_curves(
    http: TestClient,
) -> None:
    body = {"scene": scene(), "isolator_types": ["air", "elastomer"]}
    r = http.post("/comparisons/floor", json=body)
    assert r.status_code == 200, r.text
    a = r.json()
    assert (
        a["unit"] == "m/s"
        and a["points"] == ["tool", "camera"]
        and a["isolator_types"] == ["air", "elastomer"]
    )
    assert a["criteria"] == {"tool": "VC-C"}
    assert {c["name"]: c["velocity"] for c in a["curves"]} == {**VC_LEVELS, **ISO_LEVELS}
    assert a["nominal_centres"][0] == 1.0 and a["nominal_centres"][-1] == 80.0 and len(a["band_edges"]) == 21
    # the floor's own spectrum: 30 um/s in the 16 .. 31.5 Hz bands, zero above 63 Hz
    assert a["floor"]["z"][12] == pytest.approx(30e-6) and a["floor"]["z"][19] == 0.0
    for point in ("tool", "camera"):
        direct = velocity_spectra(body["scene"], ["air", "elastomer"], point)
        for t in ("air", "elastomer"):
            got = np.array([a["velocity"][t][point][axis] for axis in "xyz"], dtype=float)
            np.testing.assert_allclose(got, direct["velocity"][t], rtol=1e-12, atol=0)
            assert a["worst"][t][point]["velocity"] == pytest.approx(direct["worst"][t][0], rel=1e-12)
    # an elastomer mount (about 10 Hz) passes the building's 16-31.5 Hz resonance on; an air mount does not
    assert max(a["velocity"]["elastomer"]["tool"]["z"]) > 3 * max(a["velocity"]["air"]["tool"]["z"])


def test_floor_spectra_refuse_a_scene_without_a_floor_and_tuning_naming_the_field(http: TestClient) -> None:
    r = http.post("/comparisons/floor", json={"scene": scene(floor=False)})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "scene", "floor"], r.text
    r = http.post("/comparisons/floor", json={"scene": scene(), "tune": True})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "tune"], r.text


def test_floor_spectra_of_a_stored_case_are_its_own_isolators(http: TestClient) -> None:
    definition = {
        "name": "floor-views",
        "scene": scene(),
        "parameters": [{"path": "isolators.preset", "values": ["active", "air", "elastomer"]}],
        "design": {"type": "grid"},
    }
    sid = submitted(http, definition)
    study = validate_study(definition)
    for case, preset in enumerate(["active", "air", "elastomer"]):
        r = http.get(f"/studies/{sid}/cases/{case}/floor")
        assert r.status_code == 200, r.text
        a = r.json()
        assert a["isolator_types"] == [preset] and a["case"] == case and a["criteria"] == {"tool": "VC-C"}
        direct = velocity_spectra(study, None, "camera", case=case)
        got = np.array([a["velocity"][preset]["camera"][axis] for axis in "xyz"], dtype=float)
        np.testing.assert_allclose(got, direct["velocity"][preset], rtol=1e-9)
    r = http.get(f"/studies/{sid}/cases/3/floor")
    assert r.status_code == 404
    plain = submitted(http, {**definition, "name": "no-floor", "scene": scene(floor=False)})
    r = http.get(f"/studies/{plain}/cases/0/floor")
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["path", "case"], r.text


# ------------------------------------------------------------------------------------- calibration
def test_a_calibration_job_stores_its_traces_decimated(http: TestClient) -> None:
    r = http.post("/calibrations", json=EXAMPLE_CALIBRATION)
    assert r.status_code == 202, r.text
    info = wait(http, f"/calibrations/{r.json()['id']}")
    assert info["status"] == "done", info
    result = info["result"]
    traces = result["traces"]
    t = np.array(traces["time"])
    assert 10 < t.size <= MAX_TRACE_POINTS and np.all(np.diff(t) > 0)
    assert [c["name"] for c in traces["channels"]] == [c["name"] for c in result["channels"]]
    for trace, channel in zip(traces["channels"], result["channels"], strict=True):
        measured, before, after = (np.array(trace[k], dtype=float) for k in ("measured", "before", "after"))
        assert measured.size == before.size == after.size == t.size
        # the thinned traces hold the misfits the fit reports: the calibrated scene close, the given one not
        rms_after = np.sqrt(np.mean((after - measured) ** 2))
        rms_before = np.sqrt(np.mean((before - measured) ** 2))
        assert rms_after == pytest.approx(channel["rms_after"], rel=0.2)
        assert rms_before == pytest.approx(channel["rms_before"], rel=0.2)
        assert rms_after < 0.2 * rms_before


# ------------------------------------------------------------------------------- optimisation cases
def direct_history(definition: dict, values: dict[str, float]):
    """The engine run of one candidate's values on the study's scene, with its histories recorded."""
    body = {k: v for k, v in definition.items() if k not in ("design", "tolerances")}
    body["design"] = {"type": "list", "cases": [values]}
    study = Study.model_validate(body)
    sim = study.simulation
    return simulate(study.batch([0]), sim.fidelity, sim.integrator, sim.dt, record=[0])


@pytest.mark.parametrize("robust", [False, True], ids=["optimisation", "robust optimisation"])
def test_an_optimisation_case_recomputes_the_candidate_it_stored(
    http: TestClient, tmp_path: Path, robust: bool
) -> None:
    definition = optimisation(robust)
    sid = submitted(http, definition)
    ds = stored(http, sid, tmp_path)
    n = ds.sizes["case"]
    assert n > 3  # more candidates than the three cases an optimize design is checked with
    for case in (n - 1, int(json_best(http, sid))):
        r = http.get(f"/studies/{sid}/cases/{case}/timeseries")
        assert r.status_code == 200, r.text
        body = r.json()
        values = {k: float(ds[k].values[case]) for k in ("isolator_f_horizontal", "isolator_zeta")}
        assert body["parameters"] == pytest.approx(values, rel=1e-12)
        h = direct_history(definition, values).history
        np.testing.assert_allclose(
            np.array(body["displacement"]["y"]), h["displacement"][0, : len(body["time"]), 1]
        )
        peak = float(ds.peak_displacement.sel(axis="y").values[case])  # the nominal case, as stored
        assert np.abs(body["displacement"]["y"]).max() == pytest.approx(peak, rel=5e-3)
    assert http.get(f"/studies/{sid}/cases/{n}/timeseries").status_code == 404
    report = http.get(f"/studies/{sid}/report.html")
    assert report.status_code == 200 and "Time response of case" in report.text


def json_best(http: TestClient, study_id: str) -> int:
    return http.get(f"/studies/{study_id}/answer").json()["optimisation"]["best_case"]


# ------------------------------------------------------------------------------ client and command line
def test_the_client_passes_the_tolerance_fields_and_the_calibration_settings(http: TestClient) -> None:
    from isolab.service.client import Client

    api = Client("http://testserver")
    api._http = http  # the app in this process: TestClient is an httpx.Client
    s = scene(floor=False)
    s["criteria"] = {"tool": {"displacement": "2 mm"}}
    s["tolerances"] = {"isolators.zeta": {"distribution": "uniform", "within": "60 %"}}
    df = api.compare(s, types=["active", "elastomer"], samples=24, require=0.5, seed=5)
    robustness = df.attrs["robustness"]
    assert (robustness["samples"], robustness["seed"], robustness["require"]) == (24, 5, 0.5)
    assert {robustness["types"][t]["nominal"]["cases"] for t in ("active", "elastomer")} == {24}
    assert df.attrs["recommendation"]["require"] == 0.5

    m = EXAMPLE_CALIBRATION["measurement"]
    measurement = {"time": m["time"], "time_unit": "s", "channels": m["channels"]}
    fit = ["isolators.f_horizontal=1 Hz:6 Hz"]
    a = api.calibrate(
        EXAMPLE_CALIBRATION["scene"], measurement, fit, noise={"cg.y.displacement": "0.05 mm"}, starts=3
    )
    assert a["starts"]["count"] == 3 and a["goodness_of_fit"]["channels"][0]["noise"] == "stated"
    assert abs(a["parameters"][0]["value"] - 3.6) < 0.01


def test_isolab_run_counts_the_cases_a_robust_optimisation_simulated(tmp_path: Path) -> None:
    import yaml
    from typer.testing import CliRunner

    from isolab.service.cli import app as cli_app

    definition = optimisation(robust=True)
    (tmp_path / "robust.yaml").write_text(yaml.safe_dump(definition))
    r = CliRunner().invoke(
        cli_app, ["run", str(tmp_path / "robust.yaml"), "-o", str(tmp_path / "r.nc"), "--workers", "1"]
    )
    assert r.exit_code == 0, r.output
    with xr.open_dataset(tmp_path / "r.nc") as ds:
        candidates = ds.sizes["case"]
    samples = definition["design"]["robust"]["samples"]
    assert f"{candidates * (samples + 1)} cases simulated ({candidates} candidates) in " in r.output, r.output
