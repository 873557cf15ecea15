"""HTTP routers of the isolab service and the dependencies they share.

Each module in this package defines one ``router = APIRouter(...)``; :func:`service.app.create_app`
includes them. Handlers reach the application's state through the typed dependencies below
(``store: StoreDep``, ``settings: SettingsDep``, ``jobs: JobsDep``...), never through ``request.app.state``.
The studies layer's refusals (a definition, a case query) are answered by :mod:`isolab.service.api.errors`:
handlers let them rise.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import TYPE_CHECKING, Annotated, Any, TypeVar

from anyio import CapacityLimiter, to_thread
from fastapi import Depends, HTTPException, Request

from isolab.service.api.jobs import JobQueue
from isolab.service.api.kernel_warmup import KernelWarmup
from isolab.service.api.schemas import MessageBody, ValidationErrorBody
from isolab.service.settings import Settings
from isolab.studies.results.store import Store, StudyNotFound, StudyRecord

if TYPE_CHECKING:  # Dask is imported when the service starts: `isolab serve` answers sooner
    from distributed import Client

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


async def dask_client_if_running(request: Request) -> Client | None:
    """FastAPI dependency: the app's Dask client, or None while the app's lifespan does not run."""
    return getattr(request.app.state, "dask", None)


async def dask_client(request: Request) -> Client:
    """FastAPI dependency: the app's Dask client (one per app, opened by its lifespan)."""
    client = await dask_client_if_running(request)
    if client is None:
        raise RuntimeError(
            "the Dask client is not running: serve the app made by create_app() with its lifespan"
        )
    return client


async def kernel_warmup(request: Request) -> KernelWarmup | None:
    """FastAPI dependency: the warm-up of the engine's kernels on the workers, or None while the app's
    lifespan does not run."""
    return getattr(request.app.state, "kernels", None)


async def study_store(request: Request) -> Store:
    """FastAPI dependency: the app's study store (the job queue's; opened on first use)."""
    return _jobs(request).store


async def job_queue(request: Request) -> JobQueue:
    """FastAPI dependency: the app's study queue (started by the lifespan)."""
    return _jobs(request)


# The dependencies are coroutines: they only read app state, and a plain function would cost every
# request a round trip through the thread pool.
def _jobs(request: Request) -> JobQueue:
    jobs = getattr(request.app.state, "jobs", None)
    if jobs is None:
        raise RuntimeError(
            "the job queue is not running: serve the app made by create_app() with its lifespan"
        )
    return jobs


SettingsDep = Annotated[Settings, Depends(app_settings)]
"""A handler's parameter: the app's settings."""
StoreDep = Annotated[Store, Depends(study_store)]
"""A handler's parameter: the app's study store."""
JobsDep = Annotated[JobQueue, Depends(job_queue)]
"""A handler's parameter: the app's study queue."""
if TYPE_CHECKING:
    DaskDep = Annotated[Client, Depends(dask_client)]
    DaskIfRunningDep = Annotated[Client | None, Depends(dask_client_if_running)]
else:  # FastAPI reads only the dependency; the type stays a name until Dask is imported
    DaskDep = Annotated[Any, Depends(dask_client)]
    DaskIfRunningDep = Annotated[Any, Depends(dask_client_if_running)]
"""``DaskDep``, a handler's parameter: the app's Dask client (500 when the app runs without its lifespan);
``DaskIfRunningDep``: the app's Dask client, or None (what ``/health`` reports on)."""
KernelsDep = Annotated[KernelWarmup | None, Depends(kernel_warmup)]
"""A handler's parameter: the warm-up of the engine's kernels (None without the app's lifespan)."""


# ------------------------------------------------------------------------------------ HTTP answers
Responses = dict[int | str, dict[str, Any]]
NOT_FOUND: Responses = {
    404: {"model": MessageBody, "description": "no study with this id (or a malformed id)"}
}
NOT_DONE: Responses = {409: {"model": MessageBody, "description": "the study is not done yet"}}
INVALID: Responses = {
    422: {"model": ValidationErrorBody, "description": "invalid input; `loc` names the field"}
}
PNG: Responses = {200: {"content": {"image/png": {}}, "description": "a PNG image"}}


def invalid(loc: list[str | int], msg: str, kind: str = "value_error") -> HTTPException:
    """A 422 with FastAPI's error shape: ``{"detail": [{"loc": [...], "msg": ..., "type": ...}]}``."""
    return HTTPException(status_code=422, detail=[{"loc": loc, "msg": msg, "type": kind}])


def study_row(store: Store, study_id: str) -> StudyRecord:
    """The catalog record of a study; 404 when there is none (or the id is malformed)."""
    try:
        return store.get(study_id)
    except (StudyNotFound, ValueError):
        raise HTTPException(status_code=404, detail=f"no study with id {study_id!r}") from None


def require_done(row: StudyRecord) -> None:
    """409 unless the study is done, saying where it is."""
    if row["status"] != "done":
        detail = f"study {row['id']} is {row['status']}"
        if row["status"] in ("queued", "running"):
            detail += f" ({row['n_done']} of {row['n_cases']} cases done)"
        elif row.get("error"):
            detail += f": {row['error']}"
        raise HTTPException(status_code=409, detail=detail + "; its results exist once it is done")
