"""What the service refuses before it parses or validates a request: bodies too large or nested too deep,
quantities whose arithmetic would not end, numbers no float holds, studies above the case limit.

:class:`RequestLimits` is the ASGI middleware in front of every route. A body is refused with 413 as soon
as it is known to be larger than ``ISOLAB_MAX_BODY_BYTES``: by its ``Content-Length`` before any of it is
read, or, for a chunked body, as soon as the bytes received pass the limit (the rest is never read). A JSON
body nested deeper than :data:`MAX_JSON_DEPTH` is refused with 422 before it is parsed (the parser would
otherwise recurse into it). :func:`unreadable_body_is_422` turns FastAPI's 400 for a body its JSON parser
raised on (bytes that are not UTF-8, a number of more than 4300 digits) into the 422 any bad JSON gets.

:func:`screen_definition` walks a parsed study or scene and names the first field whose value is hostile:
quantity text is read by a units parser that computes integer powers exactly, so ``"9**9**9 kg"`` would
take hours and ``"10**999 kg"`` no float holds. :func:`case_count_bound` counts a study's cases from the
raw definition, so a study above ``ISOLAB_MAX_CASES`` is refused before its design is built.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from typing import Any

import numpy as np
from fastapi.exception_handlers import http_exception_handler
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.requests import Request
from starlette.responses import JSONResponse, Response
from starlette.types import ASGIApp, Message, Receive, Scope, Send

MAX_JSON_DEPTH = 32
"""Deepest nesting of objects and arrays accepted in a JSON body (a study needs about 8)."""
FREE_TEXT_KEYS = frozenset({"description"})
"""Keys whose string values are prose, never read as quantities (no length or power rule)."""
SAMPLED_DESIGNS = ("lhs", "sobol", "random")



# ---------------------------------------------------------------------------------------------- bodies
def json_depth(body: bytes) -> int:
    """Deepest nesting of ``[``/``{`` in a JSON text (brackets inside strings do not count)."""
    if not body:
        return 0
    bare = re.sub(rb'"(?:[^"\\]|\\.)*"', b'""', body)
    codes = np.frombuffer(bare, dtype=np.uint8)
    steps = np.zeros(codes.size, dtype=np.int32)
    steps[(codes == ord("[")) | (codes == ord("{"))] = 1
    steps[(codes == ord("]")) | (codes == ord("}"))] = -1
    return int(np.cumsum(steps).max(initial=0))


def _header(scope: Scope, name: bytes) -> bytes | None:
    for key, value in scope.get("headers") or []:
        if key.lower() == name:
            return value
    return None


class RequestLimits:
    """ASGI middleware: 413 for a body over ``max_bytes`` (read no further than the limit), 422 for a
    JSON body nested deeper than ``max_depth``. Requests without a body pass straight through."""

    def __init__(self, app: ASGIApp, max_bytes: int, max_depth: int = MAX_JSON_DEPTH):
        self.app = app
        self.max_bytes = int(max_bytes)
        self.max_depth = int(max_depth)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        length = _header(scope, b"content-length")
        chunked = b"chunked" in (_header(scope, b"transfer-encoding") or b"").lower()
        if length is not None:
            text = length.strip()
            if not text.isdigit():
                await self._answer(scope, send, 400, "Content-Length is not a number of bytes")
                return
            if int(text) > self.max_bytes:
                await self._too_large(scope, send)
                return
            if int(text) == 0 and not chunked:
                await self.app(scope, receive, send)
                return
        elif not chunked:
            await self.app(scope, receive, send)
            return
        parts: list[bytes] = []
        seen = 0
        while True:
            message = await receive()
            if message["type"] != "http.request":  # the client went away
                return
            chunk = message.get("body", b"")
            seen += len(chunk)
            if seen > self.max_bytes:
                await self._too_large(scope, send)
                return
            parts.append(chunk)
            if not message.get("more_body", False):
                break
        body = b"".join(parts)
        content_type = (_header(scope, b"content-type") or b"").lower()
        if b"json" in content_type and json_depth(body) > self.max_depth:
            await self._answer(
                scope,
                send,
                422,
                [
                    {
                        "loc": ["body"],
                        "msg": f"JSON nested deeper than {self.max_depth} levels of objects and arrays",
                        "type": "value_error",
                    }
                ],
            )
            return
        delivered = False

        async def replay() -> Message:
            nonlocal delivered
            if not delivered:
                delivered = True
                return {"type": "http.request", "body": body, "more_body": False}
            return await receive()

        await self.app(scope, replay, send)

    async def _too_large(self, scope: Scope, send: Send) -> None:
        await self._answer(
            scope, send, 413, f"request body larger than {self.max_bytes} bytes (ISOLAB_MAX_BODY_BYTES)"
        )

    @staticmethod
    async def _answer(scope: Scope, send: Send, status: int, detail: Any) -> None:
        # the connection closes after the answer: the rest of an unread body is never read
        response = JSONResponse({"detail": detail}, status_code=status, headers={"Connection": "close"})

        async def nothing() -> Message:
            return {"type": "http.disconnect"}

        await response(scope, nothing, send)


BODY_PARSE_ERROR = "There was an error parsing the body"
"""FastAPI's 400 detail for a body its JSON parser raised on (bad UTF-8, a number of over 4300 digits)."""


async def unreadable_body_is_422(request: Request, exc: StarletteHTTPException) -> Response:
    """Exception handler: FastAPI answers 400 for a body its JSON parser raised on (not a
    ``JSONDecodeError``); answer 422 naming the body and the reason, as for any other bad JSON.
    Every other HTTP error is answered as usual."""
    if exc.status_code == 400 and exc.detail == BODY_PARSE_ERROR:
        cause = exc.__cause__
        reason = f"{type(cause).__name__}: {cause}" if cause is not None else "it cannot be parsed"
        return JSONResponse(
            {
                "detail": [
                    {
                        "loc": ["body"],
                        "msg": f"the body is not valid JSON: {reason}"[:500],
                        "type": "json_invalid",
                    }
                ]
            },
            status_code=422,
        )
    return await http_exception_handler(request, exc)


# ------------------------------------------------------------------------------------------ quantities
def quantity_problem(text: str) -> str | None:
    """Why the quantity text ``text`` is refused, or None when it is safe to hand to the units parser: the
    rules of :func:`studies.units.quantity_text_problem`, and a value no 64-bit float holds (``10**999``)."""
    from isolab.studies.units import quantity_text_problem

    return quantity_text_problem(text) or _magnitude_problem(text)


def _magnitude_problem(text: str) -> str | None:
    """The units parser's reading of a screened text: None unless its number overflows a float."""
    from isolab.studies.units import UREG

    try:
        q = UREG.Quantity(text)
        magnitude = q.magnitude if hasattr(q, "magnitude") else q
        float(np.asarray(magnitude, dtype=float))
        if hasattr(q, "to_base_units"):
            float(np.asarray(q.to_base_units().magnitude, dtype=float))
    except OverflowError:
        return "the number is too large for a 64-bit float"
    except Exception:  # unreadable text: validation names the field and the reason
        return None
    return None


def _walk(value: Any, loc: list[str | int]) -> Iterator[tuple[list[str | int], Any]]:
    """(loc, leaf) of every leaf of a parsed JSON value, without recursion."""
    stack: list[tuple[list[str | int], Any]] = [(loc, value)]
    while stack:
        where, node = stack.pop()
        if isinstance(node, dict):
            stack.extend((where + [str(k)], v) for k, v in reversed(list(node.items())))
        elif isinstance(node, list | tuple):
            stack.extend((where + [i], v) for i, v in reversed(list(enumerate(node))))
        else:
            yield where, node


def screen_definition(body: Any, prefix: list[str | int]) -> list[dict[str, Any]]:
    """422 details (``loc`` under ``prefix``, ``msg`` naming the field) for every hostile value in a
    parsed study or scene: quantity text :func:`quantity_problem` refuses, and integers beyond a float's
    range. Empty when nothing is hostile."""
    problems = []
    for loc, leaf in _walk(body, list(prefix)):
        field = dotted(loc[len(prefix) :])
        if isinstance(leaf, bool) or leaf is None:
            continue
        if isinstance(leaf, int):
            if abs(leaf) > 1.7e308:
                problems.append(_detail(loc, f"{field}: the number is too large for a 64-bit float"))
        elif isinstance(leaf, str):
            named = [x for x in loc if isinstance(x, str)]
            if named and named[-1] in FREE_TEXT_KEYS:
                continue
            reason = quantity_problem(leaf)
            if reason is not None:
                shown = f"{leaf[:40]!r}" + ("..." if len(leaf) > 40 else "")
                problems.append(_detail(loc, f"{field}: {shown}: {reason}"))
    return problems


def dotted(loc: list[str | int]) -> str:
    """``["scene", "stages", 0, "mass"]`` -> ``scene.stages[0].mass``."""
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out or "body"


def _detail(loc: list[str | int], msg: str) -> dict[str, Any]:
    return {"loc": loc, "msg": msg, "type": "value_error"}


# --------------------------------------------------------------------------------------------- cases
def _count(value: Any) -> int | None:
    if isinstance(value, bool) or not isinstance(value, int):
        return None
    return value


def case_count_bound(body: Any) -> tuple[int, list[str | int]] | None:
    """(number of cases, loc that sets it) of a raw study definition, read without building its design;
    None when the definition does not say (validation will tell what is missing).

    Sampled designs have ``design.samples`` cases, a list design ``len(design.cases)``, a grid the
    product of each parameter's ``values`` count or ``range.num``."""
    if not isinstance(body, dict):
        return None
    design = body.get("design")
    design = design if isinstance(design, dict) else {}
    kind = design.get("type", "grid")
    if kind in SAMPLED_DESIGNS:
        n = _count(design.get("samples"))
        return None if n is None else (n, ["body", "design", "samples"])
    if kind == "list":
        cases = design.get("cases")
        return (len(cases), ["body", "design", "cases"]) if isinstance(cases, list) else None
    parameters = body.get("parameters")
    if parameters is None:
        return 1, ["body", "parameters"]
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
    return total, ["body", "parameters"]
