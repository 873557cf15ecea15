"""``/studies/{id}/sensitivity``, its PNG, the client and the CLI on a real app (the shared cluster):
a small saltelli study of the example scene runs once and every test reads it."""

from __future__ import annotations

import copy
import io
import json
import uuid

import matplotlib.image
import numpy as np
import pytest
from fastapi.testclient import TestClient
from typer.testing import CliRunner

from benchmarks.live_service import wait_finished
from isolab.service.api.schemas import EXAMPLE_SCENE
from isolab.service.cli import app as cli_app
from isolab.service.client import Client, sensitivity_frame
from isolab.studies.answers import sensitivity as sensitivity_module
from tests.service.conftest import live_app

pytestmark = pytest.mark.slow  # a service and a cluster (its test process's shared one)

N_BASE = 32
OUTPUT = "peak_point_displacement.tool.z"


def scene(duration: str = "3 s", fidelity: str = "lti", integrator: str = "exact", dt: str = "2 ms") -> dict:
    s = copy.deepcopy(EXAMPLE_SCENE)
    s["simulation"] = {"fidelity": fidelity, "integrator": integrator, "dt": dt, "duration": duration}
    return s


SALTELLI = {
    "name": "api-saltelli",
    "scene": scene(),
    "parameters": [
        {"path": "isolators.f_vertical", "range": {"start": "2 Hz", "stop": "8 Hz", "scale": "log"}},
        {"path": "isolators.zeta", "range": {"start": "5 %", "stop": "30 %"}},
        {"path": "machine.block.density", "range": {"start": "2690 kg/m^3", "stop": "2710 kg/m^3"}},
    ],
    "design": {"type": "saltelli", "samples": N_BASE, "seed": 3},
}


@pytest.fixture(scope="module")
def http(tmp_path_factory: pytest.TempPathFactory):
    with live_app(tmp_path_factory, workers=2, max_cases=1000) as client:
        yield client


@pytest.fixture(scope="module")
def study_id(http: TestClient) -> str:
    r = http.post("/studies", json=SALTELLI)
    assert r.status_code == 202, r.text
    assert r.json()["n_cases"] == N_BASE * (3 + 2)  # the true count, N (D + 2)
    info = wait_finished(http, r.json()["id"])
    assert info["status"] == "done", info
    return r.json()["id"]


def test_sobol_indices_of_a_real_study(http: TestClient, study_id: str) -> None:
    r = http.get(f"/studies/{study_id}/sensitivity", params={"output": OUTPUT})
    assert r.status_code == 200, r.text
    a = r.json()
    assert a["method"] == "sobol" and a["design"] == "saltelli"
    assert a["parameters"] == ["isolator_f_vertical", "isolator_zeta", "machine_density"]
    assert a["n_cases"] == a["n_total"] == N_BASE * 5 and a["n_excluded"] == 0
    assert a["unit"] == "m" and "point of interest" in a["long_name"]
    st, st_conf = np.array(a["indices"]["ST"]), np.array(a["conf"]["ST"])
    # physics: the heave peak follows the mount's frequency and damping; a 0.7 % change of the base's
    # density (its mass) moves it by a fraction of that: the least total effect, near zero
    assert st[2] < 0.05 and st[2] < min(st[0], st[1])
    assert np.all(st_conf >= 0) and set(a["conf"]) == {"S1", "ST"}
    # one design: its intervals are a bootstrap over the base samples, and the answer says so
    assert a["replicates"] == 1 and a["interval_method"].startswith("bootstrap over the base samples")
    assert a["parameter_units"][0] == "Hz"


def test_png_is_a_real_bar_chart(http: TestClient, study_id: str) -> None:
    r = http.get(f"/studies/{study_id}/sensitivity.png", params={"output": "settling_time"})
    assert r.status_code == 200 and r.headers["content-type"] == "image/png"
    img = matplotlib.image.imread(io.BytesIO(r.content), format="png")
    assert img.shape[0] > 200 and img.shape[1] > 400
    assert img[..., :3].std() > 0.05  # not blank: bars of colour on white


def test_bad_output_is_422_naming_output(http: TestClient, study_id: str) -> None:
    for path in ("sensitivity", "sensitivity.png"):
        r = http.get(f"/studies/{study_id}/{path}", params={"output": "peak_point_displacement.nose"})
        assert r.status_code == 422, r.text
        d = r.json()["detail"][0]
        assert d["loc"] == ["query", "output"] and "tool" in d["msg"]
    r = http.get(f"/studies/{study_id}/sensitivity")
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["query", "output"]
    r = http.get(f"/studies/{study_id}/sensitivity", params={"output": "dt"})  # the same in every case
    assert r.status_code == 422 and "depends on none of the varied parameters" in r.json()["detail"][0]["msg"]


