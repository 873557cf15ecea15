"""``POST /comparisons`` with design criteria: margins per type, one recommendation, 422 naming the field."""

from __future__ import annotations

import copy
import json
import time

import pytest
import xarray as xr
from fastapi.testclient import TestClient

from isolab.service.api.app import create_app
from isolab.service.api.schemas import EXAMPLE_SCENE
from isolab.service.settings import Settings


@pytest.fixture(scope="module")
def http(tmp_path_factory: pytest.TempPathFactory):
    settings = Settings(data_dir=tmp_path_factory.mktemp("data"), workers=1)
    with TestClient(create_app(settings)) as client:
        yield client


def scene(criteria: dict) -> dict:
    s = copy.deepcopy(EXAMPLE_SCENE)
    s["simulation"] = {"fidelity": "lti", "integrator": "exact", "dt": "2 ms", "duration": "2 s"}
    s["criteria"] = criteria
    return s


def test_comparison_recommends_the_cheapest_type_meeting_the_criteria(http: TestClient) -> None:
    # 2 mm of peak tool motion: the stiff elastomer mounts meet it, the soft active ones do not
    r = http.post("/comparisons", json={"scene": scene({"tool": {"displacement": "2 mm"}})})
    assert r.status_code == 200, r.text
    body = r.json()
    rows = body["rows"]
    assert rows["elastomer"]["meets_criteria"] is True and rows["active"]["meets_criteria"] is False
    assert rows["active"]["margin_tool_displacement"] < 0 < rows["elastomer"]["margin_tool_displacement"]
    assert body["requirements"] == [
        {
            "name": "tool_displacement",
            "limit": pytest.approx(2e-3),
            "unit": "m",
            "description": "peak displacement of tool",
        }
    ]
    rec = body["recommendation"]
    assert rec["isolator_type"] == "elastomer" and rec["cost_order"] == ["elastomer", "air", "active"]
    assert "cheapest" in rec["reason"]
    # the buyer's own prices: active first, but it fails, so the next type that meets the limit wins
    r = http.post(
        "/comparisons",
        json={
            "scene": scene({"tool": {"displacement": "2 mm"}}),
            "cost_order": ["active", "air", "elastomer"],
        },
    )
    rec = r.json()["recommendation"]
    expected = "air" if r.json()["rows"]["air"]["meets_criteria"] else "elastomer"
    assert rec["isolator_type"] == expected
    assert "active fails tool_displacement" in rec["reason"]


def test_no_criteria_no_recommendation(http: TestClient) -> None:
    s = scene({})
    del s["criteria"]
    body = http.post("/comparisons", json={"scene": s, "isolator_types": ["air"]}).json()
    assert body["recommendation"]["isolator_type"] is None
    assert "no criteria given" in body["recommendation"]["reason"]
    assert body["requirements"] == []


@pytest.mark.parametrize(
    ("criteria", "loc", "text"),
    [
        (
            {"nozzle": {"displacement": "1 mm"}},
            ["body", "scene", "criteria", "nozzle"],
            "no point of interest",
        ),
        ({"tool": {"displacement": "1 kg"}}, ["body", "scene", "criteria", "tool", "displacement"], "length"),
    ],
)
def test_bad_criteria_are_422_naming_the_field(
    http: TestClient, criteria: dict, loc: list, text: str
) -> None:
    r = http.post("/comparisons", json={"scene": scene(criteria)})
    assert r.status_code == 422
    detail = r.json()["detail"]
    assert any(d["loc"] == loc and text in d["msg"] for d in detail), detail


def test_a_study_stores_margins_and_filters_on_meets_criteria(http: TestClient, tmp_path) -> None:
    body = {
        "name": "criteria-study",
        "scene": scene({"tool": {"displacement": "2 mm"}, "isolators": {"no_liftoff": True}}),
        "parameters": [{"path": "isolators.preset", "values": ["active", "air", "elastomer"]}],
        "design": {"type": "grid"},
    }
    sid = http.post("/studies", json=body).json()["id"]
    deadline = time.monotonic() + 60
    while (info := http.get(f"/studies/{sid}").json())["status"] not in ("done", "failed"):
        assert time.monotonic() < deadline
        time.sleep(0.2)
    assert info["status"] == "done", info
    every = http.get(f"/studies/{sid}/cases", params={"columns": "isolator_type,meets_criteria"}).json()
    passing = http.get(
        f"/studies/{sid}/cases", params={"filter": "meets_criteria==true", "columns": "isolator_type"}
    ).json()
    expected = [r["isolator_type"] for r in every["rows"] if r["meets_criteria"]]
    assert [r["isolator_type"] for r in passing["rows"]] == expected
    assert "elastomer" in expected and "active" not in expected
    # the stored dataset: margins per case and criterion, with units and the block that set them
    (tmp_path / "c.nc").write_bytes(http.get(f"/studies/{sid}/dataset").content)
    ds = xr.load_dataset(tmp_path / "c.nc")
    assert ds["criterion_margin"].dims == ("isolator_type", "criterion")
    assert ds["criterion_margin"].attrs["units"] == "1"
    assert list(ds["criterion"].values) == ["tool_displacement", "isolators_no_liftoff"]
    assert json.loads(ds.attrs["criteria"])["tool"]["displacement"] == pytest.approx(2e-3)
