"""Property-based fuzzing of every operation in the OpenAPI description (schemathesis, every check it has),
against the ASGI app with its lifespan running: a LocalCluster of two workers and a study store in a
temporary directory. Twice: an open service (no token: no security is declared) and a guarded one (a token:
the bearer scheme and the 401 of every guarded route are declared), sharing the cluster and the store.

No answer may be a 5xx, and every answer must conform to the description (status code, content type,
headers, body schema, ``Allow`` of a 405, 401 without the token); inputs the description forbids must be
refused and inputs it allows accepted. Bounded: at most ``MAX_EXAMPLES`` generated requests per operation
and phase, no deadline.

Operations whose input is a language of its own (a study definition, YAML text, a scene, a measurement, the
columns of a stored study) are checked by the service beyond what a JSON schema can say: for them an input
the description allows may still be answered 422 (documented, naming the field); every other operation
must accept what its description allows.
"""

from __future__ import annotations

import re
import shutil
import tempfile
import tomllib
import uuid
from pathlib import Path

import pytest
import schemathesis
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, settings
from schemathesis.config import SchemathesisConfig
from starlette.types import Receive, Scope, Send

from benchmarks.live_service import quick_scene
from isolab.service.api.app import create_app
from isolab.service.settings import Settings

pytestmark = pytest.mark.slow  # services, clusters or processes of their own: `make test-fast` skips them

MAX_EXAMPLES = 10


class OwnLifespan:
    """The app for the fuzzer's in-process client: requests go through, the lifespan (Dask cluster, study
    queue) is the fixture's, started once."""

    def __init__(self, app):
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "lifespan":
            await self.app(scope, receive, send)
            return
        while True:
            message = await receive()
            if message["type"] == "lifespan.startup":
                await send({"type": "lifespan.startup.complete"})
            elif message["type"] == "lifespan.shutdown":
                await send({"type": "lifespan.shutdown.complete"})
                return


TOKEN = "fuzz-token-of-the-lab"

#: What the fuzzer expects beyond the description, shared with ``schemathesis run`` from the checkout: the
#: operations that check their input beyond its JSON schema (a definition, YAML text, a scene, a
#: measurement, a point or the columns of the stored study) may refuse an input the schema allows with a
#: 422, and a body too large for ISOLAB_MAX_BODY_BYTES is refused with the documented 413.
PROJECT_CONFIG = Path(__file__).resolve().with_name("schemathesis.toml")


def fuzz_config(token: str | None) -> SchemathesisConfig:
    config = tomllib.loads(PROJECT_CONFIG.read_text())
    config["headers"] = {"Authorization": f"Bearer {token}"} if token else {}
    return SchemathesisConfig.from_dict(config)


# the data directory is made by the lifespan, so collecting this module leaves nothing behind
DATA = Path(tempfile.gettempdir()) / f"isolab-fuzz-{uuid.uuid4().hex}"
APP = create_app(Settings(data_dir=DATA, workers=2, max_cases=500))
GUARDED = create_app(Settings(data_dir=DATA, workers=2, max_cases=500, api_token=TOKEN))
open_schema = schemathesis.openapi.from_asgi("/openapi.json", OwnLifespan(APP), config=fuzz_config(None))
guarded_schema = schemathesis.openapi.from_asgi(
    "/openapi.json", OwnLifespan(GUARDED), config=fuzz_config(TOKEN)
)


@pytest.fixture(scope="module", autouse=True)
def running_app():
    """The app's lifespan for the module (a 2-worker LocalCluster), with one finished study; the guarded
    app shares its cluster, study queue and calibration jobs."""
    with TestClient(APP) as http:
        GUARDED.state.dask = APP.state.dask
        GUARDED.state.jobs = APP.state.jobs
        GUARDED.state.calibrations = APP.state.calibrations
        r = http.post(
            "/studies",
            json={
                "name": "fuzz-seed",
                "scene": quick_scene(),
                "parameters": [{"path": "isolators.preset", "values": ["air", "elastomer"]}],
            },
        )
        assert r.status_code == 202, r.text
        yield APP
        GUARDED.state.dask = GUARDED.state.jobs = GUARDED.state.calibrations = None
    shutil.rmtree(DATA, ignore_errors=True)


@open_schema.parametrize()
@settings(max_examples=MAX_EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck))
def test_every_operation_answers_within_its_description(case) -> None:
    """No token: the description declares no security, and every check holds."""
    case.call_and_validate(timeout=60)


@guarded_schema.parametrize()
@settings(max_examples=MAX_EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck))
def test_every_operation_answers_within_its_description_with_a_token(case) -> None:
    """A token: the bearer scheme and the 401s are declared; requests without it are refused as described."""
    case.call_and_validate(headers={"Authorization": f"Bearer {TOKEN}"}, timeout=60)


def test_the_description_declares_the_token_only_when_one_is_set() -> None:
    for app, token in ((APP, None), (GUARDED, TOKEN)):
        spec = app.openapi()
        schemes = spec.get("components", {}).get("securitySchemes", {})
        guarded = spec["paths"]["/studies"]["get"]
        assert bool(schemes) == (token is not None)
        assert ("security" in guarded) == (token is not None)
        assert ("401" in guarded["responses"]) == (token is not None)
        assert "security" not in spec["paths"]["/health"]["get"]
        for path, ops in spec["paths"].items():
            for method, op in ops.items():
                if "requestBody" in op:
                    assert {"413", "422"} <= set(op["responses"]), (method, path)


def test_the_project_config_names_operations_the_description_holds() -> None:
    """Each operation ``schemathesis.toml`` lets refuse a schema-valid input is one the description holds
    (a renamed route would otherwise lose its exemption silently), and /comparisons/floor.png is one."""
    spec = APP.openapi()
    operations = [(m.upper(), p) for p, ops in spec["paths"].items() for m in ops]
    exempt = tomllib.loads(PROJECT_CONFIG.read_text())["operations"]
    for rule in exempt:
        method, pattern = rule["include-method"], rule["include-path-regex"]
        assert any(m == method and re.search(pattern, p) for m, p in operations), rule
    assert any(re.search(r["include-path-regex"], "/comparisons/floor.png") for r in exempt)


def test_a_route_of_the_store_documents_its_503() -> None:
    spec = APP.openapi()
    for path, ops in spec["paths"].items():
        for method, op in ops.items():
            if path.startswith(("/studies", "/calibrations")):
                assert "503" in op["responses"], (method, path)
    assert "503" in spec["paths"]["/calibrations/{calibration_id}"]["get"]["responses"]
