"""HTTP routers of the isolab service and the dependencies they share.

Each module in this package defines one ``router = APIRouter(...)``; :func:`service.app.create_app`
includes them. Handlers reach the application's state through the dependencies below.
"""

from __future__ import annotations

from distributed import Client
from fastapi import Request

from service.settings import Settings


def app_settings(request: Request) -> Settings:
    """FastAPI dependency: the :class:`~service.settings.Settings` the app was created with."""
    return request.app.state.settings


def dask_client(request: Request) -> Client:
    """FastAPI dependency: the app's Dask client (one per app, opened by its lifespan)."""
    client = getattr(request.app.state, "dask", None)
    if client is None:
        raise RuntimeError(
            "the Dask client is not running: serve the app made by create_app() with its lifespan"
        )
    return client
