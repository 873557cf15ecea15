"""FastAPI application factory of the isolab service.

``create_app()`` builds the app; its lifespan opens one Dask client for the app's whole life (joining
``DASK_SCHEDULER_ADDRESS`` when set, else starting a LocalCluster of worker processes) and closes it on
shutdown. Start it with ``isolab serve``, which hands the app to uvicorn.
"""

from __future__ import annotations

import logging
import socket
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from importlib.metadata import PackageNotFoundError, version

from anyio import to_thread
from distributed import Client, LocalCluster
from fastapi import FastAPI
from fastapi.middleware.cors import CORSMiddleware

from service.routes import health
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


def create_app(settings: Settings | None = None) -> FastAPI:
    """Build the isolab FastAPI app.

    Args:
        settings: service settings; ``None`` reads them from the environment (:func:`load_settings`).

    The Dask client is available as ``app.state.dask`` (and through the
    :func:`service.routes.dask_client` dependency) while the app's lifespan runs.
    """
    settings = settings if settings is not None else load_settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        settings.data_dir.mkdir(parents=True, exist_ok=True)
        client, cluster = await to_thread.run_sync(start_dask, settings)
        app.state.dask = client
        app.state.dask_cluster = cluster
        try:
            yield
        finally:
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
    if settings.cors_origins:
        app.add_middleware(
            CORSMiddleware,
            allow_origins=list(settings.cors_origins),
            allow_methods=["*"],
            allow_headers=["*"],
        )
    app.include_router(health.router)
    return app
