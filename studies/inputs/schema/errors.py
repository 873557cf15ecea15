"""Validation errors as the user reads them: one line per error, the dotted path of the input first."""

from __future__ import annotations

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
            elif head.startswith(parts[-1]):
                loc, msg = ".".join([*parts[:-1], head]), rest
        out.append(f"{loc}: {msg}" if loc else msg)
    return out
