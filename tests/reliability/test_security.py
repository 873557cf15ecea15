"""Security on a shared network, against a real server (uvicorn on loopback, one Dask worker): the bearer
token on every route but /health, study ids that name no path outside the store, CORS only for the
configured origins, and definitions that are data (never code, never a file name)."""

from __future__ import annotations

import http.client
import re
import time
from pathlib import Path
from typing import Any

import httpx
import pytest

from benchmarks.live_service import quick_scene, thread_server
from isolab.service.api.app import create_app
from isolab.service.api.schemas import EXAMPLE_CALIBRATION, EXAMPLE_COMPARISON, EXAMPLE_STUDY_TEXT
from isolab.service.settings import Settings
from tests.shared_cluster import shared_scheduler

pytestmark = pytest.mark.slow  # services, clusters or processes of their own: `make test-fast` skips them

TOKEN = "s3cret-token-of-the-lab"
ALLOWED = "https://lab.example"
FOREIGN = "https://evil.example"
SECRET = "TOP SECRET: not part of any study"

STUDY = {
    "name": "../../escape/../../etc/passwd",
    "description": "__import__('os').system('touch pwned')",
    "scene": quick_scene(),
    "parameters": [{"path": "isolators.preset", "values": ["air", "elastomer"]}],
    "design": {"type": "grid"},
}

CATALOGUE_TEXT = (Path(__file__).resolve().parents[2] / "studies/catalogues/representative.yaml").read_text()

# Every route of the app: (method, path template) -> how to call it with the right token, and the answer.
ROUTES: dict[tuple[str, str], dict[str, Any]] = {
    ("GET", "/health"): {"status": 200, "open": True},
    ("GET", "/studies"): {"status": 200},
    ("POST", "/studies"): {"status": 202, "json": STUDY},
    ("GET", "/studies/{study_id}"): {"status": 200},
    ("GET", "/studies/{study_id}/dataset"): {"status": 200},
    ("GET", "/studies/{study_id}/cases"): {"status": 200},
    ("GET", "/studies/{study_id}/cases/{case}/timeseries"): {"status": 200, "params": {"every": 50}},
    ("GET", "/studies/{study_id}/cases/{case}/plot.png"): {"status": 200},
    ("GET", "/studies/{study_id}/plot.png"): {
        "status": 200,
        "params": {"y": "peak_displacement_y", "x": "isolator_type"},
    },
    ("POST", "/comparisons"): {"status": 200, "json": EXAMPLE_COMPARISON},
    ("POST", "/sizings"): {"status": 200, "json": {"scene": EXAMPLE_COMPARISON["scene"], "max_cases": 1}},
    ("POST", "/comparisons/floor.png"): {
        "status": 200,
        "json": {
            **EXAMPLE_COMPARISON,
            "scene": {**EXAMPLE_COMPARISON["scene"], "floor": {"spectrum": {"z": "VC-D"}}},
            "point": "tool",
        },
    },
    ("POST", "/comparisons/floor"): {
        "status": 200,
        "json": {
            **EXAMPLE_COMPARISON,
            "scene": {**EXAMPLE_COMPARISON["scene"], "floor": {"spectrum": {"z": "VC-D"}}},
        },
    },
    # the guarded study stands on no floor spectrum: answered (422, naming the case) with the token
    ("GET", "/studies/{study_id}/cases/{case}/floor"): {"status": 422},
    # the guarded study has two cases, too few for an index: answered (422, naming the output) with the token
    ("GET", "/studies/{study_id}/sensitivity"): {"status": 422, "params": {"output": "peak_displacement.y"}},
    ("GET", "/studies/{study_id}/sensitivity.png"): {
        "status": 422,
        "params": {"output": "peak_displacement.y"},
    },
    ("POST", "/calibrations"): {"status": 202, "json": EXAMPLE_CALIBRATION},
    # no calibration of that id: answered (404) with the token
    ("GET", "/calibrations/{calibration_id}"): {"status": 404},
    ("DELETE", "/calibrations/{calibration_id}"): {"status": 404},
    ("DELETE", "/studies/{study_id}"): {"status": 204},
    ("GET", "/examples"): {"status": 200},
    ("GET", "/examples/{name}"): {"status": 200},
    ("POST", "/studies/validate"): {"status": 200, "json": {"text": EXAMPLE_STUDY_TEXT}},
    ("GET", "/studies/{study_id}/definition.yaml"): {"status": 200},
    ("GET", "/studies/{study_id}/design"): {"status": 200},
    ("GET", "/studies/{study_id}/error-estimate"): {"status": 200},
    ("GET", "/studies/{study_id}/answer"): {"status": 200},
    ("GET", "/studies/{study_id}/report.html"): {"status": 200},
    ("POST", "/simulations"): {
        "status": 200,
        "json": {"scene": EXAMPLE_COMPARISON["scene"], "max_points": 50},
    },
    ("POST", "/scenes/check"): {"status": 200, "json": {"scene": EXAMPLE_COMPARISON["scene"]}},
    ("POST", "/catalogues/read"): {"status": 200, "json": {"text": CATALOGUE_TEXT}},
    ("GET", "/scenes/examples"): {"status": 200},
    ("GET", "/scenes/examples/{name}"): {"status": 200},
}


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> dict:
    root = tmp_path_factory.mktemp("lab")
    data = root / "data"
    (root / "secret.txt").write_text(SECRET)
    settings = Settings(
        data_dir=data, scheduler_address=shared_scheduler(1), api_token=TOKEN, cors_origins=(ALLOWED,)
    )
    app = create_app(settings)
    with thread_server(app) as url:
        yield {"url": url, "data": data, "root": root, "app": app}


