"""FastAPI application factory of the isolab service.

``create_app()`` builds the app; its lifespan opens one Dask client for the app's whole life (joining
``DASK_SCHEDULER_ADDRESS`` when set, else starting a LocalCluster of worker processes) and starts the
study queue, which resumes unfinished studies (the study store opens when first needed); on shutdown it
stops the queue (running studies stay queued for the next start) and closes the client. Start it with
``isolab serve``, which hands the app to uvicorn.

When ``ISOLAB_API_TOKEN`` is set, every route but ``/health`` wants ``Authorization: Bearer <token>``;
request bodies larger than ``ISOLAB_MAX_BODY_BYTES`` are refused with 413.
"""

from __future__ import annotations

import hmac
import logging
import socket
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from importlib.metadata import PackageNotFoundError, version

from anyio import to_thread
from distributed import Client, LocalCluster
from fastapi import Depends, FastAPI, HTTPException, Request
from fastapi.middleware.cors import CORSMiddleware
from fastapi.responses import JSONResponse
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from service.jobs import JobQueue
from service.routes import comparisons, health, studies
from service.settings import Settings, load_settings

#: Port of the Dask dashboard of the in-process LocalCluster, when free.
DASHBOARD_PORT = 8787

log = logging.getLogger(__name__)


def service_version() -> str:
    """Installed version of the isolab package."""
    try:
        return version("isolab")
    except PackageNotFoundError:
        return "0+unknown"


def free_dashboard_address(port: int = DASHBOARD_PORT) -> str | None:
    """``":<port>"`` when that TCP port can be bound on all interfaces, else ``None`` (no dashboard)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind(("", port))
        except OSError:
            return None
    return f":{port}"


def start_dask(settings: Settings) -> tuple[Client, LocalCluster | None]:
    """Open the Dask client the service runs on.

    Returns the client and the LocalCluster it owns (``None`` when joining an external scheduler).
    """
    if settings.scheduler_address is not None:
        log.info("joining Dask scheduler at %s", settings.scheduler_address)
        return Client(settings.scheduler_address), None
    cluster = LocalCluster(
        n_workers=settings.workers,
        threads_per_worker=1,
        processes=True,
        dashboard_address=free_dashboard_address(),
        silence_logs=logging.WARNING,
    )
    try:
        client = Client(cluster)
    except BaseException:
        cluster.close()
        raise
    log.info("started LocalCluster with %d workers at %s", settings.workers, cluster.scheduler_address)
    return client, cluster


def stop_dask(client: Client, cluster: LocalCluster | None) -> None:
    """Close the client, then the LocalCluster it owns (an external scheduler is left running)."""
    try:
        client.close()
    finally:
        if cluster is not None:
            cluster.close()


def require_token(
    request: Request,
    credentials: HTTPAuthorizationCredentials | None = Depends(HTTPBearer(auto_error=False)),
) -> None:
    """FastAPI dependency: when the app has an API token, the request must carry it as a bearer token."""
    token = request.app.state.settings.api_token
    if token is None:
        return
    given = credentials.credentials if credentials is not None else ""
    if not hmac.compare_digest(given.encode(), token.encode()):
        raise HTTPException(status_code=401, detail="missing or wrong bearer token",
                            headers={"WWW-Authenticate": "Bearer"})


class BodyLimit:
    """ASGI middleware: refuse request bodies larger than ``max_bytes`` with 413 (by Content-Length up
    front, or while a body without one streams in)."""

    def __init__(self, app: ASGIApp, max_bytes: int):
        self.app = app
        self.max_bytes = int(max_bytes)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        length = dict(scope.get("headers") or []).get(b"content-length")
        if length is not None and length.isdigit() and int(length) > self.max_bytes:
            await self._refuse(scope, receive, send)
            return
        seen = 0

        async def limited() -> Message:
            nonlocal seen
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > self.max_bytes:
                    raise _TooLarge
            return message

        try:
            await self.app(scope, limited, send)
        except _TooLarge:
            await self._refuse(scope, receive, send)

    async def _refuse(self, scope: Scope, receive: Receive, send: Send) -> None:
        response = JSONResponse(
            {"detail": f"request body larger than {self.max_bytes} bytes (ISOLAB_MAX_BODY_BYTES)"},
            status_code=413,
        )
        await response(scope, receive, send)


class _TooLarge(Exception):
    pass


def create_app(settings: Settings | None = None) -> FastAPI:
    """Build the isolab FastAPI app.

    Args:
        settings: service settings; ``None`` reads them from the environment (:func:`load_settings`).

    The Dask client is available as ``app.state.dask`` (and through the
    :func:`service.routes.dask_client` dependency) while the app's lifespan runs, the study store as
    ``app.state.jobs.store`` and the study queue as ``app.state.jobs``.
    """
    settings = settings if settings is not None else load_settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        settings.data_dir.mkdir(parents=True, exist_ok=True)
        client, cluster = await to_thread.run_sync(start_dask, settings)
        app.state.dask = client
        app.state.dask_cluster = cluster
        jobs: JobQueue | None = None
        try:
            jobs = JobQueue(settings.data_dir, client)  # the store opens when first needed
            await to_thread.run_sync(jobs.start)
            app.state.jobs = jobs
            yield
        finally:
            app.state.jobs = None
            if jobs is not None:
                await to_thread.run_sync(jobs.stop)
            app.state.dask = None
            app.state.dask_cluster = None
            await to_thread.run_sync(stop_dask, client, cluster)

    app = FastAPI(
        title="isolab",
        summary="Batch design-of-experiments service for machines on vibration isolators",
        version=service_version(),
        lifespan=lifespan,
    )
    app.state.settings = settings
    app.state.dask = None
    app.state.dask_cluster = None
    app.state.jobs = None
    app.add_middleware(BodyLimit, max_bytes=settings.max_body_bytes)
    if settings.cors_origins:
        app.add_middleware(
            CORSMiddleware,
            allow_origins=list(settings.cors_origins),
            allow_methods=["*"],
            allow_headers=["*"],
        )
    app.include_router(health.router)
    guarded = [Depends(require_token)]
    app.include_router(studies.router, dependencies=guarded)
    app.include_router(comparisons.router, dependencies=guarded)
    return app
