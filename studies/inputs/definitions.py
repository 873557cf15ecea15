"""A study definition as a user submits it: screened, counted and validated before anything is built.

The steps every submission goes through, whatever carries it (REST, the CLI, a web page):

1. :func:`case_count_bound` counts the cases from the raw definition (grid: the product of each
   parameter's count; list: its length; lhs/sobol/random: ``samples``; saltelli: ``samples`` times
   D + 2) and :func:`long_lists` measures its lists, so a study above a case limit is refused from
   lengths and integers alone, before anything is read or built (a 600,000-value list in milliseconds);
2. :func:`screen_definition` names every hostile value of the raw definition: quantity text whose
   arithmetic would not end (the units parser computes integer powers exactly, so ``"9**9**9 kg"`` would
   take hours) and numbers no 64-bit float holds (``"10**999 kg"``);
3. :func:`isolab.studies.inputs.study.validate_study` parses and checks it.

:func:`check_definition` runs them in order and raises :class:`DefinitionError` with one detail per
problem, each ``{"loc": [...], "msg": ..., "type": ...}`` with ``loc`` the full path of the field.
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterator, Mapping, Sequence
from typing import Any

from pydantic import ValidationError

from isolab.studies.inputs.schema.errors import join_paths
from isolab.studies.inputs.schema.fields import (
    MAX_CRITERIA,
    MAX_MOUNTS,
    MAX_PARAMETERS,
    MAX_POINTS,
    MAX_SEGMENTS,
    MAX_STAGES,
)
from isolab.studies.inputs.study import SAMPLED_TYPES, Study, study_from_json, validate_study
from isolab.studies.questions.designs import saltelli_cases
from isolab.studies.units import quantity_problem

FREE_TEXT_KEYS = frozenset({"description", "name"})
"""Keys whose string values are prose or names, never read as quantities (no length or power rule; a
name's own pattern and length are the model's)."""

Loc = list[str | int]


class DefinitionError(ValueError):
    """A definition is refused; ``details`` holds one ``{"loc", "msg", "type"}`` per problem."""

    def __init__(self, details: list[dict[str, Any]]):
        super().__init__("; ".join(str(d["msg"]) for d in details))
        self.details = details


def detail(loc: Loc, msg: str, kind: str = "value_error") -> dict[str, Any]:
    """One problem: where (``loc``), why (``msg``) and its type."""
    return {"loc": list(loc), "msg": msg, "type": kind}


# ---------------------------------------------------------------------------------------------- screening
def _leaves(value: Any, loc: Loc) -> Iterator[tuple[Loc, Any]]:
    """(loc, leaf) of every string and integer leaf of a parsed JSON value (the leaves screening reads),
    without recursion. Floats, booleans and None are skipped without building their loc: a list of a
    million numbers is passed over in milliseconds."""
    stack: list[tuple[Loc, Any]] = [(loc, value)]
    while stack:
        where, node = stack.pop()
        if isinstance(node, dict):
            items: Iterator[tuple[Any, Any]] = iter(node.items())
        elif isinstance(node, list | tuple):
            items = enumerate(node)
        else:
            if isinstance(node, str | int) and not isinstance(node, bool):
                yield where, node
            continue
        nested = []
        for key, v in items:
            kind = type(v)
            if kind is float or kind is bool or v is None:
                continue
            key = key if isinstance(key, int) else str(key)
            if kind is str or kind is int:
                yield [*where, key], v
            else:
                nested.append(([*where, key], v))
        stack.extend(reversed(nested))


def dotted(loc: Sequence[str | int]) -> str:
    """``["scene", "stages", 0, "mass"]`` -> ``scene.stages[0].mass``."""
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out or "body"


def screen_definition(body: Any, prefix: Loc) -> list[dict[str, Any]]:
    """Details (``loc`` under ``prefix``, ``msg`` naming the field) for every hostile value in a parsed
    study or scene: quantity text :func:`isolab.studies.units.quantity_problem` refuses, and integers
    beyond a float's range. Empty when nothing is hostile."""
    problems = []
    for loc, leaf in _leaves(body, list(prefix)):
        if isinstance(leaf, int):
            if abs(leaf) <= 1.7e308:
                continue
            field = dotted(loc[len(prefix) :])
            problems.append(detail(loc, f"{field}: the number is too large for a 64-bit float"))
        elif isinstance(leaf, str):
            named = [x for x in loc if isinstance(x, str)]
            if named and named[-1] in FREE_TEXT_KEYS:
                continue
            reason = quantity_problem(leaf)
            if reason is not None:
                field = dotted(loc[len(prefix) :])
                shown = f"{leaf[:40]!r}" + ("..." if len(leaf) > 40 else "")
                problems.append(detail(loc, f"{field}: {shown}: {reason}"))
    return problems