@pytest.fixture(scope="module")
def api(server: dict):
    with httpx.Client(
        base_url=server["url"], timeout=60.0, headers={"Authorization": f"Bearer {TOKEN}"}
    ) as c:
        yield c


@pytest.fixture(scope="module")
def done(api: httpx.Client) -> str:
    """A study run to the end through the guarded API (its name and description are hostile text)."""
    r = api.post("/studies", json=STUDY)
    assert r.status_code == 202, r.text
    sid = r.json()["id"]
    deadline = time.monotonic() + 90
    while (info := api.get(f"/studies/{sid}").json())["status"] in ("queued", "running"):
        assert time.monotonic() < deadline, info
        time.sleep(0.1)
    assert info["status"] == "done", info
    return sid


def concrete(path: str, study_id: str) -> str:
    return (
        path.replace("{study_id}", study_id)
        .replace("{case}", "0")
        .replace("{name}", "isolator-comparison")
        .replace("{calibration_id}", "0" * 32)
    )


def call(
    client: httpx.Client, method: str, path: str, spec: dict, params: dict | None = None, **kwargs: Any
) -> httpx.Response:
    return client.request(method, path, params=params or spec.get("params"), json=spec.get("json"), **kwargs)


# ------------------------------------------------------------------------------------------ the token
def test_the_table_covers_every_route_of_the_app(server: dict) -> None:
    spec = server["app"].openapi()
    routes = {(method.upper(), path) for path, ops in spec["paths"].items() for method in ops}
    assert routes == set(ROUTES), "a route was added or removed: give it a line in ROUTES"


@pytest.mark.parametrize(("method", "path"), list(ROUTES), ids=[f"{m} {p}" for m, p in ROUTES])
def test_every_route_but_health_wants_the_token(
    server: dict, api: httpx.Client, done: str, method: str, path: str
) -> None:
    spec = ROUTES[(method, path)]
    url = concrete(path, done)
    with httpx.Client(base_url=server["url"], timeout=60.0) as bare:
        for headers in (
            {},
            {"Authorization": "Bearer wrong-token"},
            {"Authorization": f"Bearer {TOKEN}x"},
            {"Authorization": f"Bearer {TOKEN[:-1]}"},
            {"Authorization": "Bearer"},
            {"Authorization": f"Basic {TOKEN}"},
            {"Authorization": TOKEN},
            {"X-API-Token": TOKEN},
        ):
            r = call(bare, method, url, spec, headers=headers)
            if spec.get("open"):
                assert r.status_code == spec["status"], (headers, r.status_code)
            else:
                assert r.status_code == 401, (headers, r.status_code, r.text[:200])
                assert r.headers["www-authenticate"] == "Bearer"
                assert r.json() == {"detail": "missing or wrong bearer token"}
        r = call(bare, method, url, spec, params={**spec.get("params", {}), "token": TOKEN})
        assert r.status_code == (spec["status"] if spec.get("open") else 401)
    if method == "DELETE":  # the study the other routes read stays: delete one of its own
        sid = api.post("/studies", json=STUDY).json()["id"]
        url = concrete(path, sid)
    r = call(api, method, url, spec)
    assert r.status_code == spec["status"], r.text[:500]


