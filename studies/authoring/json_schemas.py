"""The JSON Schema (draft-07) of study and scene files, made from the pydantic models.

:func:`study_json_schema` and :func:`scene_json_schema` carry ``$schema``, ``$id`` and ``title``; the
service publishes them at ``GET /schemas/study.json`` and ``GET /schemas/scene.json``, for the YAML
language server's modeline ``# yaml-language-server: $schema=http://127.0.0.1:8000/schemas/study.json``.
Quantities accept a number (SI) or a string with units; each carries its dimension and SI unit
(``x-dimension``, ``x-unit``) and its accepted range (``exclusiveMinimum``, ``minimum``, ``maximum``, with
``x-range-reason``). :func:`model_schema_text` is the models' own schema (pydantic's draft 2020-12), what
the Markdown reference (:mod:`studies.authoring.reference_markdown`) walks.
"""

from __future__ import annotations

import functools
import json
from typing import Any

from pydantic import BaseModel
from pydantic.json_schema import GenerateJsonSchema, models_json_schema

from isolab.studies.inputs.schema import Scene
from isolab.studies.inputs.study import Study
from isolab.studies.questions.criteria import Criteria, PointCriteria

SCHEMA_DIALECT = "http://json-schema.org/draft-07/schema#"
"""The JSON Schema draft the published schemas follow: the draft the YAML language server validates with
(pydantic writes draft 2020-12; :func:`_draft7` turns its tuples and ``$defs`` into draft-07's)."""
DEFAULT_BASE_URL = "http://127.0.0.1:8000"
"""Where ``isolab serve`` listens by default: the ``$id`` of a schema made without a request."""
STUDY_SCHEMA_PATH = "/schemas/study.json"
SCENE_SCHEMA_PATH = "/schemas/scene.json"

EXTRA_KEYS: dict[type[BaseModel], tuple[type[BaseModel], str, str]] = {
    Criteria: (
        PointCriteria,
        "<point>",
        "any other key is a point of interest (a key of the scene's `points`): the limits at that point",
    ),
}
"""Models that accept keys of their own choosing (``extra="allow"``): the model each such key's value
is, the placeholder the reference writes for the key and what it says of it."""


class _FileSchema(GenerateJsonSchema):
    """Pydantic's JSON schema, with the value of a ``default_factory`` written as the field's default."""

    def get_default_value(self, schema: Any) -> Any:
        factory = schema.get("default_factory")
        if factory is not None and not schema.get("default_factory_takes_data"):
            return factory()
        return super().get_default_value(schema)


def _model_schema(root: type[BaseModel]) -> dict[str, Any]:
    """The validation JSON schema of ``root`` with the models of :data:`EXTRA_KEYS` in its ``$defs``,
    and every such model's free keys described by its value model."""
    extras = [value for value, _, _ in EXTRA_KEYS.values()]
    _, top = models_json_schema(
        [(root, "validation"), *[(m, "validation") for m in extras]],
        by_alias=True,
        ref_template="#/$defs/{model}",
        schema_generator=_FileSchema,
    )
    defs = top["$defs"]
    schema = defs.pop(root.__name__)
    for model, (value, key, text) in EXTRA_KEYS.items():
        node = defs.get(model.__name__)
        if node is not None:
            node["additionalProperties"] = {"$ref": f"#/$defs/{value.__name__}", "description": text}
            node["x-extra-key"] = key
    schema["$defs"] = {name: defs[name] for name in _reached(schema, defs)}
    return schema


def _refs(node: Any) -> list[str]:
    """Names of the ``$defs`` that ``node`` refers to, in order of appearance (not through other defs)."""
    out: list[str] = []
    stack = [node]
    while stack:
        n = stack.pop()
        if isinstance(n, dict):
            ref = n.get("$ref")
            if isinstance(ref, str) and ref.startswith("#/$defs/"):
                out.append(ref.removeprefix("#/$defs/"))
            stack.extend(reversed([v for k, v in n.items() if k not in ("$defs", "default")]))
        elif isinstance(n, list):
            stack.extend(reversed(n))
    return out


def _reached(root: dict[str, Any], defs: dict[str, Any]) -> list[str]:
    """The ``$defs`` reached from ``root``, depth first in the order the keys are written."""
    order: list[str] = []

    def visit(name: str) -> None:
        if name in order or name not in defs:
            return
        order.append(name)
        for ref in _refs(defs[name]):
            visit(ref)

    for ref in _refs(root):
        visit(ref)
    return order


@functools.lru_cache(maxsize=4)
def model_schema_text(root: type[BaseModel]) -> str:
    """:func:`_model_schema` as JSON text, made once per process (each caller gets a fresh copy)."""
    return json.dumps(_model_schema(root))


def _draft7(schema: dict[str, Any]) -> dict[str, Any]:
    """``schema`` (pydantic's draft 2020-12) in draft-07 terms: ``definitions`` for ``$defs`` and a tuple's
    ``prefixItems`` as the array form of ``items`` (its ``items``, if any, as ``additionalItems``)."""
    text = json.dumps(schema).replace('"#/$defs/', '"#/definitions/')
    out = json.loads(text)
    if "$defs" in out:
        out["definitions"] = out.pop("$defs")
    stack: list[Any] = [out]
    while stack:
        node = stack.pop()
        if isinstance(node, dict):
            if "prefixItems" in node:
                if "items" in node:
                    node["additionalItems"] = node.pop("items")
                node["items"] = node.pop("prefixItems")
            stack.extend(v for k, v in node.items() if k not in ("default", "examples", "const", "enum"))
        elif isinstance(node, list):
            stack.extend(node)
    return out


def _published(root: type[BaseModel], title: str, schema_id: str) -> dict[str, Any]:
    schema = _draft7(json.loads(model_schema_text(root)))
    return {"$schema": SCHEMA_DIALECT, "$id": schema_id, **schema, "title": title}


def study_json_schema(base_url: str = DEFAULT_BASE_URL) -> dict[str, Any]:
    """The JSON Schema of a study file (YAML or JSON), ``$id`` ``<base_url>/schemas/study.json``."""
    return _published(Study, "isolab study file", base_url.rstrip("/") + STUDY_SCHEMA_PATH)


def scene_json_schema(base_url: str = DEFAULT_BASE_URL) -> dict[str, Any]:
    """The JSON Schema of a scene file (YAML or JSON), ``$id`` ``<base_url>/schemas/scene.json``."""
    return _published(Scene, "isolab scene file", base_url.rstrip("/") + SCENE_SCHEMA_PATH)
