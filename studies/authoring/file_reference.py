"""The reference of study and scene files: every key, and the JSON Schema editors check the files with.

Both are made from the pydantic models (:class:`studies.study.Study`, :class:`studies.schema.Scene` and
everything below them), so a field added to a model appears in both without further work:

- :func:`study_json_schema` and :func:`scene_json_schema`: the JSON Schema (draft-07) of a study file
  and of a scene file, with ``$schema``, ``$id`` and ``title``; the service publishes them at
  ``GET /schemas/study.json`` and ``GET /schemas/scene.json``, for the YAML language server's modeline
  ``# yaml-language-server: $schema=http://127.0.0.1:8000/schemas/study.json``. Quantities accept a number
  (SI) or a string with units; each carries its dimension and SI unit (``x-dimension``, ``x-unit``) and
  its accepted range (``exclusiveMinimum``, ``minimum``, ``maximum``, with ``x-range-reason``).
- :func:`render`: ``docs/study-files.md``, one table per model walked from that schema (key, type, unit,
  default, accepted range, description), the parameter paths a study may vary (read from the example
  scene by :func:`studies.parameters.available_paths`) and every design type with an example.

Regenerate the document with ``make docs`` (``python -m isolab.studies.authoring.file_reference >
docs/study-files.md``); a test fails while it differs from :func:`render`.
"""

from __future__ import annotations

import copy
import functools
import json
import re
import sys
from pathlib import Path
from typing import Any

import yaml
from pydantic import BaseModel
from pydantic.json_schema import GenerateJsonSchema, models_json_schema

from isolab.studies.inputs.parameters import CATEGORICAL, available_paths, resolve
from isolab.studies.inputs.schema import DesignSpec, Scene
from isolab.studies.inputs.study import Study, load_scene
from isolab.studies.questions.criteria import Criteria, PointCriteria

SCHEMA_DIALECT = "http://json-schema.org/draft-07/schema#"
"""The JSON Schema draft the published schemas follow: the draft the YAML language server validates with
(pydantic writes draft 2020-12; :func:`_draft7` turns its tuples and ``$defs`` into draft-07's)."""
DEFAULT_BASE_URL = "http://127.0.0.1:8000"
"""Where ``isolab serve`` listens by default: the ``$id`` of a schema made without a request."""
STUDY_SCHEMA_PATH = "/schemas/study.json"
SCENE_SCHEMA_PATH = "/schemas/scene.json"
EXAMPLES_DIR = Path(__file__).resolve().parent.parent / "examples"
EXAMPLE_SCENE = EXAMPLES_DIR / "article-scriber.yaml"
"""The scene whose parameter paths the reference lists, and which the design examples run on."""

EXTRA_KEYS: dict[type[BaseModel], tuple[type[BaseModel], str, str]] = {
    Criteria: (
        PointCriteria,
        "<point>",
        "any other key is a point of interest (a key of the scene's `points`): the limits at that point",
    ),
}
"""Models that accept keys of their own choosing (``extra="allow"``): the model each such key's value
is, the placeholder the reference writes for the key and what it says of it."""

