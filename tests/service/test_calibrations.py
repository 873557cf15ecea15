"""``POST /calibrations``, ``Client.calibrate`` and ``isolab calibrate``, without a cluster: the app is
served without its lifespan (a calibration runs in the API process, not on Dask).

The measurement is :data:`EXAMPLE_CALIBRATION`'s: the example scene's c.g. in Y at 20 Hz, recorded by a
tracker that started 0.1 s before the stage, on mounts 3.6 Hz sideways instead of the air preset's 3 Hz.
"""

from __future__ import annotations

import base64
import copy
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
from isolab.studies.answers.calibration import measurement_csv, measurement_from_columns
from isolab.studies.inputs.study import load_scene

TRUE_F_HORIZONTAL = 3.6  # Hz, what the example's measurement was made with
TRUE_OFFSET = 0.1  # s


@pytest.fixture(scope="module")
def http(tmp_path_factory: pytest.TempPathFactory) -> TestClient:
    return TestClient(create_app(Settings(data_dir=tmp_path_factory.mktemp("data"))))  # no lifespan


def csv_text() -> str:
    m = EXAMPLE_CALIBRATION["measurement"]
    return measurement_csv(measurement_from_columns(m["time"], m["channels"]))


def test_post_recovers_the_mounts_and_draws_the_traces(http: TestClient) -> None:
    body = copy.deepcopy(EXAMPLE_CALIBRATION)
    body["measurement"] = {"csv": csv_text()}  # the same measurement as CSV text
    body["plot"] = True
    r = http.post("/calibrations", json=body)
    assert r.status_code == 200, r.text
    a = r.json()
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
    ],
)
def test_bad_input_is_422_naming_the_field(http: TestClient, change, loc) -> None:
    body = copy.deepcopy(EXAMPLE_CALIBRATION)
    change(body)
    r = http.post("/calibrations", json=body)
    assert r.status_code == 422, r.text
    assert r.json()["detail"][0]["loc"][: len(loc) + 1] == ["body", *loc], r.json()


def test_client_calibrate(http: TestClient, tmp_path: Path) -> None:
    scene = tmp_path / "scene.yaml"
    scene.write_text(yaml.safe_dump(EXAMPLE_CALIBRATION["scene"]))
    meas = tmp_path / "measured.csv"
    meas.write_text(csv_text())
    api = Client("http://testserver")
    api._http = http  # the app in this process: TestClient is an httpx.Client
    a = api.calibrate(scene, meas, ["isolators.f_horizontal=1 Hz:6 Hz"])
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
