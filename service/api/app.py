"""FastAPI application factory of the isolab service.

``create_app()`` builds the app; its lifespan opens one Dask client for the app's whole life (joining
``DASK_SCHEDULER_ADDRESS`` when set, else starting a LocalCluster of worker processes) and starts the
study queue, which resumes unfinished studies (the study store opens when first needed); on shutdown it
stops the queue (running studies stay queued for the next start) and closes the client. Start it with
``isolab serve``, which hands the app to uvicorn.

When ``ISOLAB_API_TOKEN`` is set, every route but ``/health`` (and the API description: ``/docs``,
``/redoc``, ``/openapi.json``; the file schemas ``/schemas/*.json``) wants ``Authorization: Bearer
<token>``; request bodies larger than ``ISOLAB_MAX_BODY_BYTES`` are refused with 413 before they are
read, JSON nested too deep with 422 (:class:`service.request_limits.RequestLimits`). CORS answers only the
origins of ``ISOLAB_CORS_ORIGINS``. The web page (``/ui/``, :mod:`service.routes.ui`) is static: its
shells and assets need no token, and all its data comes from the API above, with the token.
"""

from __future__ import annotations

import hmac
import logging
import socket
import sys
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import TYPE_CHECKING

from anyio import to_thread
from fastapi import Depends, FastAPI, HTTPException, Request
from fastapi.exceptions import RequestValidationError
from fastapi.middleware.cors import CORSMiddleware
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from starlette.exceptions import HTTPException as StarletteHTTPException

from isolab.service.api.errors import add_domain_error_handlers
from isolab.service.api.jobs import RUNNING_STUDIES, JobQueue
from isolab.service.api.kernel_warmup import KernelWarmup
from isolab.service.api.openapi import describe_settings
from isolab.service.api.request_limits import RequestLimits, unreadable_body_is_422, validation_errors_as_json
from isolab.service.api.routes import (
    authoring,
    calibrations,
    cases,
    comparisons,
    file_schemas,
    health,
    heavy_work_limiter,
    sensitivity,
    studies,
    ui,
)
from isolab.service.api.unavailable import add_store_handlers
from isolab.service.settings import Settings, load_settings
from isolab.studies.answers.calibration.jobs import CalibrationJobs
from isolab.studies.results.calibrations import CalibrationStore
from isolab.studies.results.store import StoreLock
from isolab.studies.run.fanout import LOOPBACK, local_cluster

if TYPE_CHECKING:  # Dask is imported when the service starts: `isolab serve` answers sooner
    from distributed import Client, LocalCluster

#: Tasks the LocalCluster's scheduler gives a worker per thread: 1.0, none waiting in a worker's own queue.
WORKER_SATURATION = 1.0
#: Seconds a thread may hold the interpreter lock while another waits (Python's default is 0.005).
SWITCH_INTERVAL_S = 0.001

log = logging.getLogger(__name__)


def service_version() -> str:
    """Installed version of the isolab package."""
    from isolab.studies import __version__

    return __version__


def free_dashboard_address(port: int | None) -> str | None:
    """``"127.0.0.1:<port>"`` when the dashboard is asked for (``port``, the setting
    ``ISOLAB_DASHBOARD_PORT``) and that TCP port can be bound on the loopback interface, else ``None``
    (no dashboard; a port in use is logged, not taken over by another port)."""
    if port is None:
        return None
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((LOOPBACK, port))
        except OSError:
            log.info("no Dask dashboard: port %d of %s is in use", port, LOOPBACK)
            return None
    return f"{LOOPBACK}:{port}"


def service_cluster(workers: int, dashboard_address: str | None = None) -> LocalCluster:
    """The LocalCluster the service starts when it joins no scheduler: ``workers`` processes of one thread,
    on loopback (:func:`isolab.studies.run.fanout.local_cluster`). A worker holds only the chunk it runs
    (:data:`WORKER_SATURATION`): the next one is picked when it is free, by priority, so a study submitted
    while a large one runs waits for one chunk (see studies.run.fanout), not for two."""
    return local_cluster(
        workers, dashboard_address, **{"distributed.scheduler.worker-saturation": WORKER_SATURATION}
    )


def start_dask(settings: Settings) -> tuple[Client, LocalCluster | None]:
    """Open the Dask client the service runs on.

    Returns the client and the LocalCluster it owns (``None`` when joining an external scheduler).
    """
    from distributed import Client

    from isolab.service.api.worker_priority import LowerPriority

    if settings.scheduler_address is not None:
        log.info("joining Dask scheduler at %s", settings.scheduler_address)
        return Client(settings.scheduler_address), None
    cluster = service_cluster(settings.workers, free_dashboard_address(settings.dashboard_port))
    try:
        client = Client(cluster)
        # the workers share this machine's cores with the API: the API answers first (see worker_priority)
        client.register_plugin(LowerPriority())
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