DESIGN_EXAMPLES: dict[str, tuple[str, str]] = {
    "grid": (
        "Full factorial: every combination of the parameters' `values` (or `range` with `num` levels). "
        "The dataset has one dimension per parameter.",
        """\
parameters:
  - path: isolators.preset
    values: [active, air, elastomer]
  - path: stages.y.profile.acceleration
    range: {start: 0.5 g, stop: 2 g, num: 4}
design:
  type: grid                   # 3 x 4 = 12 cases
""",
    ),
    "lhs": (
        "Latin hypercube of `samples` cases over the parameters' ranges (each range cut into `samples` "
        "strata, each hit once); the same `seed` gives the same cases.",
        """\
parameters:
  - path: isolators.f_vertical
    range: {start: 1.5 Hz, stop: 6 Hz, scale: log}
  - path: stages.y.mass
    range: {start: 500 kg, stop: 1500 kg}
design:
  type: lhs
  samples: 200
  seed: 1
""",
    ),
    "sobol": (
        "Scrambled Sobol' sequence of `samples` cases (best balanced when `samples` is a power of 2).",
        """\
parameters:
  - path: isolators.zeta
    range: {start: 2 %, stop: 40 %}
  - path: isolators.layout.span_y
    range: {start: 2.4 m, stop: 4.0 m}
design:
  type: sobol
  samples: 256
""",
    ),
    "random": (
        "Independent uniform samples: `samples` cases; a categorical parameter draws from its `values`.",
        """\
parameters:
  - path: isolators.preset
    values: [air, elastomer]
  - path: stages.y.profile.acceleration
    range: {start: 0.5 g, stop: 2 g}
design:
  type: random
  samples: 100
  seed: 7
""",
    ),
    "saltelli": (
        "Saltelli's scheme for Sobol' sensitivity indices (`isolab sensitivity`): `samples` is the base "
        "sample N, the study runs N (D + 2) cases for D parameters (N (2D + 2) with `second_order: true`). "
        "Ranges only: no categorical parameter.",
        """\
parameters:
  - path: isolators.f_vertical
    range: {start: 1.5 Hz, stop: 6 Hz, scale: log}
  - path: isolators.zeta
    range: {start: 5 %, stop: 40 %}
  - path: stages.y.mass
    range: {start: 500 kg, stop: 1500 kg}
design:
  type: saltelli
  samples: 64                  # 64 x (3 + 2) = 320 cases
""",
    ),
    "list": (
        "The cases one by one: each entry of `cases` maps every parameter's name to its value (units "
        "allowed). Parameters then need neither `values` nor `range`.",
        """\
parameters:
  - path: isolators.preset                 # name: isolator_type
  - path: stages.y.profile.acceleration    # name: stage_y_acceleration
design:
  type: list
  cases:
    - {isolator_type: air, stage_y_acceleration: 1 g}
    - {isolator_type: elastomer, stage_y_acceleration: 1.5 g}
    - {isolator_type: active, stage_y_acceleration: 2 g}
""",
    ),
    "optimize": (
        "An optimiser (pymoo) picks the cases generation by generation, at most `budget` in all: "
        "`objective` is `minimize <output>` or `maximize <output>` (a list of them for a Pareto front), "
        "`constraints` the word `criteria` (every criterion met) or `<output> <= <value>` with units.",
        """\
parameters:
  - path: isolators.f_vertical
    range: {start: 1.5 Hz, stop: 6 Hz}
  - path: isolators.zeta
    range: {start: 5 %, stop: 40 %}
design:
  type: optimize
  objective: minimize settling_time
  constraints: ["min_isolator_load >= 0 N"]
  budget: 200
  population: 20
""",
    ),
}
"""Per design type: what it does and a ``parameters:``/``design:`` example (on :data:`EXAMPLE_SCENE`)."""

VARIANT_SCENE_CHANGES = """\
machine:
  mass: 10000 kg
  cg: [1.3 m, 2.1 m, 0.17 m]
  inertia_diagonal: [1.5e4 kg m^2, 5.7e3 kg m^2, 2e4 kg m^2]
isolators:
  preset: air
  list:
    - {position: [0.2 m, 0.3 m, -0.33 m], k: [2e5 N/m, 2e5 N/m, 1.2e6 N/m]}
    - {position: [2.4 m, 0.3 m, -0.33 m]}
    - {position: [2.4 m, 3.9 m, -0.33 m]}
    - {position: [0.2 m, 3.9 m, -0.33 m]}
floor:
  sine: {amplitude: [0, 0, 2 um], frequency: [0, 0, 12 Hz]}
"""
"""What the reference's second scene changes in :data:`EXAMPLE_SCENE`: a machine by mass, an explicit
list of mounts and a sine floor, whose parameter paths the example scene has not."""
VARIANT_STAGE_PROFILES = {
    "y": {
        "type": "sequence",
        "segments": [
            {"move": "1.5 m", "velocity": "2 m/s", "acceleration": "1 g", "jerk": "100 m/s^3"},
            {"dwell": "0.2 s"},
            {"move": "-1.5 m", "velocity": "2 m/s", "acceleration": "1 g"},
        ],
    },
    "x": {
        "type": "scurve",
        "travel": "0.3 m",
        "velocity": "1 m/s",
        "acceleration": "1 g",
        "jerk": "50 m/s^3",
    },
}


