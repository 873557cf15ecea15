"""The calibrated scene as text: the scene's own file with the fitted values written in.

:func:`calibrated_text` edits the scene's text where each fitted value lives (found by its scene path in
the YAML node tree, which knows every value's place in the text): a value written with a unit is
replaced by the fitted one in that unit (``3 Hz`` -> ``3.50012 Hz``), a plain number by a plain number
(SI), and a value the scene leaves out is added under its parent, in the target's SI unit. Comments,
order, units and flow style of everything else stay as written. Figures of the isolator group fitted by
the calibration override every type's ``tuning`` of them, so those tuning entries are removed (an entry
left empty goes with them). The text starts with the calibration's header of comments.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import yaml

from isolab.studies.inputs.parameters import Target
from isolab.studies.inputs.schema.scene_paths import ISOLATORS, MOUNT_FIGURES
from isolab.studies.inputs.study import validate_scene
from isolab.studies.units import unit_value, written_unit

Edit = tuple[int, int, str]
"""Replace the text from one index to another by a string."""


def _number(value: float, unit: str | None, dimension: str) -> str:
    """``value`` (SI) as the scene would write it: in ``unit`` when one is given, else a plain number."""
    one = unit_value(unit, dimension) if unit else None
    if unit and one:
        return f"{value / one:.8g} {unit}"
    return f"{value:.8g}"


def _child(node: yaml.Node, part: str, parent: str | None) -> yaml.Node | None:
    """The node under ``node`` that ``part`` of a scene path names (a stage by its name)."""
    if isinstance(node, yaml.MappingNode):
        for k, v in node.value:
            if isinstance(k, yaml.ScalarNode) and k.value == part:
                return v
        return None
    if isinstance(node, yaml.SequenceNode):
        if parent == "stages":
            for item in node.value:
                if isinstance(item, yaml.MappingNode) and _child(item, "name", None) is not None:
                    name = _child(item, "name", None)
                    if isinstance(name, yaml.ScalarNode) and name.value == part:
                        return item
            return None
        if part.isdigit() and int(part) < len(node.value):
            return node.value[int(part)]
    return None


def _line_start(text: str, index: int) -> int:
    return text.rfind("\n", 0, index) + 1


def _line_end(text: str, index: int) -> int:
    end = text.find("\n", index)
    return len(text) if end < 0 else end + 1


def _nested(keys: list[str], value: str, flow: bool, indent: int) -> str:
    """``keys`` nested down to ``value``: ``a: {b: v}`` in flow style, indented lines in block style."""
    if flow:
        inner = value
        for k in reversed(keys[1:]):
            inner = f"{{{k}: {inner}}}"
        return f"{keys[0]}: {inner}"
    lines = []
    for depth, k in enumerate(keys):
        pad = " " * (indent + 2 * depth)
        lines.append(f"{pad}{k}:" + (f" {value}" if depth == len(keys) - 1 else ""))
    return "\n".join(lines) + "\n"


def _write(text: str, root: yaml.Node, leaf: str, value: float, dimension: str, si: str) -> Edit | None:
    """The edit that writes ``value`` at ``leaf`` (a scene path); None where it cannot be placed."""
    parts = leaf.split(".")
    node, parent = root, None
    for i, part in enumerate(parts):
        child = _child(node, part, parent)
        if child is None:
            if not isinstance(node, yaml.MappingNode) or any(p.isdigit() for p in parts[i:]):
                return None
            new = _number(value, si or None, dimension)
            if node.flow_style:
                end = node.end_mark.index - 1  # the closing brace
                sep = ", " if node.value else ""
                return end, end, sep + _nested(parts[i:], new, True, 0)
            if not node.value:
                return None
            first = node.value[0][0]
            at = _line_start(text, first.start_mark.index)
            return at, at, _nested(parts[i:], new, False, first.start_mark.column)
        node, parent = child, part
    if not isinstance(node, yaml.ScalarNode):
        return None
    unit = written_unit(node.value, dimension) if node.style is None or node.style in "'\"" else None
    new = _number(value, unit, dimension)
    if node.style in ("'", '"'):
        new = f"{node.style}{new}{node.style}"
    return node.start_mark.index, node.end_mark.index, new


def _remove(text: str, mapping: yaml.MappingNode, index: int) -> Edit:
    """The edit that removes entry ``index`` of ``mapping`` (its key, value and the rest of its line)."""
    key, val = mapping.value[index]
    if mapping.flow_style:
        if index + 1 < len(mapping.value):
            return key.start_mark.index, mapping.value[index + 1][0].start_mark.index, ""
        start = mapping.value[index - 1][1].end_mark.index if index else key.start_mark.index
        return start, val.end_mark.index, ""
    start = _line_start(text, key.start_mark.index)
    if index + 1 < len(mapping.value):
        return start, _line_start(text, mapping.value[index + 1][0].start_mark.index), ""
    return start, _line_end(text, max(val.end_mark.index - 1, key.end_mark.index)), ""


def _stale_tuning(text: str, root: yaml.Node, figures: set[str]) -> list[Edit]:
    """Edits removing every type's ``tuning`` of the isolator group's ``figures`` (an entry left empty
    goes too)."""
    iso = _child(root, ISOLATORS, None)
    tuning = _child(iso, "tuning", ISOLATORS) if iso is not None else None
    if not isinstance(iso, yaml.MappingNode) or not isinstance(tuning, yaml.MappingNode):
        return []
    edits: list[Edit] = []
    emptied = []
    for t, (_, fig) in enumerate(tuning.value):
        if not isinstance(fig, yaml.MappingNode):
            continue
        gone = [j for j, (k, _) in enumerate(fig.value) if k.value in figures]
        if gone and len(gone) == len(fig.value):
            emptied.append(t)
        elif gone:
            edits += [_remove(text, fig, j) for j in gone]
    if emptied and len(emptied) == len(tuning.value):
        at = next(j for j, (k, _) in enumerate(iso.value) if k.value == "tuning")
        return [_remove(text, iso, at)]
    return edits + [_remove(text, tuning, t) for t in emptied]


def calibrated_text(text: str, header: Sequence[str], values: Sequence[tuple[Target, float]]) -> str:
    """``text`` (the scene's YAML or JSON) with each target's fitted ``value`` (SI) written in, stale
    tuning removed, and the ``header`` comment lines first. Where the text cannot be edited so (a value
    it cannot place), the scene with the values applied is dumped as YAML instead."""
    head = "\n".join(header) + "\n"
    try:
        root = yaml.compose(text, Loader=yaml.SafeLoader)
        if root is None:
            raise ValueError("an empty scene")
        edits: list[Edit] = []
        figures: set[str] = set()
        for target, value in values:
            for leaf in target.writes:
                e = _write(text, root, leaf, value, target.dimension, target.unit)
                if e is None:
                    raise ValueError(leaf)
                edits.append(e)
                parts = leaf.split(".")
                if len(parts) == 2 and parts[0] == ISOLATORS and parts[1] in MOUNT_FIGURES:
                    figures.add(parts[1])
        edits += _stale_tuning(text, root, figures)
        out = text
        order = sorted(range(len(edits)), key=lambda i: (edits[i][0], edits[i][1], i), reverse=True)
        for i in order:  # from the end, so that each index still points where it did
            start, end, new = edits[i]
            out = out[:start] + new + out[end:]
        validate_scene(yaml.safe_load(out))
        return head + out
    except (yaml.YAMLError, ValueError, TypeError, AttributeError):
        return head + _dumped(text, values)


def _dumped(text: str, values: Sequence[tuple[Target, float]]) -> str:
    from isolab.studies.inputs.parameters import apply, scene_dict

    data: Any = yaml.safe_load(text)
    scene = validate_scene(
        apply(scene_dict(validate_scene(data)), [t for t, _ in values], [v for _, v in values])
    )
    return yaml.safe_dump(scene_dict(scene), sort_keys=False)