async def require_token(
    request: Request,
    credentials: HTTPAuthorizationCredentials | None = Depends(HTTPBearer(auto_error=False)),
) -> None:
    """FastAPI dependency: when the app has an API token, the request must carry it as a bearer token."""
    token = request.app.state.settings.api_token
    if token is None:
        return
    given = credentials.credentials if credentials is not None else ""
    if not hmac.compare_digest(given.encode(), token.encode()):
        raise HTTPException(
            status_code=401, detail="missing or wrong bearer token", headers={"WWW-Authenticate": "Bearer"}
        )


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
        # one service per data directory: a second one refuses to start (StoreInUse) instead of running
        # the same studies twice; the kernel drops the lock when this process ends, however it ends
        store_lock = StoreLock(settings.data_dir).acquire()
        try:
            client, cluster = await to_thread.run_sync(start_dask, settings)
        except BaseException:
            store_lock.release()
            raise
        app.state.dask = client
        app.state.dask_cluster = cluster
        # the workers load (on a fresh machine: compile, once) the kernels in the background
        kernels = KernelWarmup()
        kernels.start(client)
        app.state.kernels = kernels
        jobs: JobQueue | None = None
        # threads finishing studies, validating submissions and running the Dask scheduler hold the
        # interpreter lock for long stretches: hand it on sooner, so that a status request waits less
        switch_interval = sys.getswitchinterval()
        sys.setswitchinterval(min(switch_interval, SWITCH_INTERVAL_S))
        try:
            jobs = JobQueue(settings.data_dir, client, concurrency=RUNNING_STUDIES)  # store opens when needed
            await to_thread.run_sync(jobs.start)
            app.state.jobs = jobs
            # calibrations are jobs too, fitted on the workers; a stopped service's resume here
            calibration_jobs = CalibrationJobs(
                CalibrationStore(settings.data_dir), client, draw=calibrations.draw_calibration
            )
            await to_thread.run_sync(calibration_jobs.start)
            app.state.calibrations = calibration_jobs
            yield
        finally:
            app.state.jobs = None
            if app.state.calibrations is not None:
                await to_thread.run_sync(app.state.calibrations.stop)
                app.state.calibrations = None
            if jobs is not None:
                await to_thread.run_sync(jobs.stop)
            await to_thread.run_sync(kernels.stop)
            app.state.dask = None
            app.state.dask_cluster = None
            await to_thread.run_sync(stop_dask, client, cluster)
            sys.setswitchinterval(switch_interval)
            store_lock.release()

    app = FastAPI(
        title="isolab",
        summary="Batch design-of-experiments service for machines on vibration isolators",
        version=service_version(),
        lifespan=lifespan,
        docs_url=None,  # /docs and /redoc are served by routes.ui with local assets (no CDN)
        redoc_url=None,
    )
    app.state.settings = settings
    app.state.dask = None
    app.state.dask_cluster = None
    app.state.jobs = None
    app.state.calibrations = None
    app.state.kernels = None
    app.state.heavy_work = heavy_work_limiter()
    app.add_middleware(RequestLimits, max_bytes=settings.max_body_bytes)
    add_store_handlers(app)  # a full disk or a catalog SQLite refuses: 503 with the reason
    add_domain_error_handlers(app)  # a refused definition or case query: 422; no such case or example: 404
    app.add_exception_handler(StarletteHTTPException, unreadable_body_is_422)  # type: ignore[arg-type]
    app.add_exception_handler(RequestValidationError, validation_errors_as_json)  # type: ignore[arg-type]
    if settings.cors_origins:
        app.add_middleware(
            CORSMiddleware,
            allow_origins=list(settings.cors_origins),
            allow_methods=["*"],
            allow_headers=["*"],
        )
    app.include_router(health.router)
    app.include_router(file_schemas.router)  # describes files, holds no data: open, like /openapi.json
    guarded = [Depends(require_token)]
    app.include_router(studies.router, dependencies=guarded)
    app.include_router(cases.router, dependencies=guarded)
    app.include_router(sensitivity.router, dependencies=guarded)
    app.include_router(comparisons.router, dependencies=guarded)
    app.include_router(calibrations.router, dependencies=guarded)
    app.include_router(authoring.router, dependencies=guarded)
    ui.add_ui(app)  # the web page's shells and assets (no data: every datum comes from the guarded API)
    describe_settings(app, settings)  # /openapi.json: the token's 401 and security only when one is set
    return app
