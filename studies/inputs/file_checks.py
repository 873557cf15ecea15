"""Checking a study or scene file given on the command line, with one line per problem in the user's words.

``isolab run`` and ``isolab simulate`` read a file from disk; what is wrong with it is told the way
``isolab submit`` tells it (one ``field: reason`` line per problem, no traceback), with the keys the user
wrote: a stage by its name (``stages.y.mass``, as parameter paths name it, see
:mod:`isolab.studies.inputs.parameters`) rather than its list index (``stages[0]``), the aliases of the file
(``isolators.list``, ``design``) rather than the models' internal names (``mounts``, ``design_spec``). A
study is held to the same case limit as a submitted one
(:func:`isolab.studies.inputs.definitions.check_definition`);
a scene file given where a study is expected (or the other way round) is named as such, with the command
that takes it.
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError

from isolab.studies.inputs.definitions import (
    DefinitionError,
    check_definition,
    dotted,
    screen_definition,
    validation_details,
)
from isolab.studies.inputs.schema import Scene
from isolab.studies.inputs.study import Study, validate_scene

STUDY_KEYS = frozenset({"name", "scene", "scene_file", "parameters", "design"})
"""Top-level keys only a study file has."""
SCENE_KEYS = frozenset(f.alias or name for name, f in Scene.model_fields.items()) - {"simulation", "criteria"}
"""Top-level keys only a scene file has (``simulation`` and ``criteria`` may open either)."""
INTERNAL_NAMES = {"mounts": "list", "design_spec": "design"}
"""Model attribute -> the key a file writes (the models' aliases)."""


class FileProblem(ValueError):
    """A study or scene file cannot be used; ``lines`` holds one ``field: reason`` line per problem."""

    def __init__(self, lines: list[str]):
        super().__init__("; ".join(lines))
        self.lines = lines


def read_mapping(path: str | Path) -> dict[str, Any]:
    """The mapping in a YAML or JSON file (JSON for a ``.json`` name).

    Raises:
        FileProblem: the file is missing or unreadable, is not YAML/JSON or does not hold a mapping.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise FileProblem([f"{path}: no such file"]) from None
    except IsADirectoryError:
        raise FileProblem([f"{path}: is a directory, not a file"]) from None
    except (OSError, UnicodeDecodeError) as err:
        raise FileProblem([f"{path}: cannot be read: {err}"]) from None
    try:
        data = json.loads(text) if path.suffix.lower() == ".json" else yaml.safe_load(text)
    except (yaml.YAMLError, ValueError) as err:
        kind = "JSON" if path.suffix.lower() == ".json" else "YAML"
        raise FileProblem([f"{path}: not valid {kind}: {' '.join(str(err).split())}"]) from None
    if not isinstance(data, Mapping):
        raise FileProblem([f"{path}: expected a mapping at the top level, got {type(data).__name__}"])
    return dict(data)


def file_kind(data: Mapping[str, Any]) -> str | None:
    """``"study"`` or ``"scene"`` when the top-level keys say which the mapping is; None when they do not
    (both kinds, or neither)."""
    keys = set(data)
    study, scene = bool(keys & STUDY_KEYS), bool(keys & SCENE_KEYS)
    if study == scene:
        return None
    return "study" if study else "scene"


def _stage_names(data: Any) -> list[str | None]:
    """The names of a scene's stages, None where a stage has no usable (unique) name."""
    stages = data.get("stages") if isinstance(data, Mapping) else None
    if not isinstance(stages, list):
        return []
    names = [s.get("name") if isinstance(s, Mapping) else None for s in stages]
    return [n if isinstance(n, str) and names.count(n) == 1 and n.isidentifier() else None for n in names]


_STAGE_INDEX = re.compile(r"\bstages(?:\[(\d+)\]|\.(\d+))(?=[.:,;)\s]|$)")
_INTERNAL = re.compile(r"\b(isolators\.mounts|design_spec)\b")


def in_user_words(line: str, stage_names: Sequence[str | None]) -> str:
    """``line`` with stage indices written as stage names (``stages[0].mass``, ``stages.0.mass`` ->
    ``stages.y.mass``) and internal attribute names as the keys of the file (``isolators.mounts`` ->
    ``isolators.list``, ``design_spec`` -> ``design``). An index without a unique name stays."""

    def stage(m: re.Match[str]) -> str:
        k = int(m.group(1) or m.group(2))
        name = stage_names[k] if k < len(stage_names) else None
        return f"stages.{name}" if name else m.group(0)

    line = _STAGE_INDEX.sub(stage, line)
    return _INTERNAL.sub(lambda m: "isolators.list" if m.group(1) == "isolators.mounts" else "design", line)


def problem_line(loc: Sequence[str | int], msg: str) -> str:
    """``field: reason`` from a detail's ``loc`` and ``msg``, the field named once when the message already
    names it (``design.samples: ...``, ``stages[1].parent: ...`` under ``stages``)."""
    loc = [INTERNAL_NAMES.get(x, x) if isinstance(x, str) else x for x in loc if x != "body"]
    where = dotted(loc) if loc else ""
    if not where or msg.startswith((f"{where}:", f"{where} ", f"{where}.", f"{where}[")):
        return msg
    head, sep, rest = msg.partition(": ")
    if sep and " " not in head and where.endswith(f".{head}"):  # the message names the field below
        return f"{where}: {rest}"
    last = loc[-1]
    if (
        sep
        and " " not in head
        and isinstance(last, str)
        and (head == last or head.startswith((f"{last}.", f"{last}[")))
    ):
        parent = dotted(loc[:-1]) if len(loc) > 1 else ""
        return f"{parent}.{head}: {rest}" if parent else f"{head}: {rest}"
    return f"{where}: {msg}"


def problem_lines(details: Sequence[Mapping[str, Any]], scene: Any) -> list[str]:
    """One line per detail (``{"loc", "msg", "type"}``, as :class:`DefinitionError` holds them), in the
    words of the file: ``scene`` is the scene mapping whose stages the lines may name."""
    names = _stage_names(scene)
    out = []
    for d in details:
        msg = "unknown key" if d.get("type") == "extra_forbidden" else str(d["msg"])
        line = in_user_words(problem_line(list(d.get("loc", [])), msg), names)
        if line not in out:
            out.append(line)
    return out


def check_study_file(path: str | Path, max_cases: int | None = None) -> Study:
    """The validated study of a study file, its ``scene_file`` (relative to the file) read and inlined,
    checked as a submitted study is (``max_cases``: the case limit, as ``ISOLAB_MAX_CASES`` sets it).

    Raises:
        FileProblem: one line per problem; for a scene file, that it is one and the command to use.
    """
    path = Path(path)
    data = read_mapping(path)
    if file_kind(data) == "scene":
        raise FileProblem([f"{path}: this is a scene: use `isolab simulate {path}`"])
    scene_file = data.pop("scene_file", None)
    if scene_file is not None:
        if data.get("scene") is not None:
            raise FileProblem([f"{path}: scene_file: give scene or scene_file, not both"])
        scene_path = path.resolve().parent / str(scene_file)
        if not scene_path.is_file():
            raise FileProblem([f"{path}: scene_file: no file {scene_path}"])
        data["scene"] = read_mapping(scene_path)
    try:
        return check_definition(data, max_cases, prefix=[])
    except DefinitionError as err:
        raise FileProblem(problem_lines(err.details, data.get("scene"))) from None


def check_scene_file(path: str | Path) -> Scene:
    """The validated scene of a scene file.

    Raises:
        FileProblem: one line per problem; for a study file, that it is one and the command to use.
    """
    path = Path(path)
    data = read_mapping(path)
    if file_kind(data) == "study":
        raise FileProblem([f"{path}: this is a study: use `isolab run {path} -o OUT.nc`"])
    details = screen_definition(data, [])
    if not details:
        try:
            return validate_scene(data)
        except ValidationError as err:  # the check step's failures come in the same shape
            details = validation_details(err, [])
        except (OverflowError, RecursionError) as err:
            details = [{"loc": [], "msg": f"the scene cannot be computed: {type(err).__name__}: {err}"}]
    raise FileProblem(problem_lines(details, data))
