"""Refusals that cost nothing: a text nested thousands of levels deep, a scene of 100,000 mounts and other
over-long lists are refused from a scan of their characters or lengths, before any parsing; free text is
never read as a quantity; a design's fields are those of its type; YAML keys are written once."""

from __future__ import annotations

import copy
import gc
import json
import statistics
import threading
import time
from types import SimpleNamespace
from typing import Any

import httpx
import pytest
from fastapi import APIRouter, Body, FastAPI
from fastapi.testclient import TestClient

from benchmarks.live_service import quick_scene, thread_server
from benchmarks.refusals import post_and_probe
from isolab.service.api import request_limits
from isolab.service.api.app import create_app
from isolab.service.settings import Settings
from isolab.studies.authoring.authoring import MAX_DEPTH, check_text, parse_text
from isolab.studies.inputs import schema
from isolab.studies.inputs.definitions import DefinitionError, check_definition
from isolab.studies.inputs.schema.fields import MAX_MOUNTS, MAX_POINTS, MAX_SEGMENTS, MAX_STAGES
from tests.shared_cluster import shared_scheduler

FAST_S = 0.1

#: 8,000 levels in about 16 kB, in each way YAML nests
DEEP_TEXTS = {
    "flow-lists": "name: deep\nscene: " + "[" * 8000 + "]" * 8000,
    "flow-mappings": "name: deep\nscene: " + "{a: " * 4000 + "1" + "}" * 4000,
    "block-sequence": "name: deep\nscene:\n" + "- " * 8000 + "x\n",
    "indentation": "".join(" " * i + "k:\n" for i in range(180)),
    "closers-in-a-string-first": 'name: "' + "]" * 200 + '"\nscene: ' + "[" * 8000,
}


def study(**changes: Any) -> dict[str, Any]:
    body = {
        "name": "cheap",
        "scene": quick_scene(),
        "parameters": [{"path": "isolators.preset", "values": ["air", "elastomer"]}],
        "design": {"type": "grid"},
    }
    body.update(changes)
    return body


def refused(body: dict[str, Any]) -> tuple[list[dict[str, Any]], float]:
    start = time.perf_counter()
    with pytest.raises(DefinitionError) as err:
        check_definition(body, 1_000_000)
    return err.value.details, time.perf_counter() - start


# ------------------------------------------------------------------------------------------ nesting
@pytest.mark.parametrize("text", DEEP_TEXTS.values(), ids=DEEP_TEXTS.keys())
def test_a_text_8000_levels_deep_is_refused_before_parsing_in_milliseconds(text: str) -> None:
    start = time.perf_counter()
    with pytest.raises(DefinitionError) as err:
        parse_text(text, ["body", "text"])
    took = time.perf_counter() - start
    assert took < FAST_S, f"refused after {took:.3f} s"  # (before: 31 to 70 s for the flow lists)
    [found] = err.value.details
    assert found["loc"] == ["body", "text"]
    assert f"deeper than {MAX_DEPTH} levels" in found["msg"]


def test_every_example_and_its_json_form_pass_the_nesting_scan() -> None:
    import yaml

    from isolab.studies.authoring.authoring import example_names, example_text, nesting_problem

    for name in example_names():
        text = example_text(name)
        assert nesting_problem(text, []) is None, name
        assert nesting_problem(json.dumps(yaml.safe_load(text), indent=4), []) is None, name


def test_a_text_just_within_the_depth_is_read() -> None:
    nested = "a: " + "[" * (MAX_DEPTH - 2) + "1" + "]" * (MAX_DEPTH - 2)
    data, _ = parse_text(nested, ["body", "text"])
    assert data["a"] == json.loads("[" * (MAX_DEPTH - 2) + "1" + "]" * (MAX_DEPTH - 2))


@pytest.mark.slow
def test_over_http_two_deep_texts_take_no_slot_and_a_small_request_is_answered_at_once(tmp_path) -> None:
    body = json.dumps({"text": DEEP_TEXTS["flow-lists"]}).encode()
    with thread_server(create_app(Settings(data_dir=tmp_path, scheduler_address=shared_scheduler(1)))) as url:
        with httpx.Client(base_url=url, timeout=60.0) as http:
            for _ in range(2):
                start = time.perf_counter()
                r = http.post("/studies/validate", content=body, headers={"content-type": "application/json"})
                assert r.status_code == 422, r.text
                assert r.json()["detail"][0]["loc"] == ["body", "text"]
                assert f"deeper than {MAX_DEPTH} levels" in r.json()["detail"][0]["msg"]
                assert time.perf_counter() - start < 1.0
            small = http.post("/studies/validate", json={"text": "name: x\n"})
            assert small.status_code == 422 and "scene" in small.text