# ---------------------------------------------------------------------------------------------- counting
def _count(value: Any) -> int | None:
    if isinstance(value, bool) or not isinstance(value, int):
        return None
    return value


def case_count_bound(body: Any, prefix: Loc | None = None) -> tuple[int, Loc] | None:
    """(number of cases, loc that sets it, under ``prefix``, default ``["body"]``) of a raw study
    definition, read without building its design; None when the definition does not say (validation will
    tell what is missing).

    Sampled designs have ``design.samples`` cases (saltelli: ``samples`` times D + 2, or 2D + 2 with
    ``second_order``, D the number of parameters, times ``replicates``), a list design
    ``len(design.cases)``, a grid the product of each parameter's ``values`` count or ``range.num``."""
    pre: Loc = ["body"] if prefix is None else list(prefix)
    if not isinstance(body, dict):
        return None
    design = body.get("design")
    design = design if isinstance(design, dict) else {}
    kind = design.get("type", "grid")
    if kind in SAMPLED_TYPES:
        n = _count(design.get("samples"))
        if n is not None and kind == "saltelli":  # N base samples run N (D + 2) or N (2D + 2) cases
            parameters = body.get("parameters")
            d = len(parameters) if isinstance(parameters, list) else 0
            replicates = _count(design.get("replicates"))
            n = saltelli_cases(n, max(d, 1), design.get("second_order") is True, max(replicates or 1, 1))
        return None if n is None else (n, [*pre, "design", "samples"])
    if kind == "list":
        cases = design.get("cases")
        return (len(cases), [*pre, "design", "cases"]) if isinstance(cases, list) else None
    if kind == "optimize":  # an optimiser runs at most its budget (a robust one: each candidate's draws too)
        n = _count(design.get("budget"))
        robust = design.get("robust")
        draws = _count(robust.get("samples")) if isinstance(robust, dict) else None
        if n is not None and draws is not None and draws >= 0:
            n *= draws + 1
        return None if n is None else (n, [*pre, "design", "budget"])
    parameters = body.get("parameters")
    if parameters is None:
        return 1, [*pre, "parameters"]
    if not isinstance(parameters, list):
        return None
    total = 1
    for p in parameters:
        if not isinstance(p, dict):
            return None
        values, span = p.get("values"), p.get("range")
        if isinstance(values, list):
            total *= len(values)
        elif isinstance(span, dict) and _count(span.get("num")) is not None and span["num"] >= 1:
            total *= span["num"]
        else:
            return None
        if total > 2**62:
            break
    return total, [*pre, "parameters"]


def too_many_cases(n_cases: int, loc: Loc, max_cases: int) -> dict[str, Any]:
    """The detail of a study above the case limit."""
    shown = f"{n_cases}" if n_cases <= 2**62 else f"more than {2**62}"
    return detail(
        loc,
        f"the study has {shown} cases, more than this service's limit of {max_cases} (ISOLAB_MAX_CASES)",
    )


