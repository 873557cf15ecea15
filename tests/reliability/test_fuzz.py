"""Property-based fuzzing of every operation in the OpenAPI description (schemathesis), against the ASGI
app with its lifespan running: a LocalCluster of two workers and a study store in a temporary directory.

No answer may be a 5xx, and every answer must conform to the description (status code, content type,
body schema). Bounded: at most ``MAX_EXAMPLES`` generated requests per operation, no deadline."""

from __future__ import annotations

import shutil
import tempfile
import uuid
from pathlib import Path

import pytest
import schemathesis
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, settings
from live_service import quick_scene
from schemathesis.checks import (
    content_type_conformance,
    not_a_server_error,
    response_schema_conformance,
    status_code_conformance,
)
from starlette.types import Receive, Scope, Send

from isolab.service.app import create_app
from isolab.service.settings import Settings

pytestmark = pytest.mark.slow  # services, clusters or processes of their own: `make test-fast` skips them

MAX_EXAMPLES = 30


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


# the data directory is made by the lifespan, so collecting this module leaves nothing behind
DATA = Path(tempfile.gettempdir()) / f"isolab-fuzz-{uuid.uuid4().hex}"
APP = create_app(Settings(data_dir=DATA, workers=2, max_cases=500))
schema = schemathesis.openapi.from_asgi("/openapi.json", OwnLifespan(APP))


@pytest.fixture(scope="module", autouse=True)
def running_app():
    """The app's lifespan for the module (a 2-worker LocalCluster), with one finished study."""
    with TestClient(APP) as http:
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
    shutil.rmtree(DATA, ignore_errors=True)


@schema.parametrize()
@settings(max_examples=MAX_EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck))
def test_every_operation_answers_within_its_description(case) -> None:
    case.call_and_validate(
        checks=[
            not_a_server_error,
            status_code_conformance,
            content_type_conformance,
            response_schema_conformance,
        ],
        timeout=60,
    )