# ---------------------------------------------------------------------------------------- long lists
def mounts(n: int) -> list[dict[str, Any]]:
    return [{"position": [f"{(i % 300) * 0.01} m", f"{(i // 300) * 0.01} m", "0 m"]} for i in range(n)]


def test_100000_mounts_are_refused_from_the_lists_length_in_milliseconds() -> None:
    scene = quick_scene()
    scene["isolators"] = {"preset": "air", "list": mounts(100_000)}
    details, took = refused(study(scene=scene))
    assert took < FAST_S, f"refused after {took:.3f} s"  # (before: 22 s)
    assert [d["loc"] for d in details] == [["body", "scene", "isolators", "list"]]
    assert f"100000 mounts, more than the {MAX_MOUNTS}" in details[0]["msg"]


@pytest.mark.parametrize(
    ("where", "limit"),
    [("stages", MAX_STAGES), ("points", MAX_POINTS), ("segments", MAX_SEGMENTS), ("parameters", 64)],
)
def test_every_long_list_of_a_study_is_refused_naming_it_and_its_bound(where: str, limit: int) -> None:
    body = study()
    scene = body["scene"]
    if where == "stages":
        scene["stages"] = [{**scene["stages"][0], "name": f"s{i}"} for i in range(limit + 1)]
        loc = ["body", "scene", "stages"]
    elif where == "points":
        scene["points"] = {f"p{i}": ["0 m", "0 m", "0 m"] for i in range(limit + 1)}
        loc = ["body", "scene", "points"]
    elif where == "segments":
        move = {"type": "move", "distance": "1 mm", "velocity": "1 m/s", "acceleration": "1 g"}
        scene["stages"][0]["profile"] = {"type": "sequence", "segments": [move] * (limit + 1)}
        loc = ["body", "scene", "stages", 0, "profile", "segments"]
    else:
        body["parameters"] = [{"path": "isolators.preset", "values": ["air"]}] * (limit + 1)
        loc = ["body", "parameters"]
    details, took = refused(body)
    assert took < FAST_S
    assert [d["loc"] for d in details] == [loc]
    assert f"{limit + 1} {where}, more than the {limit}" in details[0]["msg"]


def test_the_models_state_the_bounds_too() -> None:
    scene = schema.Scene.model_json_schema()
    assert scene["properties"]["stages"]["maxItems"] == MAX_STAGES
    assert scene["properties"]["points"]["maxProperties"] == MAX_POINTS
    isolators = schema.Isolators.model_json_schema()
    assert isolators["properties"]["list"]["anyOf"][0]["maxItems"] == MAX_MOUNTS


@pytest.mark.slow
def test_over_http_100000_mounts_are_a_fast_422_and_health_stays_fast(tmp_path) -> None:
    scene = quick_scene()
    scene["isolators"] = {"preset": "air", "list": mounts(100_000)}
    content = json.dumps(study(scene=scene), separators=(",", ":")).encode()
    with thread_server(create_app(Settings(data_dir=tmp_path, scheduler_address=shared_scheduler(1)))) as url:
        worst = 0.0
        for _ in range(3):
            r, took, latencies = post_and_probe(url, content)
            assert r.status_code == 422, r.text
            assert r.json()["detail"][0]["loc"] == ["body", "scene", "isolators", "list"]
            assert took < 2.0, f"422 after {took:.2f} s (upload included)"
            assert statistics.median(latencies) < 0.1
            worst = max(worst, *latencies)
        # Parsed on the loop: 0.32 to 0.83 s; off it, 0.09 to 0.17 s on a busy two-core machine, about 1 s
        # when other test processes load both cores. Where the body is parsed is asserted without a clock
        # by test_a_large_body_is_parsed_in_a_worker_thread_without_the_collector; this bound holds the
        # 2.6 s stall of a list checked after parsing off, with room for a loaded machine.
        assert worst < 1.5, f"/health took {worst:.2f} s while the body was checked"


