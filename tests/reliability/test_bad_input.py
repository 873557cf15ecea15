"""Malformed and hostile study definitions POSTed to a real server (uvicorn on loopback, one Dask worker).

Every one is answered 422 (413 for size) within seconds, with a ``loc`` and a message that name the field;
none gives a 500 or a hang, and none leaves anything in the catalog or the store directory.
"""

from __future__ import annotations

import copy
import json
import select
import socket
import time
from collections.abc import Callable
from http.client import HTTPConnection
from pathlib import Path
from typing import Any

import httpx
import pytest

from benchmarks.live_service import quick_scene, thread_server
from isolab.service.api.app import create_app
from isolab.service.api.request_limits import MAX_JSON_DEPTH
from isolab.service.settings import Settings
from tests.shared_cluster import shared_scheduler

pytestmark = pytest.mark.slow  # services, clusters or processes of their own: `make test-fast` skips them

MAX_CASES = 1000
MAX_BODY = 1024 * 1024
ANSWER_WITHIN_S = 10.0

BASE: dict[str, Any] = {
    "name": "bad-input-base",
    "scene": quick_scene(),
    "parameters": [
        {"path": "isolators.preset", "values": ["air", "elastomer"]},
        {"path": "stages.y.profile.acceleration", "values": ["1 g", "2 g"]},
    ],
    "design": {"type": "grid"},
}


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> dict:
    data = tmp_path_factory.mktemp("data")
    settings = Settings(
        data_dir=data, scheduler_address=shared_scheduler(1), max_cases=MAX_CASES, max_body_bytes=MAX_BODY
    )
    with thread_server(create_app(settings)) as url:
        yield {"url": url, "data": data}


@pytest.fixture(scope="module")
def http(server: dict):
    with httpx.Client(base_url=server["url"], timeout=60.0) as client:
        yield client


def edit(change: Callable[[dict], Any]) -> dict:
    d = copy.deepcopy(BASE)
    change(d)
    return d


def setter(*path: str | int, value: Any) -> Callable[[dict], None]:
    def change(d: dict) -> None:
        node = d
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = value

    return change


def deleter(*path: str | int) -> Callable[[dict], None]:
    def change(d: dict) -> None:
        node = d
        for key in path[:-1]:
            node = node[key]
        del node[path[-1]]

    return change


def machine(**fields: Any) -> Callable[[dict], None]:
    base = {"mass": "10000 kg", "cg": ["1.3 m", "2.1 m", "0.17 m"], "inertia_diagonal": [1.5e4, 6e3, 2e4]}
    base.update(fields)
    for key in [k for k, v in base.items() if v is None]:
        del base[key]
    return setter("scene", "machine", value=base)


def mounts(*xy: tuple[float, float]) -> Callable[[dict], None]:
    return setter(
        "scene", "isolators", value={"preset": "air", "list": [{"position": [x, y, 0.0]} for x, y in xy]}
    )


def params(*specs: dict, design: dict | None = None) -> Callable[[dict], None]:
    def change(d: dict) -> None:
        d["parameters"] = list(specs)
        d["design"] = design or {"type": "grid"}

    return change


MASS = ("scene", "stages", 0, "mass")
MASS_LOC = ["body", "scene", "stages", 0, "mass"]

