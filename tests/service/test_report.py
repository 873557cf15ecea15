"""``GET /studies/{id}/answer`` and ``GET /studies/{id}/report.html``: what a done study answers, and the
design report that carries it, on a real service (a study run to the end on its cluster)."""

from __future__ import annotations

import base64
import copy
import re
import time
from html import escape
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from isolab.service.api.app import create_app
from isolab.service.api.schemas import EXAMPLE_SCENE
from isolab.service.plots.report import percent, quantity
from isolab.service.settings import Settings
from tests.service.conftest import live_app

pytestmark = pytest.mark.slow  # a service with its cluster

HOSTILE = "<script>alert('report')</script> & co"
SCENE = copy.deepcopy(EXAMPLE_SCENE)
SCENE["simulation"] = {"fidelity": "lti", "integrator": "exact", "dt": "2 ms", "duration": "2 s"}
STUDY = {
    "name": HOSTILE,
    "description": "air against elastomer <b>under</b> the scriber",
    "scene": SCENE,
    "criteria": {
        "tool": {"displacement": "3 mm"},
        "isolators": {"no_liftoff": True, "max_deflection": "10 mm"},
    },
    "parameters": [{"path": "isolators.preset", "values": ["air", "elastomer"]}],
    "design": {"type": "grid"},
}


@pytest.fixture(scope="module")
def http(tmp_path_factory: pytest.TempPathFactory):
    with live_app(tmp_path_factory, workers=1, max_cases=100) as client:
        yield client


@pytest.fixture(scope="module")
def done(http: TestClient) -> str:
    r = http.post("/studies", json=STUDY)
    assert r.status_code == 202, r.text
    sid = r.json()["id"]
    deadline = time.monotonic() + 90
    while (info := http.get(f"/studies/{sid}").json())["status"] in ("queued", "running"):
        assert time.monotonic() < deadline, info
        time.sleep(0.1)
    assert info["status"] == "done", info
    return sid


def test_the_answer_gives_each_cases_margins_and_the_values_they_judge(http: TestClient, done: str) -> None:
    answer = http.get(f"/studies/{done}/answer").json()
    cases = http.get(f"/studies/{done}/cases", params={"format": "json"}).json()["rows"]
    crit = {c["name"]: c for c in answer["question"]["criteria"]}
    assert set(crit) == {"tool_displacement", "isolators_no_liftoff", "isolators_max_deflection"}
    assert (
        crit["tool_displacement"]["limit"] == pytest.approx(3e-3) and crit["tool_displacement"]["unit"] == "m"
    )
    assert answer["scene"]["mass"] == pytest.approx(2.6 * 4.2 * 0.34 * 2700)  # the block's
    listed = answer["criteria"]["cases"]
    assert [c["label"] for c in listed] == ["isolator_type = air", "isolator_type = elastomer"]
    for case, row in zip(listed, cases, strict=True):
        for name, m in case["margins"].items():
            assert m == pytest.approx(row[f"margin_{name}"])
        # the value judged is the stored output: the tool's peak displacement, its largest axis
        peak = max(row[f"peak_point_displacement_tool_{a}"] for a in "xyz")
        assert case["values"]["tool_displacement"] == pytest.approx(peak, rel=1e-9)
        assert (
            case["meets_criteria"] == row["meets_criteria"] == all(m >= 0 for m in case["margins"].values())
        )
    assert answer["criteria"]["n_meeting"] == sum(c["meets_criteria"] for c in listed)
    worst = [min(c["margins"].values()) for c in listed]
    assert answer["criteria"]["best_case"]["case"] == worst.index(max(worst))
    assert answer["optimisation"] is None


def test_the_report_carries_the_answers_numbers_escaped_and_without_script(
    http: TestClient, done: str
) -> None:
    answer = http.get(f"/studies/{done}/answer").json()
    r = http.get(f"/studies/{done}/report.html")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    policy = r.headers["content-security-policy"]
    assert "default-src 'none'" in policy and "script" not in policy  # nothing may run in it
    html = r.text
    assert "<script" not in html.lower() and not re.search(r"<[^>]+\son\w+\s*=", html)  # no handler
    assert escape(HOSTILE) in html and HOSTILE not in html
    assert "&lt;b&gt;under&lt;/b&gt;" in html
    for case in answer["criteria"]["cases"]:
        for name, margin in case["margins"].items():
            assert escape(percent(margin)) in html, name
        assert escape(quantity(case["values"]["tool_displacement"], "m")) in html
    assert f"{answer['scene']['mass']:,.0f} kg" in html
    # the plots inline as PNG: the criteria against the isolator type and the time response of a case
    images = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', html)
    assert len(images) >= 2 and all(base64.b64decode(i)[:8] == b"\x89PNG\r\n\x1a\n" for i in images)
    assert "@media print" in html and "http://" not in html and "https://" not in html
    assert "The model and its error estimate" in html and answer["model"]["fidelity"] in html


def test_the_report_of_an_unknown_study_is_404(http: TestClient) -> None:
    for path in ("report.html", "answer"):
        r = http.get(f"/studies/{'0' * 32}/{path}")
        assert r.status_code == 404 and "no study" in r.json()["detail"]


def test_the_report_wants_the_token_when_the_service_has_one(tmp_path: Path) -> None:
    client = TestClient(create_app(Settings(data_dir=tmp_path, api_token="t0ken", max_cases=10)))
    for headers in ({}, {"Authorization": "Bearer wrong"}):
        r = client.get(f"/studies/{'0' * 32}/report.html", headers=headers)
        assert r.status_code == 401 and r.headers["www-authenticate"] == "Bearer"
    # with the token it answers (tests/reliability/test_security.py runs it on a guarded service)