def test_a_large_body_is_parsed_in_a_worker_thread_without_the_collector(monkeypatch) -> None:
    seen: list[tuple[int, bool]] = []

    def watched(body: bytes) -> Any:
        seen.append((threading.get_ident(), gc.isenabled()))
        return json.loads(body)

    # the parser as the module calls it: which thread, and whether the collector runs meanwhile
    monkeypatch.setattr(request_limits, "json", SimpleNamespace(loads=watched))
    loop_threads: list[int] = []
    router = APIRouter(route_class=request_limits.JsonParsedOffLoop)

    @router.post("/echo")
    async def echo(body: dict[str, Any] = Body()) -> dict[str, int]:
        loop_threads.append(threading.get_ident())
        return {"mounts": len(body["list"])}

    app = FastAPI()
    app.include_router(router)
    big = {"list": mounts(20_000)}
    assert len(json.dumps(big)) > request_limits.LOOP_SCAN_BYTES
    with TestClient(app) as http:
        r = http.post("/echo", json=big)
        assert r.status_code == 200 and r.json() == {"mounts": 20_000}
        [(parser, collecting)] = seen
        assert parser != loop_threads[0]  # not the event loop's thread
        assert not collecting and gc.isenabled()  # paused while parsing, running again after
        assert http.post("/echo", json={"list": mounts(3)}).json() == {"mounts": 3}
        assert seen[1][0] == loop_threads[1]  # a small body is parsed on the loop
        bad = http.post(
            "/echo",
            content=b'{"list": [' + b"1," * 200_000 + b"]}",
            headers={"content-type": "application/json"},
        )
        assert bad.status_code == 422 and bad.json()["detail"][0]["type"] == "json_invalid"


def test_overlapping_collector_pauses_end_with_the_last() -> None:
    pause = request_limits.CollectorPause()
    assert gc.isenabled()
    with pause.paused():
        with pause.paused():
            assert not gc.isenabled()
        assert not gc.isenabled()
    assert gc.isenabled()


# ------------------------------------------------------------------------------------- smaller ones
def test_a_name_is_free_text_never_read_as_a_quantity() -> None:
    accepted = check_definition(study(name="spindle at 2^13 rpm ** 9"), 1_000_000)
    assert accepted.name == "spindle at 2^13 rpm ** 9"


def test_a_saltelli_design_of_one_sample_is_refused_at_submission() -> None:
    body = study(
        parameters=[{"path": "isolators.f_vertical", "range": {"start": "2 Hz", "stop": "4 Hz"}}],
        design={"type": "saltelli", "samples": 1},
    )
    details, _ = refused(body)
    assert [d["loc"] for d in details] == [["body", "design", "samples"]]
    assert "at least 2 base samples" in details[0]["msg"]
    body["design"]["samples"] = 2
    assert check_definition(body, 1_000_000).n_cases == 2 * (1 + 2)


@pytest.mark.parametrize(("field", "value"), [("samples", 16), ("second_order", True)])
def test_an_optimize_design_refuses_samples_and_second_order(field: str, value: Any) -> None:
    body = study(
        parameters=[{"path": "isolators.f_vertical", "range": {"start": "2 Hz", "stop": "4 Hz"}}],
        design={"type": "optimize", "objective": "minimize settling_time.tool", "budget": 20, field: value},
    )
    details, _ = refused(body)
    assert [d["loc"] for d in details] == [["body", "design", field]]
    assert "an optimize design does not take it" in details[0]["msg"]


def test_a_key_written_twice_is_refused_naming_it_and_its_line() -> None:
    text = "name: first\nscene:\n  machine: {}\nname: second\n"
    with pytest.raises(DefinitionError) as err:
        check_text(text, 1_000_000, 1)
    [found] = err.value.details
    assert found["line"] == 4
    assert "'name' is written twice" in found["msg"] and "lines 1, 4" in found["msg"]
    nested = "name: x\nscene:\n  machine:\n    mass: 1 t\n    mass: 2 t\n"
    with pytest.raises(DefinitionError) as err:
        check_text(nested, 1_000_000, 1)
    assert err.value.details[0]["line"] == 5 and "'mass'" in err.value.details[0]["msg"]


def test_the_same_key_in_two_mappings_is_not_a_duplicate() -> None:
    base = copy.deepcopy(study())
    text = json.dumps(base)  # every stage and point has its own "name"/axis keys: no false alarm
    assert check_text(text, 1_000_000, 1)["n_cases"] == 2