def long_lists(body: Any, max_cases: int, prefix: Loc | None = None) -> list[dict[str, Any]]:
    """Details for every list of a raw study definition longer than the case limit: a parameter's
    ``values`` (a grid of them has at least that many cases; a sampled design draws at most
    ``max_cases`` of them) and ``design.cases``. Read before anything is parsed."""
    pre: Loc = ["body"] if prefix is None else list(prefix)
    if not isinstance(body, dict):
        return []
    found: list[tuple[Loc, int]] = []
    parameters = body.get("parameters")
    for i, p in enumerate(parameters if isinstance(parameters, list) else []):
        values = p.get("values") if isinstance(p, dict) else None
        if isinstance(values, list):
            found.append(([*pre, "parameters", i, "values"], len(values)))
    design = body.get("design")
    cases = design.get("cases") if isinstance(design, dict) else None
    if isinstance(cases, list):
        found.append(([*pre, "design", "cases"], len(cases)))
    return [
        detail(
            loc,
            f"{dotted(loc[len(pre) :])}: {n} entries, more than this service's limit of {max_cases} cases "
            "(ISOLAB_MAX_CASES)",
        )
        for loc, n in found
        if n > max_cases
    ]


def _entries(container: Any, key: str) -> Any:
    return container.get(key) if isinstance(container, dict) else None


def over_long_lists(body: Any, prefix: Loc | None = None) -> list[dict[str, Any]]:
    """Details for every list of a raw study definition (or of its scene) longer than its bound: mounts,
    stages, points, criteria, a profile's segments, parameters (the ``MAX_*`` of
    :mod:`isolab.studies.inputs.schema.fields`). Read from lengths alone, before anything is parsed: a
    100,000-mount scene is refused in microseconds instead of after every mount is read."""
    pre: Loc = ["body"] if prefix is None else list(prefix)
    found: list[tuple[Loc, Any, int, str]] = [
        ([*pre, "parameters"], _entries(body, "parameters"), MAX_PARAMETERS, "parameters"),
        ([*pre, "criteria"], _entries(body, "criteria"), MAX_CRITERIA, "criteria"),
    ]
    for scene_loc, scene in (([*pre, "scene"], _entries(body, "scene")), (pre, body)):
        if not isinstance(scene, dict) or scene_loc == pre and "machine" not in scene:
            continue  # the body is a scene itself only when it names a machine
        stages = _entries(scene, "stages")
        found += [
            (
                [*scene_loc, "isolators", "list"],
                _entries(_entries(scene, "isolators"), "list"),
                MAX_MOUNTS,
                "mounts",
            ),
            ([*scene_loc, "stages"], stages, MAX_STAGES, "stages"),
            ([*scene_loc, "points"], _entries(scene, "points"), MAX_POINTS, "points"),
            ([*scene_loc, "criteria"], _entries(scene, "criteria"), MAX_CRITERIA, "criteria"),
        ]
        for i, stage in enumerate(stages[:MAX_STAGES] if isinstance(stages, list) else []):
            segments = _entries(_entries(stage, "profile"), "segments")
            found.append(
                ([*scene_loc, "stages", i, "profile", "segments"], segments, MAX_SEGMENTS, "segments")
            )
    return [
        detail(
            loc,
            f"{dotted(loc[len(pre) :])}: {len(entries)} {what}, more than the {limit} a study may have",
            "too_long",
        )
        for loc, entries, limit, what in found
        if isinstance(entries, list | dict) and len(entries) > limit
    ]


def case_limit_loc(study: Study, prefix: Loc) -> Loc:
    """Where a validated study's case count is set: its samples, its list of cases or its parameters."""
    spec = study.design_spec
    if spec.type in SAMPLED_TYPES:
        return [*prefix, "design", "samples"]
    if spec.type == "optimize":
        return [*prefix, "design", "budget"]
    return [*prefix, "design", "cases"] if spec.type == "list" else [*prefix, "parameters"]