# ------------------------------------------------------------------------------------------- schema
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
def _schema_text(root: type[BaseModel]) -> str:
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
    schema = _draft7(json.loads(_schema_text(root)))
    return {"$schema": SCHEMA_DIALECT, "$id": schema_id, **schema, "title": title}


def study_json_schema(base_url: str = DEFAULT_BASE_URL) -> dict[str, Any]:
    """The JSON Schema of a study file (YAML or JSON), ``$id`` ``<base_url>/schemas/study.json``."""
    return _published(Study, "isolab study file", base_url.rstrip("/") + STUDY_SCHEMA_PATH)


def scene_json_schema(base_url: str = DEFAULT_BASE_URL) -> dict[str, Any]:
    """The JSON Schema of a scene file (YAML or JSON), ``$id`` ``<base_url>/schemas/scene.json``."""
    return _published(Scene, "isolab scene file", base_url.rstrip("/") + SCENE_SCHEMA_PATH)


# -------------------------------------------------------------------------------- rendering helpers
def _anchor(name: str) -> str:
    return name.lower()


def _prose(text: str | None) -> str:
    """Docstring or description text as one markdown table cell."""
    if not text:
        return ""
    text = re.sub(r":(?:mod|func|class|data|meth|attr):`~?([^`]+)`", r"`\1`", text)
    text = text.replace("``", "`")
    text = " ".join(text.split())
    return text.replace("|", "\\|")


def _first_sentence(text: str | None) -> str:
    """The first sentence (or the part before a colon) of ``text``, outside quotes and brackets; a period
    after a single letter (``c.g.``) does not end it."""
    text = _prose(text)
    depth, quoted = 0, False
    for i, ch in enumerate(text):
        if ch == "`":
            quoted = not quoted
        elif ch in "([{":
            depth += 1
        elif ch in ")]}":
            depth -= 1
        elif ch in ".:" and not quoted and depth == 0 and (i + 1 == len(text) or text[i + 1] == " "):
            if ch == "." and i >= 2 and text[i - 1].isalpha() and not text[i - 2].isalnum():
                continue  # an abbreviation: c.g.
            return text[:i] + ("." if ch == "." else "")
    return text


def _is_null(node: Any) -> bool:
    return isinstance(node, dict) and node.get("type") == "null"


def _branches(node: dict[str, Any]) -> list[dict[str, Any]]:
    for key in ("anyOf", "oneOf"):
        if key in node and "x-dimension" not in node:
            return [b for b in node[key] if not _is_null(b)]
    return [node]


def _type(node: dict[str, Any]) -> str:
    """What a value of ``node`` is, in words with links to the models."""
    if "$ref" in node:
        name = node["$ref"].removeprefix("#/$defs/")
        return f"[{name}](#{_anchor(name)})"
    if "x-dimension" in node:
        return str(node["x-dimension"]).replace("_", " ")
    if "const" in node:
        return f"`{node['const']}`"
    if "enum" in node:
        return "one of " + ", ".join(f"`{v}`" for v in node["enum"])
    branches = _branches(node)
    if branches != [node]:
        parts: list[str] = []
        for b in branches:
            t = _type(b)
            if t not in parts:
                parts.append(t)
        if "number" in parts and "integer" in parts:
            parts.remove("integer")
        return " or ".join(parts)
    kind = node.get("type")
    if kind == "array":
        if "prefixItems" in node:
            items = [_type(i) for i in node["prefixItems"]]
            return f"[{', '.join(items)}]" if len(set(items)) > 1 else f"{len(items)} × {items[0]}"
        return f"list of {_type(node.get('items', {}))}"
    if kind == "object":
        value = node.get("additionalProperties")
        if isinstance(value, dict):
            key = _type(node["propertyNames"]) if "propertyNames" in node else "key"
            return f"map of {key} → {_type(value)}"
        patterns = node.get("patternProperties")
        if isinstance(patterns, dict) and len(patterns) == 1:
            return f"map of name → {_type(next(iter(patterns.values())))}"
        return "mapping"
    if kind == "string":
        return "name" if "pattern" in node else "string"
    if kind in ("integer", "number", "boolean"):
        return str(kind)
    return "any"


