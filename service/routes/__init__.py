"""HTTP routers of the isolab service and the dependencies they share.

Each module in this package defines one ``router = APIRouter(...)``; :func:`service.app.create_app`
includes them. Handlers reach the application's state through the dependencies below.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any, TypeVar

from anyio import CapacityLimiter, to_thread
from distributed import Client
from fastapi import Request

from isolab.service.settings import Settings

T = TypeVar("T")

HEAVY_REQUESTS = 2
"""Requests that compute (validate a study, run the engine, draw a figure) at the same time; more wait
their turn without holding a thread. CPU-bound threads of one process share one interpreter lock: capping
them keeps the quick requests (a study's status) quick while heavy ones run."""


def heavy_work_limiter() -> CapacityLimiter:
    """A fresh limiter of :data:`HEAVY_REQUESTS` (one per app: ``app.state.heavy_work``)."""
    return CapacityLimiter(HEAVY_REQUESTS)


async def run_heavy(request: Request, func: Callable[..., T], *args: Any, **kwargs: Any) -> T:
    """Run ``func(*args, **kwargs)`` in a worker thread, at most :data:`HEAVY_REQUESTS` at once per app."""
    limiter = getattr(request.app.state, "heavy_work", None)
    return await to_thread.run_sync(functools.partial(func, *args, **kwargs), limiter=limiter)


async def app_settings(request: Request) -> Settings:
    """FastAPI dependency: the :class:`~service.settings.Settings` the app was created with."""
    return request.app.state.settings


async def dask_client(request: Request) -> Client:
    """FastAPI dependency: the app's Dask client (one per app, opened by its lifespan)."""
    client = getattr(request.app.state, "dask", None)
    if client is None:
        raise RuntimeError(
            "the Dask client is not running: serve the app made by create_app() with its lifespan"
        )
    return client