# (id, definition, expected loc prefix, words the message holds)
CATALOGUE: list[tuple[str, dict, list, str]] = [
    # missing fields
    ("missing-name", edit(deleter("name")), ["body", "name"], "Field required"),
    ("missing-scene", edit(deleter("scene")), ["body", "scene"], "scene: missing"),
    ("missing-machine", edit(deleter("scene", "machine")), ["body", "scene", "machine"], "Field required"),
    (
        "missing-isolators",
        edit(deleter("scene", "isolators")),
        ["body", "scene", "isolators"],
        "Field required",
    ),
    (
        "missing-profile",
        edit(deleter("scene", "stages", 0, "profile")),
        ["body", "scene", "stages", 0, "profile"],
        "Field required",
    ),
    ("machine-without-mass", edit(machine(mass=None)), ["body", "scene", "machine"], "missing mass"),
    # wrong types
    ("name-is-a-number", edit(setter("name", value=42)), ["body", "name"], "string"),
    (
        "parameters-not-a-list",
        edit(setter("parameters", value={"path": "stages.y.mass"})),
        ["body", "parameters"],
        "list",
    ),
    ("mass-is-a-list", edit(setter(*MASS, value=[1000])), MASS_LOC, "expected a mass"),
    ("mass-is-a-boolean", edit(setter(*MASS, value=True)), MASS_LOC, "boolean"),
    ("mass-is-a-length", edit(setter(*MASS, value="3 m")), MASS_LOC, "expected a mass"),
    ("mass-is-words", edit(setter(*MASS, value="heavy")), MASS_LOC, "cannot read"),
    (
        "stage-axis-zero",
        edit(setter("scene", "stages", 0, "axis", value=[0, 0, 0])),
        ["body", "scene", "stages", 0, "axis"],
        "zero vector",
    ),
    (
        "samples-not-an-integer",
        edit(
            params(
                {"path": "stages.y.mass", "range": {"start": 1, "stop": 2}},
                design={"type": "lhs", "samples": "many"},
            )
        ),
        ["body", "design", "samples"],
        "integer",
    ),
    ("unknown-design", edit(setter("design", value={"type": "magic"})), ["body", "design", "type"], "grid"),
    ("unknown-top-level-key", edit(setter("colour", value="red")), ["body", "colour"], "Extra inputs"),
    # NaN and infinity, as text
    ("mass-nan-text", edit(setter(*MASS, value="nan")), MASS_LOC, "finite"),
    ("mass-inf-text", edit(setter(*MASS, value="inf kg")), MASS_LOC, "finite"),
    ("mass-minus-infinity-text", edit(setter(*MASS, value="-Infinity")), MASS_LOC, "finite"),
    (
        "parameter-value-nan-text",
        edit(params({"path": "stages.y.mass", "values": ["500 kg", "nan kg"]})),
        ["body", "parameters", 0, "values", 1],
        "finite",
    ),
    (
        "range-stop-inf-text",
        edit(
            params(
                {"path": "stages.y.mass", "range": {"start": "1 kg", "stop": "inf kg"}},
                design={"type": "lhs", "samples": 8},
            )
        ),
        ["body", "parameters", 0, "range", "stop"],
        "finite",
    ),
    # negative or zero mass
    ("stage-mass-zero", edit(setter(*MASS, value=0)), MASS_LOC, "greater than 0"),
    ("stage-mass-negative", edit(setter(*MASS, value="-3 kg")), MASS_LOC, "greater than 0"),
    ("machine-mass-negative", edit(machine(mass=-5)), ["body", "scene", "machine", "mass"], "greater than 0"),
    ("machine-mass-zero", edit(machine(mass="0 kg")), ["body", "scene", "machine", "mass"], "greater than 0"),
    (
        "block-density-negative",
        edit(setter("scene", "machine", "block", "density", value="-2700 kg/m^3")),
        ["body", "scene", "machine", "block", "density"],
        "greater than 0",
    ),
    (
        "varied-mass-down-to-zero",
        edit(params({"path": "stages.y.mass", "values": ["500 kg", "0 kg"]})),
        ["body", "parameters", 0],
        "the value 0 kg makes the scene invalid",
    ),
    # inertia
    (
        "inertia-negative-definite",
        edit(machine(inertia_diagonal=None, inertia=[[1e4, 0, 0], [0, 1e4, 0], [0, 0, -1e4]])),
        ["body", "scene", "machine", "inertia"],
        "positive definite",
    ),
    (
        "inertia-indefinite",
        edit(machine(inertia_diagonal=None, inertia=[[1e4, 2e4, 0], [2e4, 1e4, 0], [0, 0, 1e4]])),
        ["body", "scene", "machine", "inertia"],
        "positive definite",
    ),
    (
        "inertia-not-symmetric",
        edit(machine(inertia_diagonal=None, inertia=[[1e4, 10, 0], [0, 1e4, 0], [0, 0, 1e4]])),
        ["body", "scene", "machine", "inertia"],
        "symmetric",
    ),
    (
        "inertia-no-rigid-body",
        edit(machine(inertia_diagonal=[1e3, 1e3, 5e3])),
        ["body", "scene", "machine", "inertia_diagonal"],
        "triangle inequality",
    ),
    (
        "cg-a-kilometre-away",
        edit(machine(cg=["1.3 km", "2.1 m", "0.17 m"])),
        ["body", "scene", "machine", "cg", 0],
        "between -100 m and 100 m",
    ),
    (
        "mount-at-1e300-m",
        edit(mounts((0.2, 0.3), (2.4, 0.3), (1e300, 3.9))),
        ["body", "scene", "isolators", "list", 2, "position", 0],
        "between -100 m and 100 m",
    ),
    # isolators
    ("two-isolators", edit(mounts((0.2, 0.3), (2.4, 3.9))), ["body", "scene", "isolators"], "at least 3"),
    (
        "isolators-on-one-line",
        edit(mounts((0.2, 0.3), (1.3, 2.1), (2.4, 3.9), (0.75, 1.2))),
        ["body", "scene", "isolators"],
        "one line",
    ),
    (
        "isolators-layout-and-list",
        edit(setter("scene", "isolators", "list", value=[{"position": [0, 0, 0]}] * 4)),
        ["body", "scene", "isolators"],
        "not both",
    ),
    (
        "unknown-isolator-type",
        edit(setter("scene", "isolators", "preset", value="springy")),
        ["body", "scene", "isolators", "preset"],
        "'active', 'air' or 'elastomer'",
    ),
    (
        "unknown-isolator-type-varied",
        edit(params({"path": "isolators.preset", "values": ["air", "springy"]})),
        ["body", "parameters", 0, "values", 1],
        "not one of active, air, elastomer",
    ),
    (
        "combination-no-mount-can-carry",
        edit(
            params(
                {"path": "stages.y.mass", "range": {"start": "4000 kg", "stop": "5000 kg"}},
                {"path": "isolators.layout.span_y", "range": {"start": "0.4 m", "stop": "0.5 m"}},
                design={"type": "lhs", "samples": 50},
            )
        ),
        ["body"],
        "would carry a static load",
    ),
    # stages
    (
        "travel-longer-than-machine",
        edit(setter("scene", "stages", 0, "profile", "travel", value="5 m")),
        ["body", "scene", "stages"],
        "stages[0].profile.travel",
    ),
    (
        "stage-parent-unknown",
        edit(setter("scene", "stages", 0, "parent", value="z")),
        ["body", "scene", "stages"],
        "stages[0].parent",
    ),
    # simulation
    (
        "time-step-zero",
        edit(setter("simulation", value={"dt": 0})),
        ["body", "simulation", "dt"],
        "greater than",
    ),
    (
        "duration-over-an-hour",
        edit(setter("simulation", value={"duration": "2 h"})),
        ["body", "simulation", "duration"],
        "less than or equal to 3600",
    ),
    (
        "exact-needs-lti",
        edit(setter("simulation", value={"fidelity": "ltv", "integrator": "exact"})),
        ["body", "simulation"],
        "time-invariant",
    ),
    # cases above the limit
    (
        "lhs-above-the-case-limit",
        edit(
            params(
                {"path": "stages.y.mass", "range": {"start": 1, "stop": 2}},
                design={"type": "lhs", "samples": MAX_CASES + 1},
            )
        ),
        ["body", "design", "samples"],
        f"limit of {MAX_CASES}",
    ),
    (
        "grid-above-the-case-limit",
        edit(
            params(
                {"path": "stages.y.mass", "range": {"start": 1, "stop": 2, "num": 40}},
                {"path": "isolators.zeta", "range": {"start": 0.05, "stop": 0.3, "num": 40}},
            )
        ),
        ["body", "parameters"],
        f"{40 * 40} cases",
    ),
    (
        "list-above-the-case-limit",
        edit(
            params(
                {"path": "stages.y.mass"},
                design={"type": "list", "cases": [{"stage_y_mass": 500}] * (MAX_CASES + 1)},
            )
        ),
        ["body", "design", "cases"],
        f"limit of {MAX_CASES}",
    ),
    (
        "ten-million-samples",
        edit(
            params(
                *[
                    {"path": p, "range": {"start": 0.1, "stop": 0.2}}
                    for p in (
                        "isolators.zeta",
                        "stages.y.home.z",
                        "points.tool.x",
                        "points.tool.y",
                        "points.tool.z",
                        "machine.block.corner.z",
                    )
                ],
                design={"type": "sobol", "samples": 10_000_000},
            )
        ),
        ["body", "design", "samples"],
        "10000000 cases",
    ),
    # parameter paths
    (
        "path-does-not-exist",
        edit(params({"path": "stages.z.mass", "values": [1, 2]})),
        ["body", "parameters", 0, "path"],
        "does not exist",
    ),
    (
        "path-python-attribute",
        edit(params({"path": "__class__.__init__.__globals__", "values": [1, 2]})),
        ["body", "parameters", 0, "path"],
        "does not exist",
    ),
    (
        "path-file-system",
        edit(params({"path": "../../etc/passwd", "values": [1, 2]})),
        ["body", "parameters", 0, "path"],
        "does not exist",
    ),
    (
        "path-shared-simulation-step",
        edit(params({"path": "simulation.dt", "values": [1e-3, 2e-3]})),
        ["body", "parameters", 0, "path"],
        "does not exist",
    ),
    # files are never read over REST
    (
        "scene-file",
        edit(setter("scene_file", value="article-scriber.yaml")),
        ["body", "scene_file"],
        "not read over the API",
    ),
    (
        "scene-file-instead-of-scene",
        edit(lambda d: (d.pop("scene"), d.update(scene_file="/etc/passwd"))),
        ["body", "scene_file"],
        "not read over the API",
    ),
    # quantity text the units parser cannot finish or no float holds
    ("power-tower", edit(setter(*MASS, value="9**9**9 kg")), MASS_LOC, "raised to a power again"),
    ("power-tower-caret", edit(setter(*MASS, value="9^9^9 kg")), MASS_LOC, "raised to a power again"),
    ("power-of-a-bracket", edit(setter(*MASS, value="2**(2**40) kg")), MASS_LOC, "plain number"),
    ("power-overflow", edit(setter(*MASS, value="10**999 kg")), MASS_LOC, "exponent 999"),
    ("unit-power-overflow", edit(setter(*MASS, value="kg**99999999")), MASS_LOC, "exponent"),
    ("float-power-overflow", edit(setter(*MASS, value="1e300**12 kg")), MASS_LOC, "64-bit float"),
    ("integer-beyond-float", edit(setter(*MASS, value=10**400)), MASS_LOC, "64-bit float"),
    ("quantity-text-too-long", edit(setter(*MASS, value="1" * 5000 + " kg")), MASS_LOC, "longer than"),
    (
        "power-in-a-parameter-value",
        edit(params({"path": "stages.y.mass", "values": ["500 kg", "2**2**2**2**2 kg"]})),
        ["body", "parameters", 0, "values", 1],
        "power",
    ),
]


