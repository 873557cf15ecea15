"""Validation errors as the user reads them: one line per error, the dotted path of the input first."""

from __future__ import annotations

from collections.abc import Sequence

from pydantic import ValidationError


def error_messages(err: ValidationError) -> list[str]:
    """One line per error, ``dotted.path: reason``, e.g. ``scene.machine.inertia: must be symmetric``.

    Pydantic's "Value error, " prefix is dropped, and a message that already names its field
    (``stages[1].parent: ...`` under ``stages``) is not prefixed twice."""
    out = []
    for e in err.errors():
        parts = [str(x) for x in e["loc"]]
        loc = ".".join(parts)
        msg = e["msg"].removeprefix("Value error, ")
        head, sep, rest = msg.partition(": ")
        if sep and " " not in head and parts:
            if loc.endswith(head) or head in parts:
                msg = rest
            else:
                loc, msg = _deeper_path(parts, head, loc, msg, rest)
        out.append(f"{loc}: {msg}" if loc else msg)
    return out


def join_paths(loc: Sequence[str | int], named: Sequence[str | int]) -> list[str | int]:
    """The path of a check raised at ``loc`` whose message names ``named``, a path that overlaps the end of
    ``loc`` (``['scene', 'simulation', 'tolerance']`` + ``['simulation', 'tolerance', 'peak_foo']`` ->
    ``['scene', 'simulation', 'tolerance', 'peak_foo']``); without an overlap, ``named`` lies below
    ``loc``."""
    loc, named = list(loc), list(named)
    for i in range(len(loc)):
        if named[: len(loc) - i] == loc[i:]:
            return [*loc[:i], *named]
    return [*loc, *named]


def _deeper_path(parts: list[str], head: str, loc: str, msg: str, rest: str) -> tuple[str, str]:
    """A message naming a path that overlaps the end of its error's location (``stages[1].parent: ...``
    raised at ``stages``, ``simulation.tolerance.peak_foo: ...`` at ``scene.simulation.tolerance``): the
    location above the overlap followed by the message's path, and the message without it; otherwise both
    as they are."""
    for i in range(len(parts)):
        above = ".".join(parts[i:])
        if head.startswith(above) and head[len(above) : len(above) + 1] in ("", ".", "["):
            return ".".join([*parts[:i], head]), rest
    return loc, msg
