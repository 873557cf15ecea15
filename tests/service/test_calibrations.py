"""``/calibrations`` as jobs on the Dask workers, ``Client.calibrate`` and ``isolab calibrate``.

The measurement is :data:`EXAMPLE_CALIBRATION`'s: the example scene's c.g. in Y at 20 Hz, recorded by a
tracker that started 0.1 s before the stage, on mounts 3.6 Hz sideways instead of the air preset's 3 Hz.
The service runs with its lifespan: one Dask worker process fits the calibrations.
"""

from __future__ import annotations

import base64
import copy
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from fastapi.testclient import TestClient
from typer.testing import CliRunner

from isolab.service.api.app import create_app
from isolab.service.api.schemas import EXAMPLE_CALIBRATION
from isolab.service.cli import app as cli_app
from isolab.service.client import Client, ClientError
from isolab.service.settings import Settings
from isolab.studies.answers.calibration import calibrate_request, measurement_csv, measurement_from_columns
from isolab.studies.answers.calibration.jobs import MAX_CALIBRATION_SECONDS, estimate_cost
from isolab.studies.answers.calibration.requests import prepare_request
from isolab.studies.inputs.study import load_scene
from isolab.studies.results.calibrations import CalibrationStore
from tests.shared_cluster import shared_scheduler

TRUE_F_HORIZONTAL = 3.6  # Hz, what the example's measurement was made with
TRUE_OFFSET = 0.1  # s


def wait_done(http: TestClient, job_id: str, seconds: float = 110.0) -> dict:
    deadline = time.monotonic() + seconds
    while (info := http.get(f"/calibrations/{job_id}").json())["status"] in ("queued", "running"):
        assert time.monotonic() < deadline, info
        time.sleep(0.2)
    return info


def csv_text() -> str:
    m = EXAMPLE_CALIBRATION["measurement"]
    return measurement_csv(measurement_from_columns(m["time"], m["channels"]))