def _quantities(node: Any) -> list[dict[str, Any]]:
    """The quantity and number schemas inside ``node`` (through anyOf, items, maps; not other models)."""
    out: list[dict[str, Any]] = []
    stack = [node]
    while stack:
        n = stack.pop()
        if not isinstance(n, dict) or "$ref" in n:
            continue
        if "x-dimension" in n or n.get("type") in ("number", "integer"):
            out.append(n)
            continue
        for key in ("anyOf", "oneOf", "prefixItems"):
            stack.extend(reversed(n.get(key, [])))
        for key in ("items", "additionalProperties", "propertyNames"):
            if isinstance(n.get(key), dict):
                stack.append(n[key])
        stack.extend(v for v in n.get("patternProperties", {}).values() if isinstance(v, dict))
    return out


def _unit(node: dict[str, Any]) -> str:
    units: list[str] = []
    for q in _quantities(node):
        if "x-unit" in q:
            u = q["x-unit"] or "1"
            if u not in units:
                units.append(u)
    return ", ".join(f"{u}" for u in units)


def _number(x: float) -> str:
    return f"{x:,}" if isinstance(x, int) else f"{x:g}"


def _bounds(q: dict[str, Any]) -> str:
    low, low_open = None, False
    if "exclusiveMinimum" in q:
        low, low_open = q["exclusiveMinimum"], True
    if "minimum" in q and (low is None or q["minimum"] > low):
        low, low_open = q["minimum"], False
    high, high_open = None, False
    if "exclusiveMaximum" in q:
        high, high_open = q["exclusiveMaximum"], True
    if "maximum" in q and (high is None or q["maximum"] < high):
        high, high_open = q["maximum"], False
    if low is not None and high is not None and not low_open and not high_open:
        text = f"{_number(low)} to {_number(high)}"
    else:
        parts = []
        if low is not None:
            parts.append(f"{'>' if low_open else '≥'} {_number(low)}")
        if high is not None:
            parts.append(f"{'<' if high_open else '≤'} {_number(high)}")
        text = ", ".join(parts)
    if text and "x-range-reason" in q:
        text += f" ({q['x-range-reason']})"
    return text


def _range(node: dict[str, Any]) -> str:
    """The accepted range of ``node``'s numbers (SI), list lengths and text patterns."""
    parts: list[str] = []
    for q in _quantities(node):
        b = _bounds(q)
        if b and b not in parts:
            parts.append(b)
    stack: list[Any] = [node]
    while stack:
        n = stack.pop()
        if not isinstance(n, dict) or "$ref" in n or "x-dimension" in n:
            continue
        stack.extend(n.get("anyOf", []))
        if n.get("type") == "array" and "prefixItems" not in n:
            lo, hi = n.get("minItems"), n.get("maxItems")
            if lo is not None and hi is not None:
                parts.append(f"{lo:,} to {hi:,} entries")
            elif hi is not None:
                parts.append(f"at most {hi:,} entries")
            elif lo is not None:
                parts.append(f"at least {lo:,} {'entry' if lo == 1 else 'entries'}")
        if n.get("type") == "object" and "minProperties" in n:
            parts.append(f"at least {n['minProperties']} {'key' if n['minProperties'] == 1 else 'keys'}")
        if n.get("type") == "string":
            if "pattern" in n:
                parts.append(f"`{n['pattern']}`")
            lo, hi = n.get("minLength"), n.get("maxLength")
            if hi is not None:
                parts.append(f"{lo} to {hi} characters" if lo else f"at most {hi} characters")
        for key in ("items", "propertyNames"):
            if isinstance(n.get(key), dict):
                stack.append(n[key])
    return "; ".join(p.replace("|", "\\|") for p in parts)


