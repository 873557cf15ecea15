"""The web page's shells and assets, the local /docs and /redoc, and the authoring routes that need no
cluster (examples, checking a study text), on an app without its lifespan. The page itself runs in a real
browser in tests/browser; the stored-study routes are exercised by tests/reliability/test_security.py."""

from __future__ import annotations

from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from isolab.service.api.app import create_app
from isolab.service.api.schemas import EXAMPLE_STUDY_TEXT
from isolab.service.settings import Settings

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
        ("/ui/studies/0123456789abcdef0123456789abcdef", "study.js"),
        ("/ui/studies/0123456789abcdef0123456789abcdef/cases/3", "case.js"),
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
