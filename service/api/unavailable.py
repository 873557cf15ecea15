"""The store cannot be used just now (a full disk, an I/O error): ``503`` with the reason, never ``500``.

A catalog read or write that SQLite refuses (:class:`~isolab.studies.results.catalog.CatalogUnavailable`) or a
study file that cannot be written for want of space (:class:`~isolab.studies.results.store.StoreFull`) becomes
``503 {"detail": "<why>"}`` with ``Retry-After``; ``/health`` says the store is degraded meanwhile.
"""

from __future__ import annotations

import logging

from fastapi import FastAPI, Request
from fastapi.responses import JSONResponse

from isolab.studies.results.catalog import CatalogUnavailable
from isolab.studies.results.store import StoreFull

RETRY_AFTER_S = 30

log = logging.getLogger(__name__)


async def store_unavailable(request: Request, exc: Exception) -> JSONResponse:
    """Exception handler: the store's refusal as a 503 naming the cause."""
    log.warning("%s %s: store unavailable: %s", request.method, request.url.path, exc)
    return JSONResponse(
        status_code=503,
        content={"detail": f"the study store is unavailable: {exc}"},
        headers={"Retry-After": str(RETRY_AFTER_S)},
    )


def add_store_handlers(app: FastAPI) -> None:
    """Answer the store's refusals with 503 on every route of ``app``."""
    app.add_exception_handler(CatalogUnavailable, store_unavailable)
    app.add_exception_handler(StoreFull, store_unavailable)
