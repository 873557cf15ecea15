"""The Python client and the ``isolab submit/status/fetch`` commands against a real uvicorn server.

The server runs in a thread on 127.0.0.1 (a free port) joined to the test process's shared 2-worker cluster.
"""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
import yaml
from typer.testing import CliRunner

from benchmarks.live_service import free_port, thread_server
from isolab.engine import simulate
from isolab.service.api.app import create_app
from isolab.service.api.schemas import EXAMPLE_SCENE
from isolab.service.cli import app as cli_app
from isolab.service.client import Client, ClientError, read_study_file
from isolab.service.settings import Settings
from isolab.studies.inputs.study import load_study
from tests.shared_cluster import shared_scheduler

pytestmark = pytest.mark.slow  # services, clusters or processes of their own: `make test-fast` skips them

G = 9.80665


@pytest.fixture(scope="module")
def url(tmp_path_factory: pytest.TempPathFactory):
    with thread_server(
        create_app(Settings(data_dir=tmp_path_factory.mktemp("data"), scheduler_address=shared_scheduler(2)))
    ) as url:
        yield url


@pytest.fixture(scope="module")
def study_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A study file that names its scene by ``scene_file`` (relative to itself), as users write them."""
    root = tmp_path_factory.mktemp("files")
    scene = copy.deepcopy(EXAMPLE_SCENE)
    scene["simulation"] = {"fidelity": "lti", "integrator": "exact", "dt": "2 ms", "duration": "2 s"}
    (root / "scenes").mkdir()
    (root / "scenes" / "scriber.yaml").write_text(yaml.safe_dump(scene))
    study = {
        "name": "client-grid",
        "scene_file": "scenes/scriber.yaml",
        "parameters": [
            {"path": "isolators.preset", "values": ["air", "elastomer"]},
            {"path": "stages.y.profile.acceleration", "values": ["1 g", "1.5 g", "2 g"]},
        ],
        "design": {"type": "grid"},
    }
    path = root / "study.yaml"
    path.write_text(yaml.safe_dump(study, sort_keys=False))
    return path


@pytest.fixture(scope="module")
def done(url: str, study_file: Path) -> dict:
    with Client(url) as api:
        accepted = api.submit(study_file)
        polled: list[dict] = []
        final = api.wait(accepted["id"], progress=polled.append, poll=0.2, timeout=60)
    assert polled[-1] == final and all(p["progress"]["total"] == 6 for p in polled)
    return {"id": accepted["id"], "accepted": accepted, "final": final}


def test_read_study_file_inlines_the_scene(study_file: Path) -> None:
    body = read_study_file(study_file)
    assert "scene_file" not in body
    assert body["scene"]["stages"][0]["mass"] == "1000 kg"


def test_submit_yaml_wait_and_dataset(url: str, study_file: Path, done: dict) -> None:
    assert done["accepted"]["n_cases"] == 6
    assert done["final"]["status"] == "done"
    assert done["final"]["progress"] == {"done": 6, "total": 6, "failed": 0}
    with Client(url) as api:
        ds = api.dataset(done["id"])
    assert isinstance(ds, xr.Dataset)
    assert ds.peak_displacement.dims == ("isolator_type", "stage_y_acceleration", "axis")
    np.testing.assert_allclose(ds.stage_y_acceleration.values, [G, 1.5 * G, 2 * G], rtol=1e-12)
    # the same numbers as the engine gives for the study file read locally
    study = load_study(study_file)
    sim = study.simulation
    direct = simulate(study.batch([4]), fidelity=sim.fidelity, integrator=sim.integrator, dt=sim.dt)
    assert study.case_values(4) == {
        "isolator_type": "elastomer",
        "stage_y_acceleration": pytest.approx(1.5 * G),
    }
    cell = ds.sel(isolator_type="elastomer", stage_y_acceleration=1.5 * G)
    np.testing.assert_allclose(
        cell.peak_displacement.values, direct.peak_displacement[0], rtol=1e-9, atol=1e-15
    )
    np.testing.assert_allclose(cell.min_isolator_load.values, direct.min_isolator_load[0], rtol=1e-9)


def test_cases_status_list_and_timeseries(url: str, done: dict) -> None:
    with Client(url) as api:
        rows = api.cases(
            done["id"],
            filter="isolator_type==air",
            sort="-stage_y_acceleration",
            columns=["case", "stage_y_acceleration", "peak_displacement_y"],
        )
        assert [r["case"] for r in rows] == [2, 1, 0]
        assert [list(r) for r in rows] == [["case", "stage_y_acceleration", "peak_displacement_y"]] * 3
        y = [r["peak_displacement_y"] for r in rows]
        assert y[0] > y[1] > y[2] > 0  # harder acceleration, larger motion
        info = api.status(done["id"])
        assert info["status"] == "done" and info["definition"]["name"] == "client-grid"
        assert done["id"] in [s["id"] for s in api.list(name="client-grid")]
        ts = api.timeseries(done["id"], 2, every=5)
        assert max(abs(v) for v in ts["displacement"]["y"]) <= y[0] * (1 + 1e-12)
        assert len(ts["time"]) == 201


def test_compare(url: str) -> None:
    with Client(url) as api:
        scene = {**EXAMPLE_SCENE, "criteria": {"tool": {"displacement": "2 mm"}}}
        df = api.compare(scene, types=["elastomer", "active"], simulation={"duration": "1 s"})
    assert list(df.index) == ["elastomer", "active"]
    assert df.attrs["best"]["natural_frequency_1"] == "active"
    assert df.attrs["best"]["peak_displacement_y"] == "elastomer"
    assert df.attrs["units"]["peak_displacement_y"] == "m"
    # one table of types x criteria, and one recommendation: the stiff elastomer mounts move least
    assert df.at["elastomer", "peak_displacement_y"] < df.at["active", "peak_displacement_y"]
    tool = df[
        ["peak_point_displacement_tool_x", "peak_point_displacement_tool_y", "peak_point_displacement_tool_z"]
    ]
    assert df["margin_tool_displacement"].to_numpy() == pytest.approx(1 - tool.max(axis=1).to_numpy() / 2e-3)
    meets = df["meets_criteria"].to_dict()
    rec = df.attrs["recommendation"]
    assert rec["isolator_type"] == (
        "elastomer" if meets["elastomer"] else "active" if meets["active"] else None
    )
    assert rec["cost_order"] == ["elastomer", "active"]


def test_errors_carry_the_server_message(url: str, study_file: Path) -> None:
    with Client(url) as api:
        bad = read_study_file(study_file)
        bad["design"] = {"type": "lhs"}
        with pytest.raises(ClientError, match="design.samples") as err:
            api.submit(bad)
        assert err.value.status_code == 422
        assert err.value.detail[0]["loc"] == ["body", "design", "samples"]
        with pytest.raises(ClientError, match="no study with id") as err:
            api.status("0" * 32)
        assert err.value.status_code == 404
    with Client(f"http://127.0.0.1:{free_port()}", timeout=2) as nowhere, pytest.raises(ClientError) as err:
        nowhere.status("0" * 32)
    assert err.value.status_code is None


def test_delete_through_the_client(url: str, study_file: Path) -> None:
    definition = read_study_file(study_file)
    definition["name"] = "client-delete"
    with Client(url) as api:
        sid = api.submit(definition)["id"]
        api.wait(sid, poll=0.1, timeout=60)
        api.delete(sid)
        with pytest.raises(ClientError) as err:
            api.status(sid)
        assert err.value.status_code == 404


def test_cli_submit_status_fetch(url: str, study_file: Path, done: dict, tmp_path: Path) -> None:
    runner = CliRunner()
    result = runner.invoke(cli_app, ["submit", str(study_file), "--wait", "--url", url])
    assert result.exit_code == 0, result.output
    sid = result.output.split()[0]
    assert len(sid) == 32 and "done" in result.output and "6/6 cases" in result.output

    result = runner.invoke(cli_app, ["status", sid, "--url", url])
    assert result.exit_code == 0 and "done" in result.output and "isolator_type" in result.output
    result = runner.invoke(cli_app, ["status", "--url", url])
    assert result.exit_code == 0 and sid in result.output and done["id"] in result.output

    out = tmp_path / "fetched" / "grid.nc"
    result = runner.invoke(cli_app, ["fetch", sid, "-o", str(out), "--url", url])
    assert result.exit_code == 0, result.output
    with xr.open_dataset(out) as fetched, Client(url) as api:
        reference = api.dataset(done["id"])  # the same study submitted twice: the same numbers
        xr.testing.assert_equal(fetched.peak_displacement.load(), reference.peak_displacement)

    result = runner.invoke(cli_app, ["fetch", "f" * 32, "-o", str(tmp_path / "x.nc"), "--url", url])
    assert result.exit_code == 1 and "404" in result.output
    assert not (tmp_path / "x.nc").exists()


def test_cli_simulate_a_scene_explicit_or_by_accuracy(tmp_path: Path) -> None:
    # the article's scene as shipped (ltv/rk4), and the same scene asking for an accuracy: the second
    # reports the model chosen for it and why, and its peak agrees with the first within the tolerance
    import json

    runner = CliRunner()
    example = Path(__file__).resolve().parents[2] / "studies" / "examples" / "article-scriber.yaml"
    scene = yaml.safe_load(example.read_text())
    scene["simulation"] = {"duration": "6 s"}
    explicit = tmp_path / "explicit.yaml"
    explicit.write_text(
        yaml.safe_dump(
            scene
            | {"simulation": {"fidelity": "nonlinear", "integrator": "rk4", "dt": "1 ms", "duration": "6 s"}}
        )
    )
    asked = tmp_path / "asked.yaml"
    asked.write_text(yaml.safe_dump(scene | {"simulation": {"accuracy": "fast", "duration": "6 s"}}))
    r = runner.invoke(cli_app, ["simulate", str(explicit), "--json"])
    assert r.exit_code == 0, r.output
    ref = json.loads(r.output)
    assert (ref["fidelity"], ref["integrator"], ref["dt"]) == ("nonlinear", "rk4", 0.001)
    assert "accuracy" not in ref
    r = runner.invoke(cli_app, ["simulate", str(asked), "--json"])
    assert r.exit_code == 0, r.output
    got = json.loads(r.output)
    assert got["fidelity"] in ("lti", "ltv", "nonlinear") and got["integrator"] and got["dt"] > 0
    assert "tolerance 5 %" in got["accuracy"]
    assert got["peak_displacement"]["y"] == pytest.approx(ref["peak_displacement"]["y"], rel=0.05)
    r = runner.invoke(cli_app, ["simulate", str(asked)])
    assert r.exit_code == 0 and "chosen for the accuracy asked" in r.output
