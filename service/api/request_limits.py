"""What the service refuses before it parses a request: bodies too large or nested too deep.

:class:`RequestLimits` is the ASGI middleware in front of every route. A body is refused with 413 as soon
as it is known to be larger than ``ISOLAB_MAX_BODY_BYTES``: by its ``Content-Length`` before any of it is
read, or, for a chunked body, as soon as the bytes received pass the limit (the rest is never read). A JSON
body nested deeper than :data:`MAX_JSON_DEPTH` is refused with 422 before it is parsed (the parser would
otherwise recurse into it), and so is one holding a number no JSON may hold (``NaN``, ``Infinity``,
``1e999``: Python's json reads them as non-finite floats), naming where it is.

:func:`validation_errors_as_json` answers FastAPI's 422 with any non-finite input it echoes written as
text (the default handler cannot encode it and answers 500). :func:`unreadable_body_is_422` turns
FastAPI's 400 for a body its JSON parser raised on (bytes that are not UTF-8, a number of more than 4300
digits) into the 422 any bad JSON gets, and gives a 405 the ``Allow`` of every method at its path.

A route of a router made with ``route_class=JsonParsedOffLoop`` reads a JSON body larger than
:data:`LOOP_SCAN_BYTES` in a worker thread with the cyclic garbage collector paused
(:func:`parse_large_json`): the event loop keeps answering other requests (``/health``, a study's status)
while megabytes are parsed.

What a definition's values may be (hostile quantity text, the case limit) is checked by
:mod:`isolab.studies.inputs.definitions`, which the routes call.
"""

from __future__ import annotations

import gc
import json
import math
import re
import threading
from collections.abc import Callable, Coroutine, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
from anyio import to_thread
from fastapi.encoders import jsonable_encoder
from fastapi.exception_handlers import http_exception_handler
from fastapi.exceptions import RequestValidationError
from fastapi.routing import APIRoute
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.requests import Request
from starlette.responses import JSONResponse, Response
from starlette.types import ASGIApp, Message, Receive, Scope, Send

MAX_JSON_DEPTH = 32
"""Deepest nesting of objects and arrays accepted in a JSON body (a study needs about 8)."""


# ---------------------------------------------------------------------------------------------- bodies
#: What may parse to a float that is not finite, outside strings: the NaN and Infinity literals Python's
#: json reads, a number with an exponent of 3 or more digits (``1e999``) or a run of 300 or more digits.
_MAYBE_NON_FINITE = re.compile(rb"NaN|Infinity|[eE][-+]?\d{3}|\d{300}")
#: Bytes searched at a time for :data:`_MAYBE_NON_FINITE` (each search holds the interpreter lock), and
#: the overlap of two pieces (no match is longer).
_SEARCH_PIECE = 64 * 1024
_SEARCH_OVERLAP = 300
_QUOTE, _BACKSLASH, _SPACE = ord('"'), ord("\\"), ord(" ")


def _bare(body: bytes) -> bytes:
    """The JSON text with every string, its quotes included, blanked out with spaces (what is left is
    structure, numbers and literals, at their places).

    Array operations, not a regular expression: numpy hands the interpreter lock on while it works
    through megabytes, a regular expression would hold it throughout."""
    codes = np.frombuffer(body, dtype=np.uint8)
    edge = np.zeros(1, dtype=np.int8)
    backslash = np.concatenate((edge, (codes == _BACKSLASH).view(np.int8), edge))
    edges = np.flatnonzero(np.diff(backslash))  # where runs of backslashes start and end, in turn
    starts, ends = edges[::2], edges[1::2]
    after_odd_run = ends[((ends - starts) % 2 == 1) & (ends < codes.size)]
    quotes = codes == _QUOTE
    quotes[after_odd_run] = False  # an escaped quote
    inside = (np.cumsum(quotes, dtype=np.int32) & 1).astype(bool) | quotes
    bare = codes.copy()
    bare[inside] = _SPACE
    return bare.tobytes()


def _may_be_non_finite(bare: bytes) -> bool:
    """Whether :data:`_MAYBE_NON_FINITE` matches the bare text, searched a piece at a time."""
    for start in range(0, max(len(bare), 1), _SEARCH_PIECE):
        if _MAYBE_NON_FINITE.search(bare, start, start + _SEARCH_PIECE + _SEARCH_OVERLAP):
            return True
    return False