def test_the_bearer_scheme_is_case_insensitive_and_the_token_exact(server: dict) -> None:
    with httpx.Client(base_url=server["url"], timeout=30.0) as bare:
        assert bare.get("/studies", headers={"Authorization": f"bearer {TOKEN}"}).status_code == 200
        assert bare.get("/studies", headers={"Authorization": f"Bearer {TOKEN.upper()}"}).status_code == 401


def test_the_api_description_is_public_and_holds_no_study(server: dict, done: str) -> None:
    """/docs and /openapi.json describe the API (no data): they answer without the token."""
    with httpx.Client(base_url=server["url"], timeout=30.0) as bare:
        spec = bare.get("/openapi.json")
        assert spec.status_code == 200 and done not in spec.text
        assert bare.get("/docs").status_code == 200


def test_the_web_page_shells_are_public_and_hold_no_study(server: dict, done: str) -> None:
    """The page's HTML, scripts and the reference pages carry no data: every datum comes from the API,
    with the token (tests/browser drive it)."""
    with httpx.Client(base_url=server["url"], timeout=30.0) as bare:
        for path in (
            "/ui/",
            "/ui/new",
            "/ui/compare",
            f"/ui/studies/{done}",
            f"/ui/studies/{done}/cases/0",
            "/ui/assets/common.js",
            "/redoc",
        ):
            r = bare.get(path)
            assert r.status_code == 200, path
            assert done not in r.text and "escape" not in r.text, path


# ------------------------------------------------------------------------------------ path traversal
TRAVERSALS = [
    "..",
    "...",
    "%2e%2e",
    "..%2Fcatalog.sqlite",
    "..%2F..%2Fsecret.txt",
    "%2e%2e%2f%2e%2e%2fsecret.txt",
    "..%252F..%252Fsecret.txt",
    "..%5C..%5Csecret.txt",
    "%2Fetc%2Fpasswd",
    "catalog.sqlite",
    "studies%2F..%2F..%2Fsecret.txt",
    "....%2F%2F....%2F%2Fsecret.txt",
    "%00",
    "0123456789abcdef0123456789abcdef%00",
    "0123456789ABCDEF0123456789ABCDEF",
    "0123456789abcdef0123456789abcdef.nc",
    "0123456789abcdef0123456789abcde",
    "%200123456789abcdef0123456789abcdef",
]


def raw_get(url: str, raw_path: str, method: str = "GET") -> tuple[int, bytes]:
    """A request whose path is sent exactly as written (no client normalises ../ or decodes %2F)."""
    host, port = url.removeprefix("http://").split(":")
    conn = http.client.HTTPConnection(host, int(port), timeout=30)
    try:
        conn.putrequest(method, raw_path, skip_accept_encoding=True)
        conn.putheader("Authorization", f"Bearer {TOKEN}")
        conn.endheaders()
        response = conn.getresponse()
        return response.status, response.read()
    finally:
        conn.close()


def wait_until_idle(api: httpx.Client, timeout: float = 90.0) -> None:
    """Wait until no study of the module's service is queued or running (their files appear meanwhile)."""
    deadline = time.monotonic() + timeout
    while any(api.get("/studies", params={"status": s}).json()["total"] for s in ("queued", "running")):
        assert time.monotonic() < deadline, "studies still running"
        time.sleep(0.1)


