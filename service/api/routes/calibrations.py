"""``/calibrations``: fit a scene's parameters to measured motion, as a job on the Dask workers.

``POST /calibrations`` checks the request and estimates its engine time at once (a refusal or an estimate
above the limit: 422 naming the field), stores it and answers 202 with its id; the fit runs on a Dask
worker (:mod:`isolab.studies.answers.calibration.jobs`), never in the API's process. ``GET
/calibrations/{id}`` answers where it is, its progress and, once done, the answer (with a base64 PNG in
``plot_png`` when the request asked for it, drawn on the worker by :mod:`isolab.service.plots.calibration`).
``DELETE /calibrations/{id}`` stops the fit (its worker stops at its next engine batch) and removes the job:
every route then answers 404 for it.
"""

from __future__ import annotations

from typing import Annotated, Any

from anyio import to_thread
from fastapi import APIRouter, Body, Depends, HTTPException, Request, Response

from isolab.service.api.request_limits import JsonParsedOffLoop
from isolab.service.api.routes import INVALID, Responses, run_heavy
from isolab.service.api.schemas import (
    EXAMPLE_CALIBRATION,
    CalibrationJob,
    CalibrationRequest,
    MessageBody,
)
from isolab.service.plots.calibration import calibration_notes, calibration_png
from isolab.studies.answers.calibration.jobs import CalibrationJobs, price_request
from isolab.studies.results.calibrations import CalibrationNotFound

router = APIRouter(prefix="/calibrations", tags=["calibrations"], route_class=JsonParsedOffLoop)

NO_CALIBRATION: Responses = {
    404: {"model": MessageBody, "description": "no calibration with this id (or a malformed id)"}
}
NOT_RUNNING: Responses = {
    503: {"model": MessageBody, "description": "the service's workers are not running; try again later"}
}


def draw_calibration(traces: dict[str, Any], answer: dict[str, Any]) -> bytes:
    """The PNG of a calibration's traces (drawn on the worker that fitted it)."""
    return calibration_png(traces, "calibration", calibration_notes(answer))


async def calibration_jobs(request: Request) -> CalibrationJobs:
    """FastAPI dependency: the app's calibration jobs (started by the lifespan); 503 without them."""
    jobs = getattr(request.app.state, "calibrations", None)
    if jobs is None:
        raise HTTPException(status_code=503, detail="calibrations run on the service's workers: not running")
    return jobs


CalibrationsDep = Annotated[CalibrationJobs, Depends(calibration_jobs)]
"""A handler's parameter: the app's calibration jobs."""


def job_body(jobs: CalibrationJobs, job_id: str) -> CalibrationJob:
    """The job's answer body; 404 when there is none."""
    try:
        job = jobs.store.get(job_id)
        result = jobs.store.result(job_id) if job["status"] == "done" else None
    except CalibrationNotFound as err:
        raise HTTPException(status_code=404, detail=str(err)) from None
    progress = dict(job["progress"])
    estimated = max(int(job["estimate"]["cases"]), 1)
    done = job["status"] == "done"
    progress["fraction"] = 1.0 if done else min(0.99, progress.get("cases", 0) / estimated)
    return CalibrationJob.model_validate({**job, "progress": progress, "result": result})


@router.post(
    "",
    status_code=202,
    response_model=CalibrationJob,
    responses={**INVALID, **NOT_RUNNING},
    summary="Calibrate a scene against measured motion (a job)",
)
async def calibrate(
    http: Request,
    jobs: CalibrationsDep,
    request: CalibrationRequest = Body(
        openapi_examples={
            "laser tracker": {
                "summary": "the mounts' horizontal frequency from a Y trace of the c.g. at 20 Hz",
                "value": EXAMPLE_CALIBRATION,
            },
        }
    ),
) -> CalibrationJob:
    """Check the request and estimate its engine time (422 naming the field when it is refused or the
    estimate exceeds ``estimate.limit_seconds``), then fit on the workers: poll ``GET
    /calibrations/{id}``. The fit finds the parameters named in ``fit`` (and the measurement's time offset)
    so that the scene's simulated motion matches the measured channels; its answer holds the fitted values
    with 1-sigma uncertainties (or "not determined by this measurement"), the misfit per channel before and
    after, and the calibrated scene as YAML. Acceleration channels are fitted in acceleration, measured and
    simulated alike detrended and band-passed (``highpass``, ``lowpass``)."""
    body = request.model_dump(exclude_none=True)
    cost = await run_heavy(http, price_request, body)
    try:
        job = await run_heavy(http, jobs.submit, body, cost)
    except RuntimeError as err:
        raise HTTPException(status_code=503, detail=str(err)) from None
    return await to_thread.run_sync(job_body, jobs, job["id"])


@router.get(
    "/{calibration_id}",
    response_model=CalibrationJob,
    responses={**NO_CALIBRATION, **NOT_RUNNING},
    summary="A calibration: status, progress and its answer once done",
)
async def calibration(calibration_id: str, jobs: CalibrationsDep) -> CalibrationJob:
    """Where the calibration is (``queued``, ``running``, ``done``, ``failed`` with ``error``), its cost
    estimate, its progress (engine batches and cases run), and ``result`` once done."""
    return await to_thread.run_sync(job_body, jobs, calibration_id)  # a file read: no heavy slot


@router.delete(
    "/{calibration_id}",
    status_code=204,
    responses={**NO_CALIBRATION, **NOT_RUNNING},
    summary="Cancel and remove a calibration",
)
async def delete_calibration(calibration_id: str, jobs: CalibrationsDep) -> Response:
    """Stop the calibration's fit (its worker stops at its next engine batch, within seconds) and remove
    it: every route answers 404 for it afterwards."""
    try:
        gone = await to_thread.run_sync(jobs.delete, calibration_id)
    except CalibrationNotFound as err:
        raise HTTPException(status_code=404, detail=str(err)) from None
    if not gone:
        raise HTTPException(status_code=404, detail=f"no calibration with id {calibration_id!r}")
    return Response(status_code=204)