def post(http: httpx.Client, **kwargs: Any) -> tuple[httpx.Response, float]:
    t0 = time.monotonic()
    r = http.post("/studies", **kwargs)
    return r, time.monotonic() - t0


def study_files(data: Path) -> list[str]:
    d = data / "studies"
    return sorted(p.name for p in d.iterdir()) if d.exists() else []


def test_the_base_definition_is_valid(http: httpx.Client) -> None:
    """The catalogue's definitions differ from an accepted one by one field each (checked without storing
    it: the catalog stays empty for the tests below)."""
    from isolab.studies.inputs.definitions import check_definition

    assert check_definition(copy.deepcopy(BASE), MAX_CASES).n_cases == 4


@pytest.mark.parametrize(
    ("definition", "loc", "words"), [c[1:] for c in CATALOGUE], ids=[c[0] for c in CATALOGUE]
)
def test_bad_definition_is_refused_naming_the_field(
    http: httpx.Client, server: dict, definition: dict, loc: list, words: str
) -> None:
    r, seconds = post(http, json=definition)
    assert r.status_code == 422, r.text[:2000]
    assert seconds < ANSWER_WITHIN_S
    details = r.json()["detail"]
    assert isinstance(details, list) and details
    hits = [d for d in details if d["loc"][: len(loc)] == loc and words in d["msg"]]
    assert hits, details
    assert http.get("/studies").json()["total"] == 0
    assert study_files(server["data"]) == []