def test_post_recovers_the_mounts_and_draws_the_traces(http: TestClient) -> None:
    body = copy.deepcopy(EXAMPLE_CALIBRATION)
    body["measurement"] = {"csv": csv_text()}  # the same measurement as CSV text
    body["plot"] = True
    r = http.post("/calibrations", json=body)
    assert r.status_code == 202, r.text
    job = r.json()
    assert job["status"] in ("queued", "running") and job["result"] is None
    assert 0 < job["estimate"]["seconds"] <= job["estimate"]["limit_seconds"] == MAX_CALIBRATION_SECONDS
    info = wait_done(http, job["id"])
    assert info["status"] == "done" and info["error"] is None, info
    a = info["result"]
    assert info["progress"]["fraction"] == 1.0 and info["progress"]["cases"] == a["evaluations"]["cases"]
    (fh,) = a["parameters"]
    assert fh["path"] == "isolators.f_horizontal" and fh["determined"]
    assert fh["start"] == pytest.approx(3.0)  # the air preset
    assert abs(fh["value"] - TRUE_F_HORIZONTAL) < max(3 * fh["sigma"], 2e-3)
    assert abs(a["time_offset"]["value"] - TRUE_OFFSET) < 2e-3
    (ch,) = a["channels"]
    assert ch["rms_after"] < 0.01 * ch["rms_before"]  # the 3 Hz mounts miss the trace, 3.6 Hz meet it
    assert load_scene(a["scene_yaml"]).isolators.f_horizontal == pytest.approx(fh["value"])
    png = base64.b64decode(a["plot_png"])
    assert png[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize(
    ("change", "loc"),
    [
        (
            lambda b: b["measurement"]["channels"][0].update(name="cg.q.displacement"),
            ["measurement", "channels", 0, "name"],
        ),
        (lambda b: b["measurement"]["channels"][0].update(unit="kg"), ["measurement", "channels", 0, "name"]),
        (
            lambda b: b["measurement"]["channels"][0].update(name="camera.y.displacement"),
            ["measurement", "channels", 0],
        ),
        (lambda b: b["measurement"]["channels"][0]["values"].pop(), ["measurement", "channels", 0]),
        (lambda b: b["fit"][0].update(path="isolators.f_sideways"), ["fit", 0, "path"]),
        (lambda b: b["fit"][0].update(lower="7 Hz"), ["fit", 0, "upper"]),
        (lambda b: b["fit"][0].update(lower="1 kg"), ["fit", 0, "lower"]),
        (lambda b: b.update(fit=[]), ["fit"]),
        (lambda b: b["scene"]["stages"][0].update(mass="-3 kg"), ["scene", "stages", 0, "mass"]),
        (lambda b: b.update(highpass="fast"), ["highpass"]),
        (lambda b: b["measurement"].update(csv="time,cg.y.displacement\n0,1"), ["measurement"]),
        (lambda b: b.update(simulation={"dt": "0 s"}), ["simulation", "dt"]),
        (lambda b: b.update(simulation={"dt": "0.2 s"}), ["simulation", "dt"]),
        (lambda b: b.update(simulation={"auto_step": "yes"}), ["simulation", "auto_step"]),
        (lambda b: b.update(noise={"cg.q.displacement": "1 mm"}), ["noise", "cg.q.displacement"]),
        (lambda b: b.update(noise={"cg.y.displacement": "-1 mm"}), ["noise", "cg.y.displacement"]),
        (lambda b: b.update(starts=0), ["starts"]),
    ],
)
def test_bad_input_is_422_naming_the_field(http: TestClient, change, loc) -> None:
    body = copy.deepcopy(EXAMPLE_CALIBRATION)
    change(body)
    r = http.post("/calibrations", json=body)
    assert r.status_code == 422, r.text
    assert r.json()["detail"][0]["loc"][: len(loc) + 1] == ["body", *loc], r.json()


def test_the_job_answers_what_the_calibration_itself_does(http: TestClient) -> None:
    """Run on a worker, the fit gives the numbers of the calibration run here, to the last bit."""
    body = copy.deepcopy(EXAMPLE_CALIBRATION)
    body["plot"] = False
    job = http.post("/calibrations", json=body).json()
    direct = calibrate_request(body).to_json()
    answer = wait_done(http, job["id"])["result"]
    assert answer["plot_png"] is None
    keys = ("parameters", "time_offset", "channels", "residual_variance", "goodness_of_fit", "starts")
    for key in (*keys, "evaluations", "scene_yaml"):
        assert answer[key] == direct[key], key


def test_the_estimate_is_within_a_factor_of_three_of_the_work_done() -> None:
    fit = calibrate_request(EXAMPLE_CALIBRATION).evaluations
    cost = estimate_cost(prepare_request(EXAMPLE_CALIBRATION))
    assert fit["cases"] / 3 <= cost.cases <= 3 * fit["cases"]
    assert fit["engine_calls"] / 3 <= cost.engine_calls <= 3 * fit["engine_calls"]


def costly_body() -> dict:
    """The example with five parameters at the reference integrator's 0.05 ms: hours of engine time."""
    body = copy.deepcopy(EXAMPLE_CALIBRATION)
    body["simulation"] = {"fidelity": "nonlinear", "integrator": "reference", "dt": "0.05 ms"}
    body["fit"] = [
        {"path": "isolators.f_horizontal", "lower": "1 Hz", "upper": "6 Hz"},
        {"path": "isolators.f_vertical", "lower": "1 Hz", "upper": "6 Hz"},
        {"path": "isolators.zeta", "lower": "1 %", "upper": "30 %"},
        {"path": "stages.y.mass", "lower": "500 kg", "upper": "1500 kg"},
        {"path": "machine.block.density", "lower": "2000 kg/m^3", "upper": "3000 kg/m^3"},
    ]
    body["offset"] = {"lower": "0 s", "upper": "0.2 s"}
    return body


def test_csv_errors_in_a_request_name_the_line_and_the_column(http: TestClient) -> None:
    body = copy.deepcopy(EXAMPLE_CALIBRATION)
    lines = csv_text().splitlines()
    lines[5] = lines[5].split(",")[0] + ",n/a"  # the file's sixth line, as an editor shows it
    body["measurement"] = {"csv": "\n".join(lines)}
    r = http.post("/calibrations", json=body)
    assert r.status_code == 422, r.text
    (d,) = r.json()["detail"]
    assert d["loc"] == ["body", "measurement", "csv"]
    assert d["msg"] == "line 6, column 'cg.y.displacement [mm]': 'n/a' is not a number", d


def test_a_calibration_above_the_limit_is_refused_at_once(http: TestClient) -> None:
    t0 = time.perf_counter()
    r = http.post("/calibrations", json=costly_body())
    assert time.perf_counter() - t0 < 5.0
    assert r.status_code == 422, r.text
    (d,) = r.json()["detail"]
    assert d["loc"] == ["body"] and f"limit of {MAX_CALIBRATION_SECONDS:.0f} s" in d["msg"], d


def slow_body() -> dict:
    """Four parameters, nonlinear RK4 at 0.1 ms: tens of engine batches of a few tenths of a second."""
    body = costly_body()
    body["simulation"] = {"fidelity": "nonlinear", "integrator": "rk4", "dt": "0.1 ms"}
    body["fit"] = body["fit"][:3]
    body["plot"] = False
    return body


def executing(http: TestClient) -> list:
    dask = http.app.state.dask  # type: ignore[attr-defined]
    running = dask.run(
        lambda dask_worker: [k for k, ts in dask_worker.state.tasks.items() if ts.state == "executing"]
    )
    return [k for keys in running.values() for k in keys]


def test_delete_stops_the_worker_within_seconds_and_the_calibration_is_gone(http: TestClient) -> None:
    job = http.post("/calibrations", json=slow_body())
    assert job.status_code == 202, job.text
    job_id = job.json()["id"]
    assert job.json()["estimate"]["seconds"] > 10  # the fit would go on for longer than the wait below
    deadline = time.monotonic() + 110
    while http.get(f"/calibrations/{job_id}").json()["progress"]["engine_calls"] < 2:
        assert time.monotonic() < deadline
        time.sleep(0.1)
    assert any(job_id in str(k) for k in executing(http))
    assert http.delete(f"/calibrations/{job_id}").status_code == 204
    t0 = time.monotonic()
    assert http.get(f"/calibrations/{job_id}").status_code == 404
    assert http.delete(f"/calibrations/{job_id}").status_code == 404
    while executing(http):
        assert time.monotonic() - t0 < 5.0, "the worker goes on fitting a deleted calibration"
        time.sleep(0.1)


def test_a_stored_calibration_is_run_when_the_service_starts(tmp_path: Path) -> None:
    """A calibration a stopped service left running is taken up by the next start, to the same answer."""
    body = copy.deepcopy(EXAMPLE_CALIBRATION)
    body["plot"] = False
    store = CalibrationStore(tmp_path)
    job = store.create(body, estimate_cost(prepare_request(body)).to_json())
    store.update(job["id"], status="running")
    with TestClient(create_app(Settings(data_dir=tmp_path, scheduler_address=shared_scheduler(1)))) as again:
        info = wait_done(again, job["id"])
    assert info["status"] == "done"
    assert info["result"]["parameters"] == calibrate_request(body).to_json()["parameters"]
    assert store.get(job["id"])["status"] == "done"


def test_unknown_or_malformed_ids_are_404(http: TestClient) -> None:
    for job_id in ("0" * 32, "not-an-id", "../../etc"):
        assert http.get(f"/calibrations/{job_id}").status_code == 404
        assert http.delete(f"/calibrations/{job_id}").status_code == 404


def test_client_calibrate(http: TestClient, tmp_path: Path) -> None:
    scene = tmp_path / "scene.yaml"
    scene.write_text(yaml.safe_dump(EXAMPLE_CALIBRATION["scene"]))
    meas = tmp_path / "measured.csv"
    meas.write_text(csv_text())
    api = Client("http://testserver")
    api._http = http  # the app in this process: TestClient is an httpx.Client
    seen: list[str] = []
    a = api.calibrate(
        scene, meas, ["isolators.f_horizontal=1 Hz:6 Hz"], progress=lambda j: seen.append(j["status"])
    )
    assert seen[-1] == "done"
    assert abs(a["parameters"][0]["value"] - TRUE_F_HORIZONTAL) < 2e-3
    assert a["plot_png"] is None
    with pytest.raises(ClientError) as err:
        api.calibrate(scene, meas, ["isolators.f_sideways=1:6"])
    assert err.value.status_code == 422


def test_cli_calibrate_prints_the_table_and_writes_the_scene(tmp_path: Path) -> None:
    scene = tmp_path / "scene.yaml"
    scene.write_text(yaml.safe_dump(EXAMPLE_CALIBRATION["scene"]))
    meas = tmp_path / "measured.csv"
    meas.write_text(csv_text())
    out, png = tmp_path / "calibrated.yaml", tmp_path / "traces.png"
    args = ["calibrate", str(scene), str(meas), "--fit", "isolators.f_horizontal=1:6", "-o", str(out)]
    r = CliRunner().invoke(cli_app, [*args, "--plot", str(png)])
    assert r.exit_code == 0, r.output
    assert "isolators.f_horizontal" in r.output and "misfit after" in r.output
    fitted = load_scene(out).isolators.f_horizontal
    assert fitted is not None and abs(fitted - TRUE_F_HORIZONTAL) < 2e-3
    assert png.read_bytes()[:4] == b"\x89PNG"
    bad = CliRunner().invoke(
        cli_app, ["calibrate", str(scene), str(meas), "--fit", "isolators.f_sideways=1:6"]
    )
    assert bad.exit_code == 2 and "fit[0].path" in bad.output
    assert np.isfinite(fitted)