# ---------------------------------------------------------------------------------------------- validation
_MESSAGE_LOC = re.compile(r"^([A-Za-z_]\w*(?:\[\d+\])?(?:\.[A-Za-z_]\w*(?:\[\d+\])?)*)(?: \([^)]*\))?: ")


def _loc_from_message(msg: str) -> Loc:
    """``design.samples: ...`` -> ['design', 'samples']; ``parameters[0].path: ...`` -> ['parameters', 0,
    'path']; no such prefix -> []."""
    m = _MESSAGE_LOC.match(msg)
    if not m:
        return []
    loc: Loc = []
    for part in m.group(1).split("."):
        name, _, rest = part.partition("[")
        loc.append(name)
        if rest:
            loc.append(int(rest.rstrip("]")))
    return loc


def validation_details(err: ValidationError, prefix: Loc) -> list[dict[str, Any]]:
    """pydantic errors as details whose ``loc`` is the full path of the field (under ``prefix``)."""
    out = []
    for e in err.errors(include_url=False):
        msg = str(e["msg"]).removeprefix("Value error, ")
        loc = [x for x in e["loc"]]
        named = _loc_from_message(msg)
        if not loc:
            loc = named
        elif named and e["type"] == "value_error":  # a model's check naming a field below it
            loc = join_paths(loc, named)
        out.append(detail([*prefix, *loc], msg, str(e["type"])))
    return out


def check_definition(body: dict[str, Any], max_cases: int | None = None, prefix: Loc | None = None) -> Study:
    """Screen, count, parse and check a study definition given as data (inline scene only; no file is
    read). Returns the validated :class:`~isolab.studies.inputs.study.Study`.

    Raises:
        DefinitionError: one detail per problem, ``loc`` under ``prefix`` (default ``["body"]``).
    """
    pre: Loc = ["body"] if prefix is None else list(prefix)
    if body.get("scene_file") is not None:
        raise DefinitionError(
            [
                detail(
                    [*pre, "scene_file"],
                    "scene_file is not read over the API: give the scene inline "
                    "under 'scene' (the Python client and `isolab submit` inline it for you)",
                )
            ]
        )
    if max_cases is not None:  # counted first: lengths and integers only, whatever the body's size
        problems = long_lists(body, max_cases, pre)
        bound = case_count_bound(body, pre)
        if bound is not None and bound[0] > max_cases and bound[1] not in [d["loc"] for d in problems]:
            problems.append(too_many_cases(bound[0], bound[1], max_cases))
        if problems:
            raise DefinitionError(problems)
    problems = over_long_lists(body, pre)
    if problems:
        raise DefinitionError(problems)
    problems = screen_definition(body, pre)
    if problems:
        raise DefinitionError(problems)
    try:
        study = validate_study(body)
    except ValidationError as err:
        raise DefinitionError(validation_details(err, pre)) from None
    except (OverflowError, RecursionError) as err:  # a number or a structure past what can be computed
        raise DefinitionError(
            [detail(pre, f"the definition cannot be computed: {type(err).__name__}: {err}")]
        ) from None
    if max_cases is not None and study.planned_cases > max_cases:
        raise DefinitionError(
            [too_many_cases(int(study.planned_cases), case_limit_loc(study, pre), max_cases)]
        )
    return study


def stored_definition(study: Study) -> dict[str, Any]:
    """The definition the catalog keeps: validated, SI, defaults filled in, names as users write them."""
    return study.model_dump(mode="json", by_alias=True, exclude_none=True)


def definition_json(row: Mapping[str, Any]) -> str:
    """The stored definition of a catalog row (a study's record) as canonical JSON (sorted keys): the key
    that :func:`studies.inputs.study.study_from_json` caches a parsed study under."""
    return json.dumps(row["definition"], sort_keys=True)


def study_of(row: Mapping[str, Any]) -> Study:
    """The study object of a catalog row (parsed once per definition and process)."""
    return study_from_json(definition_json(row))