@pytest.mark.parametrize(
    ("value", "words"),
    [(float("nan"), "finite"), (float("inf"), "finite"), (float("-inf"), "finite")],
    ids=["NaN", "Infinity", "-Infinity"],
)
def test_nan_and_infinity_literals_are_refused(http: httpx.Client, value: float, words: str) -> None:
    """JSON has no NaN, but Python's json (allow_nan) writes NaN/Infinity literals and servers parse them."""
    for change in (setter(*MASS, value=value), params({"path": "stages.y.mass", "values": [500.0, value]})):
        body = json.dumps(edit(change), allow_nan=True)
        assert "NaN" in body or "Infinity" in body
        r, _ = post(http, content=body.encode(), headers={"content-type": "application/json"})
        assert r.status_code == 422, r.text
        assert any(words in d["msg"] for d in r.json()["detail"]), r.json()
    assert http.get("/studies").json()["total"] == 0


@pytest.mark.parametrize("depth", [MAX_JSON_DEPTH + 1, 1000, 10_000, 100_000])
@pytest.mark.parametrize("kind", ["arrays", "objects"])
def test_deeply_nested_json_is_422_not_a_recursion_error(http: httpx.Client, depth: int, kind: str) -> None:
    if kind == "arrays":
        text = '{"name": "deep", "scene": ' + "[" * depth + "]" * depth + "}"
    else:
        text = '{"name": "deep", "scene": ' + '{"a": ' * depth + "1" + "}" * depth + "}"
    r, seconds = post(http, content=text.encode(), headers={"content-type": "application/json"})
    assert r.status_code == 422, r.text[:500]
    assert seconds < ANSWER_WITHIN_S
    assert r.json()["detail"][0]["loc"] == ["body"]
    assert f"deeper than {MAX_JSON_DEPTH}" in r.json()["detail"][0]["msg"]