def json_depth(body: bytes) -> int:
    """Deepest nesting of ``[``/``{`` in a JSON text (brackets inside strings do not count)."""
    if not body:
        return 0
    return _depth(_bare(body))


def _depth(bare: bytes) -> int:
    codes = np.frombuffer(bare, dtype=np.uint8)
    steps = np.zeros(codes.size, dtype=np.int32)
    steps[(codes == ord("[")) | (codes == ord("{"))] = 1
    steps[(codes == ord("]")) | (codes == ord("}"))] = -1
    return int(np.cumsum(steps).max(initial=0))


def non_finite_number(body: bytes, bare: bytes | None = None) -> tuple[list[str | int], str] | None:
    """Where a JSON text holds a number no JSON may hold: ``(loc, message)`` of the first ``NaN``,
    ``Infinity``, ``-Infinity`` or literal beyond a 64-bit float (``1e999``), else ``None``.

    Python's json reads these as non-finite floats; FastAPI would hand them on (and its 422 handler, echoing
    the input, could not encode them). Text that is not JSON is left to the route's own parser.
    """
    if not _may_be_non_finite(_bare(body) if bare is None else bare):
        return None
    try:
        data = parse_large_json(body) if len(body) > LOOP_SCAN_BYTES else json.loads(body)
    except (ValueError, RecursionError):
        return None
    found = _first_non_finite(data, ["body"])
    if found is None:
        return None
    loc, value = found
    what = "NaN" if math.isnan(value) else "Infinity" if value > 0 else "-Infinity"
    return loc, (
        f"{what} is not a finite number: a JSON number must be finite "
        "(no NaN, Infinity or literal beyond a 64-bit float such as 1e999)"
    )


def _first_non_finite(data: Any, loc: list[str | int]) -> tuple[list[str | int], float] | None:
    stack: list[tuple[Any, list[str | int]]] = [(data, loc)]
    while stack:
        node, where = stack.pop()
        if isinstance(node, float):
            if not math.isfinite(node):
                return where, node
        elif isinstance(node, dict):
            stack.extend((v, [*where, k]) for k, v in reversed(list(node.items())))
        elif isinstance(node, list):
            stack.extend((v, [*where, i]) for i, v in reversed(list(enumerate(node))))
    return None


LOOP_SCAN_BYTES = 256 * 1024
"""Bodies larger than this are scanned (depth, non-finite numbers) in a worker thread, not on the loop."""


