"""Refusals are fast (issue 13, item 4): a study is counted from its definition before anything is read or
built, its lists are bounded, and a big body is validated off the event loop.

A 600,000-value list parameter crossed with 3 isolator types (1.8 M cases) took 109 s to be refused and a
300,000-value one (900,000 cases, under the default limit of 1,000,000) 125 s to be accepted.
"""

from __future__ import annotations

import json
import statistics
import time
from typing import Any

import httpx
import pytest

from benchmarks.live_service import quick_scene, thread_server
from benchmarks.refusals import post_and_probe
from isolab.service.api.app import create_app
from isolab.service.settings import Settings
from isolab.studies.inputs import schema
from isolab.studies.inputs.definitions import DefinitionError, check_definition
from tests.shared_cluster import shared_scheduler

REFUSED_WITHIN_S = 1.0


def big_study(n: int, units: bool = False, design: dict | None = None) -> dict[str, Any]:
    """3 isolator types crossed with ``n`` Y accelerations from 5 m/s^2 up in steps of 1 um/s^2 (numbers,
    or text with units)."""
    values: list[Any] = [round(5.0 + i * 1e-6, 6) for i in range(n)]
    if units:  # the same accelerations in um/s^2: 600,000 of them fit in a 10 MiB body
        values = [f"{5_000_000 + i} um/s^2" for i in range(n)]
    return {
        "name": f"big-{n}",
        "scene": quick_scene(),
        "parameters": [
            {"path": "isolators.preset", "values": ["active", "air", "elastomer"]},
            {"path": "stages.y.profile.acceleration", "values": values},
        ],
        "design": design or {"type": "grid"},
    }


def refusal(body: dict, max_cases: int) -> tuple[list[dict], float]:
    start = time.perf_counter()
    with pytest.raises(DefinitionError) as err:
        check_definition(body, max_cases)
    return err.value.details, time.perf_counter() - start


@pytest.mark.parametrize("units", [False, True], ids=["numbers", "text-with-units"])
def test_a_600000_value_list_is_refused_from_its_count_in_well_under_a_second(units: bool) -> None:
    details, took = refusal(big_study(600_000, units=units), 1_000_000)
    assert took < REFUSED_WITHIN_S, f"refused after {took:.2f} s"
    assert [d["loc"] for d in details] == [["body", "parameters"]]
    assert "1800000 cases" in details[0]["msg"] and "ISOLAB_MAX_CASES" in details[0]["msg"]


def test_a_list_longer_than_the_case_limit_is_refused_naming_it_whatever_the_design() -> None:
    # a sampled design has `samples` cases, however many values a parameter lists: the list is bounded too
    body = big_study(1001, design={"type": "lhs", "samples": 10})
    details, took = refusal(body, 1000)
    assert took < REFUSED_WITHIN_S
    assert [d["loc"] for d in details] == [["body", "parameters", 1, "values"]]
    assert "1001 entries" in details[0]["msg"] and "ISOLAB_MAX_CASES" in details[0]["msg"]
    cases = [{"acc": 5.0}] * 1001
    body = {**big_study(1), "parameters": [{"name": "acc", "path": "stages.y.profile.acceleration"}]}
    body["design"] = {"type": "list", "cases": cases}
    details, _ = refusal(body, 1000)
    assert [d["loc"] for d in details] == [["body", "design", "cases"]]
    assert "design.cases: 1001 entries" in details[0]["msg"] and "ISOLAB_MAX_CASES" in details[0]["msg"]


def test_the_schema_bounds_every_list_a_definition_may_make_long() -> None:
    bound = schema.MAX_LIST_ENTRIES
    assert schema.ParameterSpec.model_json_schema()["properties"]["values"]["anyOf"][0]["maxItems"] == bound
    assert schema.DesignSpec.model_json_schema()["properties"]["cases"]["anyOf"][0]["maxItems"] == bound


def test_a_bad_value_at_the_end_of_a_long_list_is_refused_within_a_second() -> None:
    body = big_study(100_000)
    body["parameters"][1]["values"][-1] = "5 parsecs"
    details, took = refusal(body, 1_000_000)
    assert took < REFUSED_WITHIN_S, f"refused after {took:.2f} s"
    assert "values[99999]" in json.dumps(details)


@pytest.mark.parametrize("units", [False, True], ids=["numbers", "text-with-units"])
def test_a_100000_value_list_is_validated_in_seconds(units: bool) -> None:
    # (before: about 40 s with units, every value read by the units parser twice)
    start = time.perf_counter()
    study = check_definition(big_study(100_000, units=units), 1_000_000)
    took = time.perf_counter() - start
    assert study.n_cases == 300_000
    assert took < 3.0, f"validated in {took:.2f} s"
    accelerations = study.design().levels["stage_y_acceleration"]
    assert accelerations[0] == 5.0 and accelerations[-1] == pytest.approx(5.099999, abs=1e-12)


@pytest.mark.slow
def test_over_http_the_600000_value_study_is_a_422_within_a_second_and_health_stays_fast(tmp_path) -> None:
    bodies = [
        json.dumps(big_study(600_000, units), separators=(",", ":")).encode() for units in (False, True)
    ]
    with thread_server(create_app(Settings(data_dir=tmp_path, scheduler_address=shared_scheduler(1)))) as url:
        for content in bodies:
            check_fast_422(url, content)


def check_fast_422(url: str, content: bytes) -> None:
    """POST ``content``: a 422 naming the case limit within about a second, /health fast meanwhile."""
    assert len(content) < 10 * 1024 * 1024
    with httpx.Client(base_url=url, timeout=60.0) as http:
        assert http.get("/health").status_code in (200, 503)
        r, took, latencies = post_and_probe(url, content)
        assert r.status_code == 422, r.text
        assert r.json()["detail"][0]["loc"] == ["body", "parameters"]
        assert "ISOLAB_MAX_CASES" in r.json()["detail"][0]["msg"]
        assert took < REFUSED_WITHIN_S + 1.0, f"422 after {took:.2f} s (upload included)"
        assert statistics.median(latencies) < 0.1
        assert max(latencies) < 1.0, f"/health took {max(latencies):.2f} s while the body was checked"
        assert http.get("/studies").json()["total"] == 0