@pytest.mark.parametrize(
    ("content", "content_type"),
    [
        (b"", "application/json"),
        (b"[1, 2]", "application/json"),
        (b"null", "application/json"),
        (b'"a study"', "application/json"),
        (b'{"name": "x", ', "application/json"),
        (bytes(range(256)), "application/json"),
        (b"name=x", "application/x-www-form-urlencoded"),
        (b'{"name": "caf\xe9 \xff\xfe"}', "application/json"),
        (b'{"name": "x", "scene": ' + b"7" * 5000 + b"}", "application/json"),
    ],
    ids=["empty", "array", "null", "string", "truncated", "binary", "form", "not-utf-8", "5000-digit-number"],
)
def test_bodies_that_are_not_a_json_object(http: httpx.Client, content: bytes, content_type: str) -> None:
    r, _ = post(http, content=content, headers={"content-type": content_type})
    assert r.status_code == 422, r.text
    assert r.json()["detail"][0]["loc"][0] == "body"


def _raw_post(url: str, head: bytes, chunks, timeout: float = 5.0) -> tuple[bytes, int, float]:
    """Send ``head`` then ``chunks`` until the server answers; (answer, body bytes sent, seconds)."""
    host, port = url.removeprefix("http://").split(":")
    sock = socket.create_connection((host, int(port)), timeout=timeout)
    sent = 0
    t0 = time.monotonic()
    try:
        sock.sendall(head)
        for chunk in chunks:
            if select.select([sock], [], [], 0)[0]:
                break  # the server has answered
            try:
                sock.sendall(chunk)
            except (BrokenPipeError, ConnectionResetError, TimeoutError):
                break  # the server stopped reading
            sent += len(chunk)
        answer = b""
        while b"\r\n\r\n" not in answer:
            part = sock.recv(65536)
            if not part:
                break
            answer += part
        return answer, sent, time.monotonic() - t0
    finally:
        sock.close()


FIFTY_MB = 50 * 1024 * 1024
PIECE = 64 * 1024


