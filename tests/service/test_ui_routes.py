"""The web page's shells and assets, the local /docs and /redoc, and the authoring routes that need no
cluster (examples, checking a study text), on an app without its lifespan. The page itself runs in a real
browser in tests/browser; the stored-study routes are exercised by tests/reliability/test_security.py."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
import yaml
from fastapi.testclient import TestClient

from isolab.service.api.app import create_app
from isolab.service.api.routes import comparisons
from isolab.service.api.schemas import EXAMPLE_STUDY_TEXT
from isolab.service.settings import Settings
from isolab.studies.answers.single_case import MAX_CASE_VALUES
from isolab.studies.authoring.authoring import EXAMPLES_DIR

TOKEN = "s3cret"


@pytest.fixture
def bare(tmp_path: Path) -> TestClient:
    return TestClient(create_app(Settings(data_dir=tmp_path, api_token=TOKEN, max_cases=100)))


def auth() -> dict[str, str]:
    return {"Authorization": f"Bearer {TOKEN}"}


def test_root_redirects_to_the_page_and_every_shell_is_served(bare: TestClient) -> None:
    r = bare.get("/", follow_redirects=False)
    assert r.status_code == 307 and r.headers["location"] == "/ui/"
    for path, script in (
        ("/ui/", "index.js"),
        ("/ui/new", "new.js"),
        ("/ui/compare", "compare.js"),
        ("/ui/scene", "scene.js"),
        ("/ui/studies/0123456789abcdef0123456789abcdef", "study.js"),
        ("/ui/studies/0123456789abcdef0123456789abcdef/cases/3", "case.js"),
        ("/ui/calibrate", "calibration.js"),
        ("/ui/calibrations/0123456789abcdef0123456789abcdef", "calibration.js"),
    ):
        r = bare.get(path)
        assert r.status_code == 200 and r.headers["content-type"].startswith("text/html"), path
        assert f"/ui/assets/{script}" in r.text and "http" not in r.text.replace("http-equiv", ""), path
        assert bare.get(f"/ui/assets/{script}").status_code == 200


def test_assets_come_from_registry_packages_not_a_cdn(bare: TestClient) -> None:
    plotly = bare.get("/ui/vendor/plotly.min.js")
    assert plotly.status_code == 200 and "plotly.js" in plotly.text[:200]
    docs = bare.get("/docs").text
    redoc = bare.get("/redoc").text
    for page in (docs, redoc):
        assert "cdn" not in page and "googleapis" not in page
        assert '<a href="/ui/"' in page  # the reference pages lead back to the web page
    assert "/ui/vendor/docs/swagger-ui-bundle.js" in docs and "/ui/vendor/docs/swagger-ui.css" in docs
    for asset in (
        "/ui/vendor/docs/swagger-ui-bundle.js",
        "/ui/vendor/docs/swagger-ui.css",
        "/ui/vendor/redoc.standalone.js",
    ):
        assert bare.get(asset).status_code == 200, asset
    assert "cdn.redoc.ly" not in bare.get("/ui/vendor/redoc.standalone.js").text
    spec = bare.get("/openapi.json").json()
    assert not [p for p in spec["paths"] if p.startswith("/ui") or p in ("/", "/docs", "/redoc")]


def test_the_authoring_routes_want_the_token(bare: TestClient) -> None:
    assert bare.get("/examples").status_code == 401
    assert bare.post("/studies/validate", json={"text": EXAMPLE_STUDY_TEXT}).status_code == 401


def test_examples_and_checking_a_text(bare: TestClient) -> None:
    names = bare.get("/examples", headers=auth()).json()["names"]
    assert "isolator-comparison" in names
    example = bare.get("/examples/isolator-comparison", headers=auth()).json()
    assert example["text"].startswith("#")
    assert bare.get("/examples/nope", headers=auth()).status_code == 404
    ok = bare.post("/studies/validate", json={"text": example["text"]}, headers=auth())
    assert ok.status_code == 200, ok.text
    assert ok.json()["n_cases"] == 12 and ok.json()["definition"]["name"] == "isolator-comparison"
    bad = example["text"].replace("num: 4", "num: 400")  # 3 x 400 cases: over this app's 100
    r = bare.post("/studies/validate", json={"text": bad}, headers=auth())
    assert r.status_code == 422
    (d,) = r.json()["detail"]
    assert "limit of 100" in d["msg"] and d["line"] == 1 + bad.split("\n").index("parameters:")


# ---------------------------------------------------------------------------- a single case, run now
def scriber_scene() -> dict:
    return yaml.safe_load((EXAMPLES_DIR / "article-scriber.yaml").read_text(encoding="utf-8"))


def test_the_article_scriber_runs_now_with_its_summary_and_traces(bare: TestClient) -> None:
    r = bare.post("/simulations", json={"scene": scriber_scene()}, headers=auth())
    assert r.status_code == 200, r.text
    answer = r.json()
    assert answer["status"] == "ok" and answer["model"]["fidelity"] == "ltv"
    peak_y = answer["summary"]["peak_displacement_y"]
    assert peak_y["value"] == pytest.approx(5.67e-3, abs=0.01e-3)  # the article's 5.67 mm of Y sway
    assert peak_y["unit"] == "m" and peak_y["long_name"].startswith("peak absolute displacement")
    # the article's 3.5 Hz heave (the tuning of its air mounts), named by its motion
    heave = [m for m in answer["modes"] if m["name"].startswith("heave")]
    assert heave and heave[0]["frequency"] == pytest.approx(3.5, rel=0.05)
    traces = answer["traces"]
    assert answer["every"] * len(traces["time"]) >= answer["n_samples"] > 2000 >= len(traces["time"])
    assert set(traces["stages"]) == {"y", "x"}
    assert [p["place"] for p in answer["isolators"].values()] == [
        "front-left",
        "front-right",
        "back-right",
        "back-left",
    ]
    assert answer["isolators"]["mount_0"]["label"] == "front-left (x 0.20 m, y 0.30 m)"


def test_a_single_case_is_refused_naming_the_field_and_the_limit(bare: TestClient) -> None:
    bad = scriber_scene()
    bad["stages"][0]["mass"] = "-5 kg"
    r = bare.post("/simulations", json={"scene": bad}, headers=auth())
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "scene", "stages", 0, "mass"]
    r = bare.post("/simulations", json={"scene": scriber_scene(), "max_points": 1}, headers=auth())
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "max_points"]
    # an hour at 0.1 ms: 36 million steps x 25 series (time, 6 c.g. motions, 4 x 3 forces, 2 x 3 points),
    # past the values a case may record
    long = {"duration": "3600 s", "dt": "0.1 ms"}
    r = bare.post("/simulations", json={"scene": scriber_scene(), "simulation": long}, headers=auth())
    assert r.status_code == 422
    (d,) = r.json()["detail"]
    assert d["loc"] == ["body", "simulation", "duration"] and d["type"] == "case_too_large"
    assert f"{MAX_CASE_VALUES:,}" in d["msg"] and "36,000,001 time steps x 25 series" in d["msg"]
    # written in the scene: the scene's field is named
    s = scriber_scene()
    s["simulation"] = {**s["simulation"], **long}
    r = bare.post("/simulations", json={"scene": s}, headers=auth())
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == [
        "body",
        "scene",
        "simulation",
        "duration",
    ]
    assert bare.post("/simulations", json={"scene": scriber_scene()}).status_code == 401


def test_a_single_case_past_its_time_limit_is_answered_503_at_once(
    bare: TestClient, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(comparisons, "SIMULATION_TIME_LIMIT", 0.001)
    started = time.monotonic()
    r = bare.post("/simulations", json={"scene": scriber_scene()}, headers=auth())
    assert r.status_code == 503 and "0.001 s limit" in r.json()["detail"]
    assert time.monotonic() - started < 5.0  # the answer does not wait for the engine's thread