@pytest.mark.parametrize(("method", "path"), [k for k in ROUTES if "{study_id}" in k[1]])
def test_study_ids_name_no_path_outside_the_store(
    server: dict, api: httpx.Client, done: str, method: str, path: str
) -> None:
    wait_until_idle(api)  # the studies earlier tests submitted write their datasets when they end
    spec = ROUTES[(method, path)]
    query = "&".join(f"{k}={v}" for k, v in spec.get("params", {}).items())
    before = sorted(p.relative_to(server["root"]) for p in server["root"].rglob("*"))
    for attempt in [*TRAVERSALS, f"{done}%2F..%2F..%2F..%2Fsecret.txt", f"..%2F{done}"]:
        for raw in (
            concrete(path, attempt),
            "/studies/../../secret.txt",
            f"/studies/{done}/../../../secret.txt",
        ):
            status, body = raw_get(server["url"], raw + (f"?{query}" if query else ""), method)
            assert status in (404, 422), (raw, status, body[:200])
            assert SECRET.encode() not in body and b"SQLite format" not in body
            assert b"root:" not in body
    after = sorted(p.relative_to(server["root"]) for p in server["root"].rglob("*"))
    assert [p for p in after if p not in before and "catalog.sqlite" not in str(p)] == []
    assert (server["root"] / "secret.txt").read_text() == SECRET


def test_case_numbers_are_integers_not_paths(server: dict, done: str) -> None:
    for case in ("..%2F..%2Fsecret.txt", "-1", "1e3", "0x1", "%2e%2e"):
        status, body = raw_get(server["url"], f"/studies/{done}/cases/{case}/timeseries")
        assert status in (404, 422), (case, status)
        assert SECRET.encode() not in body


# ------------------------------------------------------------------------------------------- CORS
def test_cors_answers_the_configured_origin_only(server: dict, done: str) -> None:
    with httpx.Client(base_url=server["url"], timeout=30.0) as bare:
        for origin, allowed in (
            (ALLOWED, True),
            (FOREIGN, False),
            ("null", False),
            (ALLOWED + ".evil", False),
        ):
            preflight = bare.options(
                "/studies",
                headers={
                    "Origin": origin,
                    "Access-Control-Request-Method": "POST",
                    "Access-Control-Request-Headers": "authorization, content-type",
                },
            )
            # the preflight carries no token and is answered by CORS, not refused by the token
            assert preflight.headers.get("access-control-allow-origin") == (origin if allowed else None)
            assert preflight.status_code == (200 if allowed else 400)
            for headers, status in (({"Authorization": f"Bearer {TOKEN}"}, 200), ({}, 401)):
                r = bare.get(f"/studies/{done}", headers={**headers, "Origin": origin})
                assert r.status_code == status
                assert r.headers.get("access-control-allow-origin") == (origin if allowed else None)
            r = bare.post(
                "/studies", json={"name": 1}, headers={"Authorization": f"Bearer {TOKEN}", "Origin": origin}
            )
            assert r.status_code == 422
            assert r.headers.get("access-control-allow-origin") == (origin if allowed else None)


def test_cors_is_closed_without_configured_origins(tmp_path: Path) -> None:
    from fastapi.testclient import TestClient

    app = create_app(Settings(data_dir=tmp_path, api_token=TOKEN))
    client = TestClient(app)  # no lifespan needed: token and CORS answer first
    for method, path in [k for k in ROUTES if "{study_id}" not in k[1]]:
        r = client.options(path, headers={"Origin": ALLOWED, "Access-Control-Request-Method": method})
        assert "access-control-allow-origin" not in r.headers
        r = client.request(method, path, headers={"Origin": ALLOWED})
        assert "access-control-allow-origin" not in r.headers
        assert "access-control-allow-credentials" not in r.headers


# ------------------------------------------------------------------- definitions are data, not code
def test_hostile_names_and_text_touch_no_file(server: dict, api: httpx.Client, done: str) -> None:
    info = api.get(f"/studies/{done}").json()
    assert info["name"] == STUDY["name"] and info["definition"]["description"] == STUDY["description"]
    files = sorted(p.name for p in (server["data"] / "studies").iterdir())
    assert f"{done}.nc" in files
    assert all(re.fullmatch(r"[0-9a-f]{32}(\.nc|\.chunks)", f) for f in files), files
    assert not list(server["root"].rglob("pwned")) and not Path("pwned").exists()
    assert not (server["root"] / "escape").exists()
    r = api.get(f"/studies/{done}/dataset")
    filename = re.search(r'filename="?([^";]+)"?', r.headers["content-disposition"]).group(1)
    assert filename == f"escape_etc_passwd-{done}.nc"