def _default(node: dict[str, Any], required: bool) -> str:
    if required:
        return "required"
    if "default" not in node:
        return ""
    value = node["default"]
    if value is None:
        return "unset"
    if isinstance(value, dict) and value:
        return "its keys' defaults"
    text = json.dumps(value, ensure_ascii=False) if not isinstance(value, str) or not value else value
    return f"`{text}`"


def _description(node: dict[str, Any], defs: dict[str, Any]) -> str:
    text = node.get("description")
    if text and "x-dimension" in node and text.startswith(f"{node['x-dimension']}: a number in SI"):
        text = None  # the quantity's own generic text: type and unit say it
    branches = _branches(node)
    if not text and len(branches) == 1 and "$ref" in branches[0]:
        text = _first_sentence(defs.get(branches[0]["$ref"].removeprefix("#/$defs/"), {}).get("description"))
    return _prose(text)


def _table(model: dict[str, Any], defs: dict[str, Any]) -> list[str]:
    rows = ["| key | type | unit | default | accepted | description |", "|---|---|---|---|---|---|"]
    required = set(model.get("required", []))
    for key, node in model.get("properties", {}).items():
        cells = [
            f"`{key}`",
            _type(node),
            _unit(node),
            _default(node, key in required),
            _range(node),
            _description(node, defs),
        ]
        rows.append("| " + " | ".join(cells) + " |")
    extra = model.get("additionalProperties")
    if isinstance(extra, dict):
        key = model.get("x-extra-key", "<key>")
        cells = [f"`{key}`", _type(extra), _unit(extra), "", _range(extra), _prose(extra.get("description"))]
        rows.append("| " + " | ".join(cells) + " |")
    return rows


def _model_section(name: str, model: dict[str, Any], defs: dict[str, Any]) -> list[str]:
    lines = [f"### {name}", ""]
    if model.get("description"):
        lines += [_prose(model["description"]), ""]
    if model.get("properties") or isinstance(model.get("additionalProperties"), dict):
        lines += [*_table(model, defs), ""]
    return lines


# ---------------------------------------------------------------------------------- parameter paths
def _fold(path: str) -> str:
    return path[:-2] + ".{0,1,2}" if path.endswith(".0") else path


def _components(names: list[str]) -> str:
    """``["machine_ixx", "machine_iyy", "machine_izz"]`` -> ``machine_i{xx,yy,zz}``."""
    head = 0
    while all(len(n) > head and n[head] == names[0][head] for n in names):
        head += 1
    tail = 0
    while all(len(n) - tail > head and n[-1 - tail] == names[0][-1 - tail] for n in names):
        tail += 1
    middle = [n[head : len(n) - tail] for n in names]
    return names[0][:head] + "{" + ",".join(middle) + "}" + (names[0][len(names[0]) - tail :] if tail else "")


def _path_rows(scene: Scene, skip: set[str]) -> list[str]:
    """One row per parameter path of ``scene`` not in ``skip``: vector components folded into
    ``.{0,1,2}``, the entries of a list whose names carry their index into ``<j>``."""
    rows, shown = [], set()
    paths = [p for p in available_paths(scene) if p not in skip]
    for path in paths:
        head, _, last = path.rpartition(".")
        if last in ("1", "2") and f"{head}.0" in paths:
            continue
        t = resolve(path, scene)
        name, where = t.name, _fold(path)
        if path.endswith(".0"):
            name = _components([resolve(f"{head}.{i}", scene).name for i in range(3)])
        index = re.search(r"\.(\d+)\.", path)
        if index is not None and f"_{index.group(1)}_" in name:
            j = index.group(1)
            where = where[: index.start()] + ".<j>." + where[index.end() :]
            name = name.replace(f"_{j}_", "_<j>_", 1)
        if where in shown:
            continue
        shown.add(where)
        if t.dimension == CATEGORICAL:
            kind, values = "categorical", ", ".join(f"`{v}`" for v in t.levels or ())
        else:
            kind = t.dimension.replace("_", " ")
            values = {"gt0": "> 0", "ge0": "≥ 0"}.get(t.bound or "", "any")
        unit = t.unit or ("" if t.levels else "1")
        rows.append(f"| `{where}` | `{name}` | {kind} | {unit} | {values} |")
    return rows


