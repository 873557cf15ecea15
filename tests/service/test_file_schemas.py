"""``GET /schemas/study.json`` and ``/schemas/scene.json``: the JSON Schema editors check files with.

The app is built without its lifespan (no Dask cluster): the routes read nothing but the models.
"""

from __future__ import annotations

from pathlib import Path

import jsonschema
import yaml
from fastapi.testclient import TestClient

from isolab.service.api.app import create_app
from isolab.service.settings import Settings

ROOT = Path(__file__).resolve().parents[2]


def test_the_schemas_are_published_without_the_token_with_their_own_address(tmp_path: Path) -> None:
    app = create_app(Settings(data_dir=tmp_path, workers=1, api_token="s3cret-token-for-the-test"))
    bare = TestClient(app)  # no lifespan: nothing but the routes
    assert bare.get("/studies").status_code == 401  # the API wants the token...
    study = bare.get("/schemas/study.json")
    assert study.status_code == 200  # ...the file schemas do not: they hold no data
    assert study.headers["content-type"].startswith("application/json")
    schema = study.json()
    assert schema["$schema"] == "http://json-schema.org/draft-07/schema#"
    assert schema["$id"] == "http://testserver/schemas/study.json"
    assert schema["title"] == "isolab study file"
    example = yaml.safe_load((ROOT / "studies/examples/isolator-comparison.yaml").read_text())
    validator = jsonschema.Draft7Validator(schema)
    assert list(validator.iter_errors(example)) == []
    assert not validator.is_valid({**example, "parameter": example["parameters"]})

    scene = bare.get("/schemas/scene.json").json()
    assert scene["$id"] == "http://testserver/schemas/scene.json"
    assert scene["title"] == "isolab scene file"
    scriber = yaml.safe_load((ROOT / "studies/examples/article-scriber.yaml").read_text())
    assert jsonschema.Draft7Validator(scene).is_valid(scriber)
    assert "/schemas/study.json" not in app.openapi()["paths"]  # files, not the API: like /openapi.json
