"""The API description (``/openapi.json``) says what the service does, for the settings it runs with.

FastAPI describes each route from its signature; :func:`describe_settings` adds what the app around the
routes does:

- the bearer token: with ``ISOLAB_API_TOKEN`` set, the guarded routes declare the bearer security scheme
  and document their 401; with no token set nothing is declared (the API is open);
- the request limits (:mod:`isolab.service.api.request_limits`): every route that takes a body documents the
  413 of a body too large and the 422 of a body nested too deep or holding a non-finite number;
- the store (:mod:`isolab.service.api.unavailable`): every route of a study or a calibration documents the
  503 of a store that cannot be used just now (a full disk, a catalog SQLite refuses).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from fastapi import FastAPI

from isolab.service.settings import Settings

METHODS = ("get", "put", "post", "delete", "patch", "head", "options", "trace")
MESSAGE = {"$ref": "#/components/schemas/MessageBody"}
VALIDATION_ERROR = {"$ref": "#/components/schemas/ValidationErrorBody"}
STORE_PATHS = ("/studies", "/calibrations")
"""The routes that read or write the study store (a catalog row, a study's or a calibration's files)."""
STORE_UNAVAILABLE = (
    "the study store is unavailable just now (a full disk, the catalog cannot be read or written); "
    "`Retry-After` says when to try again"
)


def _json(schema: dict[str, Any], description: str) -> dict[str, Any]:
    return {"description": description, "content": {"application/json": {"schema": schema}}}


def adjust(spec: dict[str, Any], settings: Settings) -> dict[str, Any]:
    """``spec`` (FastAPI's description of the routes) made to match the app under ``settings``."""
    schemas = spec.setdefault("components", {}).setdefault("schemas", {})
    schemas.setdefault(
        "MessageBody",
        {
            "properties": {"detail": {"type": "string", "title": "Detail"}},
            "required": ["detail"],
            "type": "object",
            "title": "MessageBody",
        },
    )
    for path, ops in spec.get("paths", {}).items():
        for method, op in ops.items():
            if method not in METHODS:
                continue
            responses = op.setdefault("responses", {})
            if "security" in op:
                if settings.api_token is None:
                    del op["security"]
                else:
                    responses.setdefault("401", _json(MESSAGE, "missing or wrong bearer token"))
            if path.startswith(STORE_PATHS):
                responses.setdefault("503", _json(MESSAGE, STORE_UNAVAILABLE))
            if "requestBody" in op:
                responses.setdefault("413", _json(MESSAGE, "request body larger than ISOLAB_MAX_BODY_BYTES"))
                if "422" not in responses:
                    responses["422"] = _json(VALIDATION_ERROR, "invalid input; `loc` names the field")
    if settings.api_token is None:
        spec["components"].pop("securitySchemes", None)
    return spec


def describe_settings(app: FastAPI, settings: Settings) -> None:
    """Make ``app.openapi()`` (and ``/openapi.json``) answer the description :func:`adjust` makes."""
    default: Callable[[], dict[str, Any]] = app.openapi

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is None:
            app.openapi_schema = adjust(default(), settings)
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]
