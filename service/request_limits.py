"""What the service refuses before it parses a request: bodies too large or nested too deep.

:class:`RequestLimits` is the ASGI middleware in front of every route. A body is refused with 413 as soon
as it is known to be larger than ``ISOLAB_MAX_BODY_BYTES``: by its ``Content-Length`` before any of it is
read, or, for a chunked body, as soon as the bytes received pass the limit (the rest is never read). A JSON
body nested deeper than :data:`MAX_JSON_DEPTH` is refused with 422 before it is parsed (the parser would
otherwise recurse into it). :func:`unreadable_body_is_422` turns FastAPI's 400 for a body its JSON parser
raised on (bytes that are not UTF-8, a number of more than 4300 digits) into the 422 any bad JSON gets.

What a definition's values may be (hostile quantity text, the case limit) is checked by
:mod:`isolab.studies.definitions`, which the routes call.
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np
from fastapi.exception_handlers import http_exception_handler
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.requests import Request
from starlette.responses import JSONResponse, Response
from starlette.types import ASGIApp, Message, Receive, Scope, Send

MAX_JSON_DEPTH = 32
"""Deepest nesting of objects and arrays accepted in a JSON body (a study needs about 8)."""


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
