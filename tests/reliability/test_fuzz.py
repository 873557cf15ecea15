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

import shutil
import tempfile
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

#: Operations that check their input beyond its JSON schema (a definition, YAML text, a scene, a
#: measurement, columns of the stored study): an input the schema allows may be refused with a 422.
CHECKED_BEYOND_THE_SCHEMA = [
    ("POST", r"^/studies$"),
    ("POST", r"^/studies/validate$"),
    ("POST", r"^/comparisons$"),
    ("POST", r"^/calibrations$"),
    ("GET", r"^/studies/\{study_id\}/cases$"),
    ("GET", r"^/studies/\{study_id\}/plot\.png$"),
    ("GET", r"^/studies/\{study_id\}/cases/\{case\}/timeseries$"),
    ("GET", r"^/studies/\{study_id\}/sensitivity(\.png)?$"),
]


#: schemathesis's default answers to an input the description forbids
NEGATIVE_REFUSALS = ["400", "401", "403", "404", "405", "406", "409", "415", "422", "428", "429", "5xx"]


def fuzz_config(token: str | None) -> SchemathesisConfig:
    return SchemathesisConfig.from_dict(
        {
            "headers": {"Authorization": f"Bearer {token}"} if token else {},
            # a body too large for ISOLAB_MAX_BODY_BYTES (a text of a million escaped characters) is
            # refused with the documented 413 before it is read: that too is a refusal
            "checks": {"negative_data_rejection": {"expected-statuses": [*NEGATIVE_REFUSALS, "413"]}},
            "operations": [
                {
                    "include-method": method,
                    "include-path-regex": path,
                    "checks": {
                        "positive_data_acceptance": {
                            "expected-statuses": ["2xx", "3xx", "401", "403", "404", "409", "422", "429"]
                        }
                    },
                }
                for method, path in CHECKED_BEYOND_THE_SCHEMA
            ],
        }
    )


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
    app shares its cluster and study queue."""
    with TestClient(APP) as http:
        GUARDED.state.dask = APP.state.dask
        GUARDED.state.jobs = APP.state.jobs
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
        GUARDED.state.dask = GUARDED.state.jobs = None
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
