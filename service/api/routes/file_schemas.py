"""``GET /schemas/study.json`` and ``GET /schemas/scene.json``: the JSON Schema of study and scene files.

Editors read them through the YAML language server's modeline
(``# yaml-language-server: $schema=http://127.0.0.1:8000/schemas/study.json``); they describe files, not
the API, hold no data and answer without the token, like ``/openapi.json``. Their ``$id`` is the address
they were fetched from. The schemas are made by :mod:`isolab.studies.authoring.file_reference`.
"""

from __future__ import annotations

from fastapi import APIRouter, Request
from fastapi.responses import JSONResponse

from isolab.studies.authoring.file_reference import scene_json_schema, study_json_schema

router = APIRouter(include_in_schema=False)


def _base_url(request: Request) -> str:
    return str(request.base_url).rstrip("/")


@router.get("/schemas/study.json")
def study_schema(request: Request) -> JSONResponse:
    """The JSON Schema of a study file."""
    return JSONResponse(study_json_schema(_base_url(request)))


@router.get("/schemas/scene.json")
def scene_schema(request: Request) -> JSONResponse:
    """The JSON Schema of a scene file."""
    return JSONResponse(scene_json_schema(_base_url(request)))