def test_unknown_study_is_404_and_running_study_is_409(http: TestClient) -> None:
    r = http.get(f"/studies/{uuid.uuid4().hex}/sensitivity", params={"output": OUTPUT})
    assert r.status_code == 404
    assert http.get("/studies/nope/sensitivity.png", params={"output": OUTPUT}).status_code == 404
    long = {
        "name": "api-long",
        "scene": scene(duration="6 s", fidelity="ltv", integrator="rk4", dt="1 ms"),
        "parameters": [{"path": "isolators.f_vertical", "range": {"start": "2 Hz", "stop": "6 Hz"}}],
        "design": {"type": "saltelli", "samples": 128},
    }
    sid = http.post("/studies", json=long).json()["id"]
    try:
        r = http.get(f"/studies/{sid}/sensitivity", params={"output": OUTPUT})
        assert r.status_code == 409 and "its results exist once it is done" in r.json()["detail"]
        assert http.get(f"/studies/{sid}/sensitivity.png", params={"output": OUTPUT}).status_code == 409
    finally:
        http.delete(f"/studies/{sid}")


def test_second_request_reads_the_cache(
    http: TestClient, study_id: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    first = http.get(f"/studies/{study_id}/sensitivity", params={"output": "settling_time"})
    assert first.status_code == 200

    def no_recompute(*args, **kwargs):
        raise AssertionError("recomputed instead of reading the cache")

    monkeypatch.setattr(sensitivity_module, "sensitivity", no_recompute)
    second = http.get(f"/studies/{study_id}/sensitivity", params={"output": "settling_time"})
    assert second.status_code == 200 and second.json() == first.json()
    # another output is not cached yet: it is computed (here: refused by the stand-in, as a 500)
    with pytest.raises(AssertionError, match="recomputed"):
        http.get(f"/studies/{study_id}/sensitivity", params={"output": "natural_frequency.1"})


def test_client_frame_and_cli_table(http: TestClient, study_id: str, tmp_path, monkeypatch) -> None:
    answer = http.get(f"/studies/{study_id}/sensitivity", params={"output": OUTPUT}).json()
    df = sensitivity_frame(answer)
    assert list(df.index) == answer["parameters"]
    assert {"S1", "S1_conf", "ST", "ST_conf", "unit"} <= set(df.columns)
    assert df.attrs["method"] == "sobol" and df.attrs["output"] == OUTPUT
    np.testing.assert_allclose(df["ST"].to_numpy(), answer["indices"]["ST"])

    # the Client and the CLI over the app (httpx routed into the TestClient's transport)
    monkeypatch.setattr(Client, "_request", lambda self, method, url, **kw: http.request(method, url, **kw))
    with Client("http://test") as api:
        assert api.sensitivity(study_id, OUTPUT).equals(df)
    png = tmp_path / "s.png"
    result = CliRunner().invoke(cli_app, ["sensitivity", study_id, "--output", OUTPUT, "--plot", str(png)])
    assert result.exit_code == 0, result.output
    assert "machine_density" in result.output and "ST ± 95 %" in result.output
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_cli_on_a_local_dataset_file(tmp_path) -> None:
    from isolab.studies.results.store import write_netcdf
    from tests.studies.test_sensitivity import S1_EXACT, ishigami_study

    path = write_netcdf(ishigami_study("saltelli", 1024), tmp_path / "ishigami.nc")
    result = CliRunner().invoke(cli_app, ["sensitivity", str(path), "--output", "settling_time", "--json"])
    assert result.exit_code == 0, result.output
    answer = json.loads(result.output)
    assert answer["method"] == "sobol" and answer["n_cases"] == 1024 * 5
    np.testing.assert_allclose(answer["indices"]["S1"], S1_EXACT, atol=0.06)
    table = CliRunner().invoke(cli_app, ["sensitivity", str(path), "--output", "settling_time"])
    rows = [line for line in table.output.splitlines() if line.startswith("│ ")]
    assert [r.split("│")[2].strip() for r in rows] == ["x1", "x2", "x3"]  # ranked by ST
    bad = CliRunner().invoke(cli_app, ["sensitivity", str(path), "--output", "nope"])
    assert bad.exit_code == 2 and "nope" in bad.output