def test_a_50_mb_body_with_content_length_is_413_before_it_is_sent(http: httpx.Client, server: dict) -> None:
    head = (
        f"POST /studies HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
        f"Content-Length: {FIFTY_MB}\r\n\r\n"
    ).encode()
    answer, sent, seconds = _raw_post(server["url"], head, (b" " * PIECE for _ in range(FIFTY_MB // PIECE)))
    assert answer.startswith(b"HTTP/1.1 413"), answer[:200]
    assert sent < 16 * MAX_BODY and seconds < ANSWER_WITHIN_S  # answered on the headers alone
    assert http.get("/health").status_code == 200
    assert http.get("/studies").json()["total"] == 0


def test_a_50_mb_chunked_body_is_413_once_the_limit_is_passed(http: httpx.Client, server: dict) -> None:
    """No Content-Length: the server counts what arrives and answers as soon as it passes the limit; the
    rest of the 50 MB is never read."""
    head = (
        b"POST /studies HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
        b"Transfer-Encoding: chunked\r\n\r\n"
    )
    piece = f"{PIECE:x}\r\n".encode() + b" " * PIECE + b"\r\n"
    answer, sent, seconds = _raw_post(server["url"], head, (piece for _ in range(FIFTY_MB // PIECE)))
    assert answer.startswith(b"HTTP/1.1 413"), answer[:200]
    assert b"ISOLAB_MAX_BODY_BYTES" in answer or b"413" in answer
    assert sent < 16 * MAX_BODY, f"the client got {sent} bytes into the server before the answer"
    assert seconds < ANSWER_WITHIN_S
    assert http.get("/health").status_code == 200


def test_a_body_just_over_the_limit_is_413_naming_the_setting(http: httpx.Client) -> None:
    body = json.dumps(edit(setter("description", value="x" * MAX_BODY))).encode()
    r, _ = post(http, content=body, headers={"content-type": "application/json"})
    assert r.status_code == 413 and "ISOLAB_MAX_BODY_BYTES" in r.json()["detail"]
    assert http.get("/studies").json()["total"] == 0


def test_after_all_of_them_a_good_study_still_runs(http: httpx.Client, server: dict) -> None:
    assert http.get("/studies").json()["total"] == 0
    r = http.post("/studies", json=BASE)
    assert r.status_code == 202, r.text
    sid = r.json()["id"]
    deadline = time.monotonic() + 120  # the first study of a cold kernel cache waits for the compile
    while (info := http.get(f"/studies/{sid}").json())["status"] in ("queued", "running"):
        assert time.monotonic() < deadline, info
        time.sleep(0.1)
    assert info["status"] == "done" and info["progress"] == {"done": 4, "total": 4, "failed": 0}
    listed = http.get("/studies").json()
    assert listed["total"] == 1 and listed["items"][0]["id"] == sid
    assert study_files(server["data"]) == [f"{sid}.nc"]


def test_time_histories_too_long_are_refused_before_they_are_computed(http: httpx.Client) -> None:
    """A valid study whose cases run for an hour at 1 ms: recomputing a case's time histories would hold
    gigabytes in the API process, so the request is refused at once, naming what to change."""
    from isolab.studies.answers.history import MAX_RECORDED_SAMPLES, MAX_RETURNED_SAMPLES

    hour = {"name": "an-hour", "scene": quick_scene(duration="1 h", dt="1 ms")}
    sid = http.post("/studies", json=hour).json()["id"]
    long_ten_min = {"name": "ten-minutes", "scene": quick_scene(duration="10 min", dt="2 ms")}
    sid2 = http.post("/studies", json=long_ten_min).json()["id"]
    try:
        t0 = time.monotonic()
        r = http.get(f"/studies/{sid}/cases/0/timeseries")
        assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["path", "case"]
        assert f"at most {MAX_RECORDED_SAMPLES}" in r.json()["detail"][0]["msg"]
        r = http.get(f"/studies/{sid}/cases/0/plot.png")
        assert r.status_code == 422
        r = http.get(f"/studies/{sid2}/cases/0/timeseries")  # 300,001 samples
        assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["query", "every"]
        assert f"keep at most {MAX_RETURNED_SAMPLES} (every >= 2)" in r.json()["detail"][0]["msg"]
        assert time.monotonic() - t0 < ANSWER_WITHIN_S
    finally:
        for s in (sid, sid2):
            assert http.delete(f"/studies/{s}").status_code == 204
            assert http.delete(f"/studies/{s}").status_code in (204, 404)
    assert {i["id"] for i in http.get("/studies").json()["items"]}.isdisjoint({sid, sid2})


# -------------------------------------------------------------- NaN and Infinity in any body (issue 13)
# (path, body, loc): Python's json reads NaN, Infinity and a literal beyond a 64-bit float as non-finite
# floats; FastAPI's 422 echoed them and could not encode its own answer (a 500, the connection dropped).
NON_FINITE_BODIES: list[tuple[str, str, list]] = [
    ("/comparisons", '{"scene": NaN}', ["body", "scene"]),
    ("/comparisons", "NaN", ["body"]),
    ("/comparisons", '{"description": Infinity}', ["body", "description"]),
    (
        "/comparisons",
        '{"scene": {}, "isolator_types": ["air"], "simulation": {"dt": -Infinity}}',
        ["body", "simulation", "dt"],
    ),
    ("/comparisons", '{"scene": {}, "catalogue": "representative", "margin": NaN}', ["body", "margin"]),
    (
        "/comparisons",
        '{"scene": {}, "catalogue": {"products": [{"price": Infinity}]}}',
        ["body", "catalogue", "products", 0, "price"],
    ),
    ("/comparisons/floor.png", '{"scene": {}, "point": NaN}', ["body", "point"]),
    ("/studies", "NaN", ["body"]),
    ("/studies", "[NaN]", ["body", 0]),
    ("/studies", '{"name": "x", "scene": Infinity}', ["body", "scene"]),
    (
        "/studies",
        '{"name": "x", "scene": {"machine": {"mass": 1e999}}}',
        ["body", "scene", "machine", "mass"],
    ),
    ("/studies", '{"name": "x", "description": -1e400, "scene": {}}', ["body", "description"]),
    ("/calibrations", "Infinity", ["body"]),
    (
        "/calibrations",
        '{"scene": {}, "measurement": {"time": [0, NaN]}, "fit": []}',
        ["body", "measurement", "time", 1],
    ),
    ("/studies/validate", '{"text": NaN}', ["body", "text"]),
    ("/studies/validate", "[Infinity]", ["body", 0]),
    ("/simulations", '{"scene": NaN}', ["body", "scene"]),
    ("/simulations", '{"scene": {"machine": {"mass": Infinity}}}', ["body", "scene", "machine", "mass"]),
    ("/scenes/check", '{"scene": {"machine": {"mass": -Infinity}}}', ["body", "scene", "machine", "mass"]),
    ("/sizings", '{"scene": {}, "margin": NaN}', ["body", "margin"]),
    ("/catalogues/read", '{"text": NaN}', ["body", "text"]),
    ("/comparisons/floor", '{"scene": {}, "description": NaN}', ["body", "description"]),
]


def test_every_route_that_takes_a_body_is_in_the_non_finite_table(tmp_path: Path) -> None:
    spec = create_app(Settings(data_dir=tmp_path)).openapi()
    with_body = {
        (method.upper(), path)
        for path, ops in spec["paths"].items()
        for method, op in ops.items()
        if "requestBody" in op
    }
    assert with_body == {("POST", p) for p, _, _ in NON_FINITE_BODIES}


def test_nan_and_infinity_anywhere_in_a_body_are_422_naming_the_field(server: dict) -> None:
    """Every body holding NaN, Infinity or 1e999, on every route that takes one: 422 naming where it is,
    and the keep-alive connection stays open for the next request."""
    host, port = server["url"].removeprefix("http://").split(":")
    conn = HTTPConnection(host, int(port), timeout=30)
    try:
        conn.request("GET", "/health")
        conn.getresponse().read()
        sock = conn.sock
        for path, body, loc in NON_FINITE_BODIES:
            conn.request("POST", path, body=body.encode(), headers={"Content-Type": "application/json"})
            response = conn.getresponse()
            answer = response.read()
            assert response.status == 422, (path, body, response.status, answer[:300])
            detail = json.loads(answer)["detail"]
            assert detail[0]["loc"] == loc, (path, body, detail)
            assert "finite" in detail[0]["msg"], detail
            assert response.getheader("connection", "").lower() != "close", (path, body)
            conn.request("GET", "/health")
            assert conn.getresponse().read()
            assert conn.sock is sock, f"the connection was dropped after {path} {body}"
    finally:
        conn.close()
