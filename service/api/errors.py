"""Refusals of the studies layer as HTTP answers, registered once on the app: a route lets them rise.

* :class:`~isolab.studies.inputs.definitions.DefinitionError` (a study, scene, comparison, calibration or
  floor plot refused): 422 ``{"detail": err.details}``, one ``{loc, msg, type}`` per problem, the shape of
  FastAPI's own 422;
* :class:`~isolab.studies.results.cases.CaseQueryError` (a case-table query or a case number): 422
  ``{"detail": [{"loc": [where, param], "msg": "<message>", "type": "value_error"}]}``;
* :class:`~isolab.studies.answers.history.CaseNotFound` (no case of that number) and
  :class:`~isolab.studies.authoring.authoring.ExampleNotFound` (no example of that name): 404
  ``{"detail": "<message>"}``.

A refusal whose answer depends on the request (which query parameter a ``ValueError`` names, a study id
that names no study) stays with its route. The store's refusals (503) are
:mod:`isolab.service.api.unavailable`.
"""

from __future__ import annotations

from fastapi import FastAPI, Request
from fastapi.responses import JSONResponse

from isolab.studies.answers.history import CaseNotFound
from isolab.studies.authoring.authoring import ExampleNotFound
from isolab.studies.inputs.definitions import DefinitionError, detail
from isolab.studies.results.cases import CaseQueryError


async def definition_refused(request: Request, exc: DefinitionError) -> JSONResponse:
    """Exception handler: a refused definition as 422 with one detail per problem."""
    return JSONResponse(status_code=422, content={"detail": exc.details})


async def case_query_refused(request: Request, exc: CaseQueryError) -> JSONResponse:
    """Exception handler: a wrong case query as 422 naming the parameter and where it was given."""
    return JSONResponse(status_code=422, content={"detail": [detail([exc.where, exc.param], str(exc))]})


async def not_found(request: Request, exc: CaseNotFound | ExampleNotFound) -> JSONResponse:
    """Exception handler: a case or an example that does not exist as 404 with the message."""
    return JSONResponse(status_code=404, content={"detail": str(exc)})


def add_domain_error_handlers(app: FastAPI) -> None:
    """Answer the studies layer's refusals on every route of ``app`` (see above)."""
    # the handlers take their own error (Starlette types a handler's parameter as any Exception)
    app.add_exception_handler(DefinitionError, definition_refused)  # type: ignore[arg-type]
    app.add_exception_handler(CaseQueryError, case_query_refused)  # type: ignore[arg-type]
    app.add_exception_handler(CaseNotFound, not_found)  # type: ignore[arg-type]
    app.add_exception_handler(ExampleNotFound, not_found)  # type: ignore[arg-type]