class CollectorPause:
    """Pauses of the cyclic garbage collector, counted across threads: the collector runs again when the
    last pause ends (and only if it ran when the first began)."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.depth = 0
        self.was_enabled = False

    @contextmanager
    def paused(self) -> Iterator[None]:
        with self.lock:
            if self.depth == 0:
                self.was_enabled = gc.isenabled()
                gc.disable()
            self.depth += 1
        try:
            yield
        finally:
            with self.lock:
                self.depth -= 1
                if self.depth == 0 and self.was_enabled:
                    gc.enable()


_COLLECTOR = CollectorPause()


def parse_large_json(body: bytes) -> Any:
    """``json.loads(body)`` with the cyclic garbage collector paused (for a worker thread).

    A JSON text parses to a tree, never to a cycle, yet every hundreds of containers it makes start a
    collector pass, and the passes over the growing heap make parsing a 4 MB body 5 to 10 times slower,
    all of it holding the interpreter lock (the parser is C code: the event loop's thread cannot run until
    it returns). Paused, 4 MB of mounts parse in about 0.05 s instead of 0.4 s."""
    with _COLLECTOR.paused():
        return json.loads(body)


class LargeJsonOffLoopRequest(Request):
    """A request whose ``json()`` parses a body larger than :data:`LOOP_SCAN_BYTES` in a worker thread
    (:func:`parse_large_json`), smaller ones on the loop as usual."""

    parsed: Any

    async def json(self) -> Any:
        if not hasattr(self, "parsed"):
            body = await self.body()
            if len(body) > LOOP_SCAN_BYTES:
                self.parsed = await to_thread.run_sync(parse_large_json, body)
            else:
                self.parsed = json.loads(body)
        return self.parsed


class JsonParsedOffLoop(APIRoute):
    """The route class of the routers that take large JSON bodies (a study definition, a scene, a
    measurement): FastAPI reads the body through :class:`LargeJsonOffLoopRequest`."""

    def get_route_handler(self) -> Callable[[Request], Coroutine[Any, Any, Response]]:
        handler = super().get_route_handler()

        async def handle(request: Request) -> Response:
            return await handler(LargeJsonOffLoopRequest(request.scope, request.receive))

        return handle


def _bare_and_depth(body: bytes, max_depth: int) -> tuple[bytes, bool]:
    """The body with its strings blanked out, and whether it is nested deeper than ``max_depth``."""
    bare = _bare(body)
    return bare, _depth(bare) > max_depth


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
        # FastAPI reads a body as JSON when its type says so, or when no type is given
        if body and (b"json" in content_type or not content_type):
            # scanning a body of megabytes takes a good part of a second: in a worker thread, so that the
            # event loop keeps answering other requests (/health) meanwhile
            if len(body) > LOOP_SCAN_BYTES:
                bare, too_deep = await to_thread.run_sync(_bare_and_depth, body, self.max_depth)
            else:
                bare, too_deep = _bare_and_depth(body, self.max_depth)
            if too_deep:
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
            if len(body) > LOOP_SCAN_BYTES:
                non_finite = await to_thread.run_sync(non_finite_number, body, bare)
            else:
                non_finite = non_finite_number(body, bare)
            if non_finite is not None:
                loc, msg = non_finite
                await self._answer(
                    scope, send, 422, [{"loc": loc, "msg": msg, "type": "finite_number"}], close=False
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
    async def _answer(scope: Scope, send: Send, status: int, detail: Any, close: bool = True) -> None:
        # the connection closes after the answer (the rest of an unread body is never read), unless the
        # whole body was read
        headers = {"Connection": "close"} if close else None
        response = JSONResponse({"detail": detail}, status_code=status, headers=headers)

        async def nothing() -> Message:
            return {"type": "http.disconnect"}

        await response(scope, nothing, send)


HTTP_METHODS = frozenset({"GET", "PUT", "POST", "DELETE", "PATCH", "HEAD", "OPTIONS", "TRACE"})

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
    if exc.status_code == 405:
        allowed = allowed_methods(request)
        if allowed:
            exc.headers = {**(exc.headers or {}), "Allow": ", ".join(allowed)}
    return await http_exception_handler(request, exc)


def allowed_methods(request: Request) -> list[str]:
    """The methods the API description gives the request's path (for the ``Allow`` of a 405): those of
    the most specific template that matches it (``/studies/validate`` before ``/studies/{study_id}``).
    Starlette names only the methods of the first route that matches the path, though others at it take
    other methods. Empty for a path the description does not hold."""
    path = request.scope["path"]
    by_template: dict[str, list[str]] = {}
    for template, operations in request.app.openapi().get("paths", {}).items():
        pattern = re.sub(r"\\\{[^/]*?\\\}", "[^/]+", re.escape(template))
        if re.fullmatch(pattern, path):
            by_template[template] = sorted(m.upper() for m in operations if m.upper() in HTTP_METHODS)
    if not by_template:
        return []
    best = min(by_template, key=lambda template: (template.count("{"), -len(template)))
    return by_template[best]


def _finite_or_text(value: Any) -> Any:
    """``value`` with every non-finite float (at any depth) written as text (``"NaN"``, ``"Infinity"``)."""
    if isinstance(value, float) and not math.isfinite(value):
        return "NaN" if math.isnan(value) else "Infinity" if value > 0 else "-Infinity"
    if isinstance(value, dict):
        return {k: _finite_or_text(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_finite_or_text(v) for v in value]
    return value


async def validation_errors_as_json(request: Request, exc: RequestValidationError) -> Response:
    """Exception handler: FastAPI's 422 for a request that fails validation, the input it echoes made
    encodable (a non-finite number becomes text instead of a 500)."""
    return JSONResponse(status_code=422, content={"detail": _finite_or_text(jsonable_encoder(exc.errors()))})
