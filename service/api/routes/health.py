"""``GET /health``: is the service able to take work (store writable, Dask workers present)?"""

from __future__ import annotations

import hmac
from pathlib import Path
from typing import Any, Literal

from distributed import Client
from fastapi import APIRouter, Request, Response
from fastapi.security.utils import get_authorization_scheme_param
from pydantic import BaseModel, Field

from isolab.service.api.routes import DaskIfRunningDep, SettingsDep
from isolab.studies.results.store import check_writable

#: Longest wait for the Dask scheduler to answer the health probe, in seconds.
SCHEDULER_TIMEOUT_S = 5.0

router = APIRouter(tags=["health"])


class ServiceInfo(BaseModel):
    version: str


class StoreHealth(BaseModel):
    path: str = Field(description="absolute path of the study store directory")
    writable: bool = Field(description="a file could be created and removed in the store directory")
    error: str | None = None


class WorkerInfo(BaseModel):
    address: str
    nthreads: int
    memory_limit: int | None = Field(description="worker memory limit in bytes; null when unlimited")


class DaskHealth(BaseModel):
    scheduler: str | None = Field(description="address of the Dask scheduler")
    workers: list[WorkerInfo]
    n_workers: int
    error: str | None = None


class HealthStatus(BaseModel):
    """What ``/health`` answers a request without the API token when one is set: the status only."""

    status: Literal["ok", "degraded"]


class HealthReport(HealthStatus):
    service: ServiceInfo
    store: StoreHealth
    dask: DaskHealth


def probe_store(path: Path) -> StoreHealth:
    """Check that the store directory exists and takes writes (64 kB, and room for its reserve)."""
    resolved = path.resolve()
    error = check_writable(resolved)  # writes and syncs 64 kB; a full disk is not writable
    return StoreHealth(path=str(resolved), writable=error is None, error=error)


def probe_dask(client: Client | None, timeout_s: float = SCHEDULER_TIMEOUT_S) -> DaskHealth:
    """Ask the scheduler for its current workers, waiting at most ``timeout_s`` seconds."""
    if client is None:
        return DaskHealth(scheduler=None, workers=[], n_workers=0, error="no Dask client")
    try:
        scheduler: Any = client.scheduler  # an rpc while the client is connected
        identity = client.sync(scheduler.identity, n_workers=-1, callback_timeout=timeout_s)
    except Exception as exc:  # any failure to reach the scheduler makes the service degraded
        address = getattr(client.scheduler, "address", None)
        return DaskHealth(scheduler=address, workers=[], n_workers=0, error=f"{type(exc).__name__}: {exc}")
    workers = [
        WorkerInfo(
            address=address, nthreads=info.get("nthreads", 0), memory_limit=info.get("memory_limit") or None
        )
        for address, info in sorted(identity.get("workers", {}).items())
    ]
    return DaskHealth(scheduler=identity.get("address"), workers=workers, n_workers=len(workers))


def has_token(request: Request, token: str | None) -> bool:
    """Whether the request carries the API token as a bearer token (always, when no token is set)."""
    if token is None:
        return True
    scheme, given = get_authorization_scheme_param(request.headers.get("Authorization"))
    return scheme.lower() == "bearer" and hmac.compare_digest(given.encode(), token.encode())


@router.get(
    "/health",
    response_model=HealthReport | HealthStatus,
    responses={
        503: {
            "model": HealthReport | HealthStatus,
            "description": "no Dask worker or the store is not writable",
        }
    },
)
def health(
    request: Request, response: Response, settings: SettingsDep, dask_client: DaskIfRunningDep
) -> HealthReport | HealthStatus:
    """Report the service version, the store and the Dask cluster; 503 when the service cannot work.
    With an API token set, a request without it gets the status only (no paths, no addresses)."""
    store = probe_store(settings.data_dir)
    dask = probe_dask(dask_client)
    healthy = store.writable and dask.n_workers > 0
    if not healthy:
        response.status_code = 503
    if not has_token(request, settings.api_token):
        return HealthStatus(status="ok" if healthy else "degraded")
    return HealthReport(
        status="ok" if healthy else "degraded",
        service=ServiceInfo(version=request.app.version),
        store=store,
        dask=dask,
    )
