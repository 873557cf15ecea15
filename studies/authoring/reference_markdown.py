"""The Markdown reference of study and scene files, ``docs/study-files.md``: one table per model walked
from the models' JSON schema (key, type, unit, default, accepted range, description), the parameter paths
a study may vary (read from the example scenes by :func:`studies.inputs.parameters.available_paths`) and
every design type with an example (:mod:`studies.authoring.reference_examples`).
"""

from __future__ import annotations

import json
import re
from typing import Any

from isolab.studies.authoring.json_schemas import (
    DEFAULT_BASE_URL,
    SCENE_SCHEMA_PATH,
    STUDY_SCHEMA_PATH,
    model_schema_text,
)
from isolab.studies.authoring.reference_examples import (
    DESIGN_EXAMPLES,
    EXAMPLE_SCENE,
    design_types,
    example_scene_data,
    variant_scene,
)
from isolab.studies.inputs.parameters import CATEGORICAL, available_paths, resolve
from isolab.studies.inputs.schema import Scene
from isolab.studies.inputs.study import Study, load_scene


# -------------------------------------------------------------------------------- tables of the models
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


def _paths_section() -> list[str]:
    base = example_scene_data()
    scene = load_scene(base)
    variant = variant_scene(base)
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
    study = json.loads(model_schema_text(Study))  # pydantic's own form (draft 2020-12), walked below
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
