"""``GET /health``: is the service able to take work (store writable, Dask workers present)?"""

from __future__ import annotations

import contextlib
import hmac
import os
import shutil
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from fastapi import APIRouter, Request, Response
from fastapi.security.utils import get_authorization_scheme_param
from pydantic import BaseModel, Field

from isolab.service.api.routes import DaskIfRunningDep, KernelsDep, SettingsDep
from isolab.studies.results.store import check_writable

if TYPE_CHECKING:  # Dask is imported when the service starts
    from distributed import Client

#: Longest wait for the Dask scheduler to answer the health probe, in seconds.
SCHEDULER_TIMEOUT_S = 5.0
#: The store's next write when no study has saved a chunk yet: about one chunk of a study, bytes.
TYPICAL_CHUNK_BYTES = 2 * 1024 * 1024
MB = 1024 * 1024

router = APIRouter(tags=["health"])


class ServiceInfo(BaseModel):
    version: str


class StoreHealth(BaseModel):
    path: str = Field(description="absolute path of the study store directory")
    writable: bool = Field(
        description="a file could be created and removed in the store directory, and the free space holds "
        "the next write"
    )
    free_bytes: int | None = Field(None, description="free space of the store's file system, bytes")
    next_write_bytes: int | None = Field(
        None, description="estimate of the store's next write (the largest chunk a study saved), bytes"
    )
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


class KernelHealth(BaseModel):
    """The engine's compiled kernels on the workers: loaded (or, on a fresh machine, compiled once) in the
    background when the service starts; studies submitted meanwhile wait for them."""

    state: Literal["starting", "compiling", "loading", "ready", "failed", "off"] = Field(
        description="starting: not looked at yet; compiling: not in the kernel cache, compiling on the "
        "workers "
        "(first start only, a minute or two); loading: cached, the workers load them (seconds); ready; "
        "failed or off (no warm-up): each study compiles what it needs itself"
    )
    pairs: list[str] = Field(description="fidelity/integrator pairs warmed (the examples' and the reference)")
    seconds: float | None = Field(description="seconds since the warm-up started, or that it took once over")
    error: str | None = Field(None, description="why the warm-up failed")
    note: str | None = Field(None, description="what the web page shows meanwhile; null once ready")


class HealthStatus(BaseModel):
    """What ``/health`` answers a request without the API token when one is set: the status only."""

    status: Literal["ok", "degraded"]


class HealthReport(HealthStatus):
    service: ServiceInfo
    store: StoreHealth
    dask: DaskHealth
    kernels: KernelHealth | None = Field(
        None, description="the engine's kernels on the workers (null while the service is not running)"
    )


def next_write_bytes(root: Path) -> int:
    """Estimate of the store's next write, bytes: the largest chunk a study has saved and not yet
    assembled (its next chunk is about as large), else :data:`TYPICAL_CHUNK_BYTES`.

    Studies finish while it looks: a chunk folder or file that goes meanwhile (its study was assembled)
    is passed over, never an error of ``/health``."""
    sizes = []
    try:
        with os.scandir(root / "studies") as entries:
            folders = [entry.path for entry in entries if entry.name.endswith(".chunks")]
    except OSError:  # no store yet
        folders = []
    for folder in folders:
        try:
            with os.scandir(folder) as files:
                chunks = [file for file in files if file.name.endswith(".npz")]
        except OSError:  # the study was assembled and its chunks removed
            continue
        for chunk in chunks:
            with contextlib.suppress(OSError):
                sizes.append(chunk.stat().st_size)
    return max(sizes, default=TYPICAL_CHUNK_BYTES)


def probe_store(path: Path) -> StoreHealth:
    """Check that the store directory exists and takes writes (64 kB, and room for its reserve), and that
    its free space holds the next write."""
    resolved = path.resolve()
    error = check_writable(resolved)  # writes and syncs 64 kB; a full disk is not writable
    try:
        free: int | None = int(shutil.disk_usage(resolved).free)
    except OSError:
        free = None
    needed = next_write_bytes(resolved) if free is not None else None
    if error is None and free is not None and needed is not None and free < needed:
        error = (
            f"no space left on device for the next write: {free / MB:.2f} MB free in {resolved}, a chunk "
            f"needs about {needed / MB:.2f} MB"
        )
    return StoreHealth(
        path=str(resolved), writable=error is None, free_bytes=free, next_write_bytes=needed, error=error
    )


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
    request: Request,
    response: Response,
    settings: SettingsDep,
    dask_client: DaskIfRunningDep,
    kernels: KernelsDep,
) -> HealthReport | HealthStatus:
    """Report the service version, the store, the Dask cluster and the engine's kernels on its workers
    (still 200 while they compile); 503 when the service cannot work.
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
        kernels=KernelHealth.model_validate(kernels.report()) if kernels is not None else None,
    )