def _variant_scene(base: dict[str, Any]) -> Scene:
    data = copy.deepcopy(base)
    data.update(yaml.safe_load(VARIANT_SCENE_CHANGES))
    for stage in data["stages"]:
        stage["profile"] = copy.deepcopy(VARIANT_STAGE_PROFILES[stage["name"]])
    return load_scene(data)


def example_scene_data() -> dict[str, Any]:
    """The example scene (:data:`EXAMPLE_SCENE`) as written, a fresh dict."""
    return yaml.safe_load(EXAMPLE_SCENE.read_text(encoding="utf-8"))


def _paths_section() -> list[str]:
    base = example_scene_data()
    scene = load_scene(base)
    variant = _variant_scene(base)
    header = ["| path | default name | quantity | unit | values |", "|---|---|---|---|---|"]
    first = available_paths(scene)
    lines = [
        "## Parameter paths",
        "",
        "A parameter's `path` names one input of the scene, dotted, following the scene's own keys, with "
        "stage and point names and list indices as segments. Vector components may be written `0/1/2` or "
        "`x/y/z` (`stages.y.home.z`). A path exists only where the scene has that input: `machine.mass` "
        "for a machine given by mass, `isolators.layout.*` for a layout, a profile's `jerk` for an S-curve "
        "or a scan. `isolators.k.horizontal` sets `k.x` and `k.y` of every mount, `isolators.k.vertical` "
        "sets `k.z` (the same for `c`). Of the `simulation` block only `duration` and `settle_tolerance` "
        "may vary; the rest is shared by every case. A parameter's `name` defaults to the name below; "
        "its values take units like any quantity, and every case must still be a valid scene (the "
        "accepted ranges above apply).",
        "",
        f"The paths of the example scene `studies/examples/{EXAMPLE_SCENE.name}` (a block base on a "
        "layout of four air mounts, a Y stage scanning and an X stage riding on it, two points):",
        "",
        *header,
        *_path_rows(scene, set()),
        "",
        "With the base given by mass, c.g. and principal moments, an explicit list of mounts, a sine floor, "
        "a Y stage moving through a sequence of segments and an X stage on an S-curve, these paths exist "
        "as well:",
        "",
        *header,
        *_path_rows(variant, set(first)),
        "",
    ]
    return lines


# -------------------------------------------------------------------------------------- design types
def design_types() -> list[str]:
    """The design types :class:`~studies.schema.DesignSpec` accepts, in the order it lists them."""
    node = DesignSpec.model_json_schema()["properties"]["type"]
    return list(node["enum"]) if "enum" in node else [node["const"]]


def design_example(kind: str) -> dict[str, Any]:
    """The example study of design type ``kind`` on the example scene (a dict ready to validate)."""
    _, text = DESIGN_EXAMPLES[kind]
    return {"name": f"{kind}-example", "scene": example_scene_data(), **yaml.safe_load(text)}


def _designs_section() -> list[str]:
    lines = [
        "## Design types",
        "",
        "`design.type` picks how the cases are drawn from the parameters. Each example below is the "
        "`parameters:` and `design:` part of a study on the example scene (`scene_file: "
        f"{EXAMPLE_SCENE.name}`). Keys of `design:` that only one type takes (`samples`, `cases`, the "
        "optimize keys) are refused with the others; see [DesignSpec](#designspec) for all keys.",
        "",
    ]
    for kind in design_types():
        lines += [f"### `{kind}`", ""]
        if kind not in DESIGN_EXAMPLES:
            lines += ["(No example yet: see [DesignSpec](#designspec).)", ""]
            continue
        what, text = DESIGN_EXAMPLES[kind]
        lines += [what, "", "```yaml", text.rstrip("\n"), "```", ""]
    return lines


