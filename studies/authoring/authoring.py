"""Writing a study as text, and reading a stored one back as its author wrote it (what the web page needs).

- :func:`example_names` and :func:`example_text`: the example studies shipped with isolab
  (``studies/examples/*.yaml``), each as YAML text with its ``scene_file`` inlined (comments kept), ready
  to be edited and submitted over the API, which never reads files;
- :func:`check_text`: parse YAML (or JSON) text and check it as a submission would be checked
  (:func:`isolab.studies.inputs.definitions.check_definition`), without storing anything: the definition as
  data, its case count and an estimate of its run time; every problem is a detail whose ``line`` is the
  line of the text it points at;
- :func:`definition_yaml`: a stored definition as YAML text;
- :func:`design_summary`: a stored study's parameters in the units their author wrote;
- :func:`stored_error_estimate`: the measured error and the model a done study ran with.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from isolab.studies.inputs.definitions import DefinitionError, Loc, check_definition, detail, study_of
from isolab.studies.results.dataset import ERROR_ESTIMATE_PREFIX
from isolab.studies.results.netcdf_locks import NETCDF_LOCK
from isolab.studies.run.costs import estimate_seconds_per_case
from isolab.studies.units import to_si

EXAMPLES_DIR = Path(__file__).resolve().parent.parent / "examples"
"""The example studies shipped with the package."""
MAX_TEXT_CHARS = 1_000_000
"""Longest study text :func:`check_text` reads."""
MAX_DEPTH = 64
"""Deepest nesting of a study text (a study and its scene are about 6 levels deep)."""
MAX_NODES = 500_000
"""Most values and keys a study text may hold with its YAML aliases expanded (about as many as a text of
:data:`MAX_TEXT_CHARS` holds without aliases): aliases are accepted, as the command line accepts them, but
a few lines of aliases of aliases cannot expand to more."""

_EXAMPLE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,99}$")
_SCENE_FILE_LINE = re.compile(r"^scene_file:\s*(?P<file>[^#\s]+)\s*(#.*)?$", re.MULTILINE)
#: The block-structure prefix of a line: its indentation and the ``- `` / ``? `` indicators that open a
#: sequence item or a complex key on the same line (``- - - x`` is three levels deep).
_BLOCK_PREFIX = re.compile(r"^([ ]*)((?:[-?](?:[ \t]+|$))*)(?=[^ \n])", re.MULTILINE)
_NUMBER_THEN_UNIT = re.compile(r"^\s*[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?\s*(?P<unit>.*?)\s*$")


class ExampleNotFound(LookupError):
    """No example study of that name."""


# ---------------------------------------------------------------------------------------------- examples
def _is_study(path: Path) -> bool:
    """A study file names parameters or a scene; a scene file (article-scriber.yaml) names a machine."""
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError):
        return False
    return isinstance(data, dict) and "name" in data and ("scene" in data or "scene_file" in data)


def example_names() -> list[str]:
    """Names (file stems) of the shipped example studies, sorted."""
    return sorted(p.stem for p in EXAMPLES_DIR.glob("*.yaml") if _is_study(p))


def _example_path(name: str) -> Path:
    if not _EXAMPLE_NAME.match(name) or name not in example_names():
        raise ExampleNotFound(f"no example study {name!r}; examples: {', '.join(example_names())}")
    return EXAMPLES_DIR / f"{name}.yaml"


def example_text(name: str) -> str:
    """The example study ``name`` as YAML text with its ``scene_file`` line replaced by the scene file's
    text, indented under ``scene:`` (both files' comments kept).

    Raises:
        ExampleNotFound: there is no such example.
    """
    path = _example_path(name)
    text = path.read_text(encoding="utf-8")

    def inline(m: re.Match[str]) -> str:
        scene_path = (path.parent / m.group("file")).resolve()
        if scene_path.parent != EXAMPLES_DIR or not scene_path.is_file():
            return m.group(0)
        scene = scene_path.read_text(encoding="utf-8").rstrip("\n")
        body = "\n".join(("  " + line) if line.strip() else "" for line in scene.splitlines())
        return f"scene:                                   # from {m.group('file')}\n{body}"

    return _SCENE_FILE_LINE.sub(inline, text, count=1)


# ---------------------------------------------------------------------------------------------- checking
def _line_of(root: yaml.Node | None, loc: Loc) -> int | None:
    """1-based line of the node of the text that ``loc`` (relative to the document) points at: the
    deepest node the path reaches (a mapping entry's key line), None without a document."""
    if root is None:
        return None
    node: yaml.Node = root
    line = node.start_mark.line + 1
    for part in loc:
        if isinstance(node, yaml.MappingNode):
            entry = next((kv for kv in node.value if str(kv[0].value) == str(part)), None)
            if entry is None:
                break
            line, node = entry[0].start_mark.line + 1, entry[1]
        elif isinstance(node, yaml.SequenceNode) and isinstance(part, int) and 0 <= part < len(node.value):
            node = node.value[part]
            line = node.start_mark.line + 1
        else:
            break
    return line


def expanded_size(root: yaml.Node) -> tuple[int, int] | None:
    """(nodes, depth) of a composed document once its aliases are expanded (``*name`` repeats the node of
    ``&name`` in full, as the loaded data does), counted without expanding anything: each node once, its
    size and depth remembered. None when an alias sits inside the node it names (the data would be
    infinite)."""
    nodes: dict[int, int] = {}
    depth: dict[int, int] = {}
    open_: set[int] = set()
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    while stack:
        node, children_done = stack.pop()
        key = id(node)
        if children_done:
            kids = _children(node)
            nodes[key] = 1 + sum(nodes[id(k)] for k in kids)
            depth[key] = 1 + max((depth[id(k)] for k in kids), default=0)
            open_.discard(key)
            continue
        if key in nodes:
            continue
        if key in open_:
            return None
        open_.add(key)
        stack.append((node, True))
        for kid in _children(node):
            if id(kid) in open_:
                return None
            if id(kid) not in nodes:
                stack.append((kid, False))
    return nodes[id(root)], depth[id(root)]


def _children(node: yaml.Node) -> list[yaml.Node]:
    if isinstance(node, yaml.MappingNode):
        return [n for kv in node.value for n in kv]
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    return []


def flow_depth(text: str) -> int:
    """Deepest nesting of ``[``/``{`` in a text, a running count that never goes below zero (a bracket in
    a string or comment counts too: an upper bound on the flow nesting, read in milliseconds)."""
    codes = np.frombuffer(text.encode("utf-8", "replace"), dtype=np.uint8)
    steps = np.zeros(codes.size, dtype=np.int64)
    steps[(codes == ord("[")) | (codes == ord("{"))] = 1
    steps[(codes == ord("]")) | (codes == ord("}"))] = -1
    if steps.size == 0:
        return 0
    walk = np.cumsum(steps)
    return int((walk - np.minimum(np.minimum.accumulate(walk), 0)).max())


def block_depth(text: str, limit: int) -> tuple[int, int | None]:
    """(deepest block nesting, 1-based line where it first passes ``limit``) of a YAML text, read from
    indentation and ``- `` indicators alone (no parsing): each line closes the levels opened at its
    column or to the right of it and opens one at its column, and one more at each indicator."""
    if not re.search(f"^[-? \t]{{{max(limit, 1)},}}", text, re.MULTILINE):
        return 0, None  # no prefix as long as the limit: fewer columns than levels, it cannot be passed
    columns: list[int] = []
    deepest = 0
    for m in _BLOCK_PREFIX.finditer(text):
        indent = len(m.group(1))
        if text.startswith("#", m.end()):
            continue  # a comment opens no level
        while columns and columns[-1] >= indent:
            columns.pop()
        column = indent
        for indicator in re.finditer(r"[-?][ \t]*", m.group(2)):
            columns.append(column)
            column += len(indicator.group(0))
        columns.append(column)
        if len(columns) > deepest:
            deepest = len(columns)
            if deepest > limit:
                return deepest, text.count("\n", 0, m.start()) + 1
    return deepest, None


def nesting_problem(text: str, prefix: Loc, limit: int = MAX_DEPTH) -> dict[str, Any] | None:
    """The problem of a YAML or JSON text nested deeper than ``limit`` levels, found on a pre-scan of its
    characters before any parsing (milliseconds for a megabyte; a parser would take minutes on 8,000
    levels), else None. The bound it reads may exceed the true depth, never falls short of it."""
    flow = flow_depth(text)
    block, line = block_depth(text, max(0, limit - flow))
    if flow + block <= limit:
        return None
    found = detail(
        prefix,
        f"the text nests deeper than {limit} levels of mappings and lists (a study needs about 8)",
        "too_deep",
    )
    if line is not None:
        found["line"] = line
    return found


def duplicate_key(root: yaml.Node | None) -> tuple[str, int, int] | None:
    """(key, line, first line) of the first key written twice in one mapping of a composed document,
    else None (YAML would keep the last silently)."""
    stack = [root] if root is not None else []
    seen_nodes: set[int] = set()
    while stack:
        node = stack.pop()
        if id(node) in seen_nodes:
            continue  # an aliased node, already read
        seen_nodes.add(id(node))
        if isinstance(node, yaml.MappingNode):
            seen: dict[str, int] = {}
            for key, value in node.value:
                name = str(key.value) if isinstance(key, yaml.ScalarNode) else repr(key.value)
                line = key.start_mark.line + 1
                if name in seen:
                    return name, line, seen[name]
                seen[name] = line
                stack.append(value)
        elif isinstance(node, yaml.SequenceNode):
            stack.extend(node.value)
    return None


def parse_text(text: str, prefix: Loc) -> tuple[dict[str, Any], yaml.Node | None]:
    """The mapping a YAML (or JSON) study text holds, as JSON data, and its composed document (for line
    numbers).

    Raises:
        DefinitionError: the text is not YAML, not a mapping, nests too deep, expands past
            :data:`MAX_NODES` by its aliases or holds values JSON has no form for (dates, binary); each
            detail has the ``line`` it points at.
    """
    if len(text) > MAX_TEXT_CHARS:
        raise DefinitionError([detail(prefix, f"the text is longer than {MAX_TEXT_CHARS} characters")])
    too_deep = nesting_problem(text, prefix)
    if too_deep is not None:
        raise DefinitionError([too_deep])
    try:
        root = yaml.compose(text, Loader=yaml.SafeLoader)
        size = expanded_size(root) if root is not None else (0, 0)
        if size is None:
            raise DefinitionError([detail(prefix, "a YAML alias (*name) sits inside the node it names")])
        if size[1] > MAX_DEPTH:
            raise DefinitionError([detail(prefix, f"the text nests deeper than {MAX_DEPTH} levels")])
        if size[0] > MAX_NODES:
            raise DefinitionError(
                [
                    detail(
                        prefix,
                        f"the text holds {size[0]:,} values and keys once its YAML aliases (*name) are "
                        f"expanded, more than {MAX_NODES:,}",
                        "too_large",
                    )
                ]
            )
        twice = duplicate_key(root)
        if twice is not None:
            key, line, first = twice
            raise DefinitionError(
                [
                    {
                        **detail(
                            prefix, f"the key {key!r} is written twice in one mapping (lines {first}, {line})"
                        ),
                        "line": line,
                    }
                ]
            )
        data = yaml.safe_load(text)
    except DefinitionError:
        raise
    except yaml.MarkedYAMLError as err:
        mark = err.problem_mark or err.context_mark
        msg = f"not valid YAML: {err.problem or err}" + (f" ({err.context})" if err.context else "")
        found = detail(prefix, msg, "yaml_error")
        if mark is not None:
            found["line"] = mark.line + 1
        raise DefinitionError([found]) from None
    except (yaml.YAMLError, RecursionError, ValueError, TypeError) as err:
        raise DefinitionError([detail(prefix, f"not valid YAML: {err}", "yaml_error")]) from None
    if not isinstance(data, dict):
        raise DefinitionError(
            [
                detail(
                    prefix, f"expected a mapping (name:, scene:, parameters: ...), got {type(data).__name__}"
                )
            ]
        )
    try:
        as_json = json.loads(json.dumps(data, allow_nan=False))
    except (TypeError, ValueError) as err:
        raise DefinitionError(
            [detail(prefix, f"holds a value a study cannot have (dates, binary, .nan, .inf): {err}")]
        ) from None
    return as_json, root


def check_text(text: str, max_cases: int | None, workers: int, prefix: Loc | None = None) -> dict[str, Any]:
    """Check a study given as YAML or JSON text as a submission is checked, storing nothing.

    Returns ``{"definition", "name", "n_cases", "parameters", "estimated_seconds"}``: the definition as
    data (to submit as it is), the number of cases, the varied parameters' names and a rough run time on
    ``workers`` single-threaded workers (s).

    Raises:
        DefinitionError: each detail (``loc`` under ``prefix``, default ``["body", "text"]``) carries the
            1-based ``line`` of the text it points at, when the text has one.
    """
    pre: Loc = ["body", "text"] if prefix is None else list(prefix)
    data, root = parse_text(text, pre)
    try:
        study = check_definition(data, max_cases, pre)
    except DefinitionError as err:
        for d in err.details:
            line = _line_of(root, list(d["loc"])[len(pre) :])
            if line is not None:
                d["line"] = line
        raise
    n = int(study.planned_cases)  # an optimize design: its budget
    seconds = n * estimate_seconds_per_case(study) / max(1, workers)
    return {
        "definition": data,
        "name": study.name,
        "n_cases": n,
        "parameters": list(study.design().names),
        "estimated_seconds": float(seconds),
    }


def definition_yaml(definition: dict[str, Any]) -> str:
    """A stored definition as YAML text (keys in the stored order)."""
    return yaml.safe_dump(definition, sort_keys=False, allow_unicode=True, width=110)


# --------------------------------------------------------------------------------------- stored studies
def _written_unit(values: list[Any], dimension: str, field: str) -> tuple[str, float]:
    """(unit, SI value of one unit) of the first value written with a unit; ("", 1) when none is."""
    for v in values:
        if isinstance(v, str):
            m = _NUMBER_THEN_UNIT.match(v)
            unit = m.group("unit") if m else ""
            if unit:
                try:
                    scale = to_si(f"1 {unit}", dimension, field)
                except ValueError:
                    continue
                if math.isfinite(scale) and scale > 0:
                    return unit, scale
    return "", 1.0


def design_summary(row: Mapping[str, Any]) -> dict[str, Any]:
    """A stored study's design as its author wrote it: per parameter its column ``name``, ``path``,
    ``unit`` (SI), ``values`` or ``range`` as written, ``scale`` (linear or log), ``categorical`` and the
    ``display_unit`` its author wrote with ``display_scale`` (SI per display unit); the design type,
    samples and seed."""
    study = study_of(row)
    d = study.design()
    params = []
    for i, (spec, target, name) in enumerate(zip(study.parameters, study.targets, d.names, strict=True)):
        written: list[Any] = list(spec.values or [])
        if spec.range is not None:
            written = [spec.range.start, spec.range.stop]
        unit, scale = ("", 1.0) if target.categorical else _written_unit(written, target.dimension, name)
        params.append(
            {
                "name": name,
                "path": spec.path,
                "unit": d.units.get(name, ""),
                "categorical": target.categorical,
                "values": spec.values,
                "range": spec.range.model_dump(mode="json") if spec.range is not None else None,
                "scale": spec.range.scale if spec.range is not None else "linear",
                "display_unit": unit or d.units.get(name, ""),
                "display_scale": scale,
                "index": i,
            }
        )
    how = study.design_spec
    return {
        "name": study.name,
        "description": study.description,
        "design": {"type": how.type, "samples": how.samples, "seed": how.seed},
        "n_cases": int(study.planned_cases),
        "parameters": params,
    }


def stored_error_estimate(path: Path) -> dict[str, Any]:
    """The measured error a done study's dataset carries: ``{"method", "cases", "excluded", "outputs":
    {output: {"value", "units", "meaning", "worst_case"}}}`` (``value`` None where no case compared).

    Raises:
        FileNotFoundError: there is no dataset file.
    """
    if not Path(path).is_file():
        raise FileNotFoundError(f"no dataset file {path}")
    import xarray as xr  # on first use: the service starts sooner without it

    with NETCDF_LOCK, xr.open_dataset(path) as ds:
        outputs = {}
        for name in ds.data_vars:
            if not str(name).startswith(ERROR_ESTIMATE_PREFIX):
                continue
            var = ds[name]
            value = float(var.values)
            case = int(var.attrs.get("case", -1))
            outputs[str(name)[len(ERROR_ESTIMATE_PREFIX) :]] = {
                "value": value if math.isfinite(value) else None,
                "units": str(var.attrs.get("units", "1")),
                "meaning": str(var.attrs.get("long_name", name)),
                "worst_case": case if case >= 0 else None,
            }
        attrs = dict(ds.attrs)
    return {
        "method": str(attrs.get("error_estimate_method", "")) or None,
        "cases": json.loads(attrs.get("error_estimate_cases", "[]")),
        "excluded": json.loads(attrs.get("error_estimate_excluded", "{}")),
        "outputs": outputs,
    }


__all__ = [
    "ExampleNotFound",
    "check_text",
    "definition_yaml",
    "design_summary",
    "example_names",
    "example_text",
    "parse_text",
    "stored_error_estimate",
]