@pytest.mark.parametrize(
    "text",
    [
        "__import__('os').system('touch pwned') kg",
        "eval('1') kg",
        "open('/etc/passwd').read() kg",
        "`touch pwned` kg",
        "$(touch pwned) kg",
    ],
)
def test_quantity_text_is_parsed_never_evaluated(server: dict, api: httpx.Client, text: str) -> None:
    body = {**STUDY, "scene": quick_scene()}
    body["scene"]["stages"][0]["mass"] = text
    r = api.post("/studies", json=body)
    assert r.status_code == 422
    assert r.json()["detail"][0]["loc"] == ["body", "scene", "stages", 0, "mass"]
    assert not list(server["root"].rglob("pwned")) and not Path("pwned").exists()


def test_filter_text_is_parsed_never_evaluated(server: dict, api: httpx.Client, done: str) -> None:
    for text in (
        "__import__('os').system('touch pwned')==1",
        "status==__import__('os')",
        "peak_displacement_y<1 m**9**9**9",
        "peak_isolator_force_y<1 N^9^9^9",
    ):
        t0 = time.monotonic()
        r = api.get(f"/studies/{done}/cases", params={"filter": text})
        assert r.status_code == 422, (text, r.text)
        assert time.monotonic() - t0 < 10
        assert r.json()["detail"][0]["loc"] == ["query", "filter"]
    assert not list(server["root"].rglob("pwned")) and not Path("pwned").exists()


def test_scene_file_names_are_never_opened(server: dict, api: httpx.Client) -> None:
    for name in ("../secret.txt", str(server["root"] / "secret.txt"), "catalog.sqlite"):
        body = {k: v for k, v in STUDY.items() if k != "scene"} | {"scene_file": name}
        r = api.post("/studies", json=body)
        assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "scene_file"]
        assert SECRET not in r.text


def test_non_finite_filter_values_are_refused(api: httpx.Client, done: str) -> None:
    """``1e999`` read as infinity matched every case: inf, nan and literals beyond a 64-bit float, with or
    without a unit, are a 422 naming the filter (issue 13)."""
    for text in (
        "peak_displacement_y<1e999",
        "peak_displacement_y>-1e999",
        "peak_displacement_y<=1e999 mm",
        "peak_displacement_y<1e308 km",
        "peak_displacement_y<inf",
        "peak_displacement_y<-inf m",
        "peak_displacement_y!=nan",
        "peak_displacement_y<Infinity",
        "peak_displacement_y>=NaN mm",
    ):
        r = api.get(f"/studies/{done}/cases", params={"filter": text})
        assert r.status_code == 422, (text, r.text[:300])
        detail = r.json()["detail"][0]
        assert detail["loc"] == ["query", "filter"] and "finite" in detail["msg"], (text, detail)
    r = api.get(f"/studies/{done}/cases", params={"filter": "peak_displacement_y<1e300"})
    assert r.status_code == 200 and r.json()["n_matched"] == r.json()["n_cases"]


# ------------------------------------------------------------------------------------------ /health
def test_health_without_the_token_gives_the_status_only(server: dict) -> None:
    """/health stays open for load balancers, but without the token it tells only the status: no store
    path, no scheduler or worker addresses (issue 13)."""
    root = str(server["root"].resolve())
    with httpx.Client(base_url=server["url"], timeout=30.0) as bare:
        for headers in ({}, {"Authorization": "Bearer wrong-token"}, {"Authorization": f"Basic {TOKEN}"}):
            r = bare.get("/health", headers=headers)
            assert r.status_code == 200, r.text
            assert r.json() == {"status": "ok"}, (headers, r.text)
            assert root not in r.text and "tcp://" not in r.text
        full = bare.get("/health", headers={"Authorization": f"Bearer {TOKEN}"})
    assert full.status_code == 200
    report = full.json()
    assert report["status"] == "ok" and report["store"]["path"] == str(server["data"].resolve())
    assert report["dask"]["n_workers"] >= 1