# ------------------------------------------------------------------------------------------ document
def render() -> str:
    """``docs/study-files.md``: the reference of study and scene files, made from the models."""
    study = json.loads(_schema_text(Study))  # pydantic's own form (draft 2020-12), walked below
    defs = study["$defs"]
    lines = [
        "# Study and scene files",
        "",
        "<!-- Generated from the pydantic models by `make docs` "
        "(python -m isolab.studies.authoring.file_reference > "
        "docs/study-files.md); do not edit by hand: tests/studies/test_file_reference.py fails while this "
        "file differs from what the models give. -->",
        "",
        "A **study file** (YAML or JSON) names a base scene (inline under `scene:`, or a scene file by "
        "`scene_file:`, relative to the study file), the parameters it varies and the design that picks "
        "their values. A **scene file** describes one machine: its base, isolators, stages, points of "
        "interest, floor motion, simulation settings and design criteria; `isolab simulate` runs one, and "
        "every case of a study is one. The examples are in `studies/examples/`.",
        "",
        "- Every key not listed here is refused (a typo is an error, not an ignored input).",
        "- A quantity is a number in SI units (m, kg, s, N, rad, Hz) or a string with units: `800 mm`, "
        "`2 g` (standard gravity), `3.5 Hz`, `1.2e6 N/m`, `5 %`. The **unit** column is the SI unit a "
        "plain number is read in.",
        "- **accepted** is the range a value must lie in, in that SI unit (strings are converted first). "
        "Ranges marked *the range the engine is tested over* are the ranges the engine's extreme-scene "
        "tests cover.",
        "- Positions are in the floor frame (Z up, Y the machine's long axis), m.",
        "",
        "## Editor support",
        "",
        "A running service publishes the JSON Schema of both files: "
        f"`GET {STUDY_SCHEMA_PATH}` and `GET {SCENE_SCHEMA_PATH}` (no token needed: they hold no data). "
        "Editors with the YAML language server (VS Code's YAML extension, Neovim, Helix...) complete keys, "
        "show these descriptions and flag unknown keys and out-of-range numbers when the file starts with "
        "a modeline:",
        "",
        "```yaml",
        f"# yaml-language-server: $schema={DEFAULT_BASE_URL}{STUDY_SCHEMA_PATH}",
        "name: my-study",
        "scene_file: article-scriber.yaml",
        "```",
        "",
        f"and `# yaml-language-server: $schema={DEFAULT_BASE_URL}{SCENE_SCHEMA_PATH}` for a scene file "
        "(the address of your `isolab serve`, `ISOLAB_URL`). Without a service: "
        '`python -c "import json; from isolab.studies.authoring.file_reference import study_json_schema; '
        'print(json.dumps(study_json_schema()))" > study.schema.json`. The schema accepts what the '
        "service checks key by key; checks that involve several keys (a stage's parent listed first, "
        "mounts that carry the machine) are the service's (`isolab run`, `isolab submit`, the web page).",
        "",
        "## Study file",
        "",
        _prose(study.get("description")),
        "",
        *_table(study, defs),
        "",
        "## Scene file",
        "",
        "The scene: inline under a study's `scene:`, or a file of its own (`scene_file:`, `isolab simulate "
        "FILE`).",
        "",
        *_model_section("Scene", defs["Scene"], defs),
        "## Models",
        "",
        "Every block of the files above, in the order the study file reaches them.",
        "",
    ]
    for name, model in defs.items():
        if name == "Scene":
            continue
        lines += _model_section(name, model, defs)
    lines += _paths_section()
    lines += _designs_section()
    return "\n".join(lines).rstrip("\n") + "\n"


def main() -> None:
    """Print :func:`render` (``python -m isolab.studies.authoring.file_reference > docs/study-files.md``)."""
    sys.stdout.write(render())


if __name__ == "__main__":
    main()
