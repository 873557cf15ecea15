"""``/studies``: submit, list, inspect, cancel and delete studies; fetch their datasets.

Handlers only translate: the definition is checked by :mod:`isolab.studies.inputs.definitions`, the
catalog and files are :class:`isolab.studies.results.store.Store`, running is
:class:`isolab.service.api.jobs.JobQueue`. The case table, time histories and plots are
:mod:`isolab.service.api.routes.cases`.
"""

from __future__ import annotations

import re
from datetime import UTC, datetime
from typing import Annotated, Any

from anyio import to_thread
from fastapi import APIRouter, Body, HTTPException, Query, Request, Response
from fastapi import Path as PathParam
from fastapi.responses import FileResponse, HTMLResponse

from isolab.service.api.jobs import JobQueue, wait_for_end
from isolab.service.api.kernel_warmup import KernelWarmup
from isolab.service.api.request_limits import JsonParsedOffLoop
from isolab.service.api.routes import (
    INVALID,
    NOT_DONE,
    NOT_FOUND,
    JobsDep,
    KernelsDep,
    SettingsDep,
    StoreDep,
    invalid,
    require_done,
    run_heavy,
    study_row,
)
from isolab.service.api.schemas import (
    EXAMPLE_LHS_STUDY,
    EXAMPLE_STUDY,
    MessageBody,
    StudyAccepted,
    StudyDetail,
    StudyLinks,
    StudyList,
    StudyProgress,
    StudyStatusName,
    StudySummary,
)
from isolab.service.plots import report
from isolab.service.settings import STATUS_WAIT_S, Settings
from isolab.studies.answers.history import case_history, case_study
from isolab.studies.answers.study_answer import StudyAnswer, stored_study_answer
from isolab.studies.authoring.authoring import design_summary, stored_error_estimate
from isolab.studies.inputs.definitions import check_definition
from isolab.studies.results.cases import CaseQueryError, stored_case_table
from isolab.studies.results.catalog import StudyNotFound
from isolab.studies.results.store import Store, StudyFilter, StudyRecord

router = APIRouter(prefix="/studies", tags=["studies"], route_class=JsonParsedOffLoop)

MAX_OFFSET = 1_000_000_000
"""Largest ``offset`` of a listing (SQLite integers stop at 2**63)."""
StudyId = Annotated[str, PathParam(description="study id (32 hex digits)")]
TimeQuery = Query(
    description="RFC 3339 date-time (ISO 8601; UTC if no zone), inclusive",
    json_schema_extra={"format": "date-time"},
)
_RFC3339 = re.compile(
    r"(\d{4}-\d{2}-\d{2})[Tt ](\d{2}:\d{2}):(\d{2})(\.\d+)?([Zz]|[+-]\d{2}:\d{2})?", re.ASCII
)


def query_time(text: str | None, field_name: str) -> datetime | str | None:
    """A time filter of a listing as the catalog takes it: an RFC 3339 date-time (what the API description
    says, ``t``/``z`` in either case, a leap second read as the second before, any number of fractional
    digits) becomes a datetime; other text is left to the catalog (plain ISO 8601, or its ValueError)."""
    if text is None:
        return None
    m = _RFC3339.fullmatch(text)
    if m is None:
        return text
    day, minutes, seconds, fraction, zone = m.groups()
    micro = (fraction or ".")[1:7].ljust(6, "0")
    zone = "+00:00" if zone in (None, "Z", "z") else zone
    year_zero = day.startswith("0000-")  # RFC 3339 has a year 0; Python's datetime starts at year 1
    iso = f"{'0001' + day[4:] if year_zero else day}T{minutes}:{min(int(seconds), 59):02d}.{micro}{zone}"
    try:
        moment = datetime.fromisoformat(iso)
    except ValueError:
        raise ValueError(f"{field_name}: {text!r} is not an ISO 8601 time") from None
    try:
        return datetime.min.replace(tzinfo=UTC) if year_zero else moment.astimezone(UTC)
    except OverflowError:  # within a day of year 1 or year 9999: as far as a datetime goes
        return (datetime.min if moment.year == 1 else datetime.max).replace(tzinfo=UTC)


def links(study_id: str) -> StudyLinks:
    base = f"/studies/{study_id}"
    return StudyLinks(self=base, dataset=f"{base}/dataset", cases=f"{base}/cases")


def summary(record: StudyRecord, kernels_note: str | None = None) -> dict[str, Any]:
    """The catalog record as the fields of :class:`StudySummary`; ``kernels_note`` (what the kernels'
    warm-up says while it runs) becomes the ``note`` of a study that waits for its first cases."""
    waiting = record.status in ("queued", "running") and not record.n_done
    return {
        "note": kernels_note if waiting else None,
        "id": record.id,
        "name": record.name,
        "status": record.status,
        "progress": StudyProgress(done=record.n_done, total=record.n_cases, failed=record.n_failed),
        "created": record.created,
        "started": record.started,
        "finished": record.finished,
        "error": record.error,
        "failures": failure_note(record),
        "parameters": record.parameters,
        "isolator_types": record.isolator_types,
        "fidelity": record.fidelity,
        "integrator": record.integrator,
        "dt": record.dt,
        "generation": record.generation,
        "generations": record.generations,
        "links": links(record.id),
    }


def failure_note(record: StudyRecord) -> str | None:
    """``"3 of 12 cases failed ..."`` when cases have failed so far, else None."""
    n_failed = int(record.n_failed or 0)
    if not n_failed:
        return None
    return (
        f"{n_failed} of {record.n_cases} cases failed (status not ok); each one's status and message are "
        f"in its row of /studies/{record.id}/cases and in the dataset"
    )


@router.post(
    "",
    status_code=202,
    response_model=StudyAccepted,
    responses={
        **INVALID,
        413: {"model": MessageBody, "description": "request body too large"},
        503: {"model": MessageBody, "description": "the service is shutting down; submit again later"},
    },
    summary="Submit a study",
    # the definition is checked by studies.inputs.definitions (its errors name the field); the description
    # says at least what every definition has
    openapi_extra={
        "requestBody": {
            "content": {
                "application/json": {
                    "schema": {
                        "required": ["name", "scene"],
                        "properties": {
                            "name": {"type": "string", "minLength": 1, "maxLength": 200},
                            "scene": {"type": "object", "description": "inline scene"},
                        },
                    }
                }
            }
        }
    },
)
async def submit_study(
    request: Request,
    response: Response,
    definition: Annotated[
        dict[str, Any],
        Body(
            description="study definition with an inline scene (scene_file is not read over the API); "
            "quantities in SI or as strings with units ('2 g', '800 mm')",
            openapi_examples={
                "grid": {"summary": "3 isolator types x 2 Y accelerations (6 cases)", "value": EXAMPLE_STUDY},
                "lhs": {
                    "summary": "64-case Latin hypercube over f_vertical and zeta",
                    "value": EXAMPLE_LHS_STUDY,
                },
            },
        ),
    ],
    settings: SettingsDep,
    store: StoreDep,
    jobs: JobsDep,
) -> StudyAccepted:
    """Validate the study, store it in the catalog (status queued) and queue it. 202 with its links."""
    accepted = await run_heavy(request, accept_study, definition, settings, store, jobs)
    response.headers["Location"] = accepted.links.self
    return accepted


def accept_study(
    definition: dict[str, Any], settings: Settings, store: Store, jobs: JobQueue
) -> StudyAccepted:
    """Check a study, store it in the catalog (status queued) and queue it (runs in a worker thread); a
    refused definition raises :class:`~isolab.studies.inputs.definitions.DefinitionError` (422)."""
    study = check_definition(definition, settings.max_cases)
    n_cases = int(study.planned_cases)  # an optimize design: its budget
    study_id = store.register(study)
    try:
        jobs.submit(study_id)
    except RuntimeError as err:  # shutting down: the study stays queued and runs at the next start
        raise HTTPException(status_code=503, detail=str(err)) from None
    return StudyAccepted(id=study_id, status="queued", n_cases=n_cases, links=links(study_id))


@router.get("", response_model=StudyList, responses=INVALID, summary="List studies")
def list_studies(
    store: StoreDep,
    kernels: KernelsDep,
    name: Annotated[str | None, Query(description="exact study name")] = None,
    status: Annotated[StudyStatusName | None, Query(description="study status")] = None,
    isolator_type: Annotated[str | None, Query(description="studies involving this isolator type")] = None,
    created_after: Annotated[str | None, TimeQuery] = None,
    created_before: Annotated[str | None, TimeQuery] = None,
    limit: Annotated[int, Query(ge=1, le=500)] = 50,
    offset: Annotated[int, Query(ge=0, le=MAX_OFFSET)] = 0,
) -> StudyList:
    """Studies in the catalog, newest first, filtered (all filters must hold)."""
    try:
        where = StudyFilter(
            name=name,
            status=status,
            isolator_type=isolator_type,
            created_after=query_time(created_after, "created_after"),
            created_before=query_time(created_before, "created_before"),
        )
        records = store.list(where, limit=limit, offset=offset)
        total = store.count(where)
    except ValueError as err:
        field_name = str(err).split(":", 1)[0]
        raise invalid(["query", field_name], str(err)) from None
    note = kernels.note() if kernels is not None else None
    return StudyList(
        items=[StudySummary(**summary(r, note)) for r in records], total=total, limit=limit, offset=offset
    )


MAX_WAIT_S = STATUS_WAIT_S
"""Longest a status request may wait for its study to end (``GET /studies/{id}?wait=``), s."""


def study_detail(store: Store, study_id: str, kernels: KernelWarmup | None) -> StudyDetail:
    """A study's :class:`StudyDetail` from its catalog row (404 when there is none)."""
    row = study_row(store, study_id)
    return StudyDetail(**summary(row, kernels.note() if kernels else None), definition=row["definition"])


@router.get(
    "/{study_id}", response_model=StudyDetail, responses={**NOT_FOUND, **INVALID}, summary="A study's status"
)
async def get_study(
    study_id: StudyId,
    request: Request,
    store: StoreDep,
    jobs: JobsDep,
    kernels: KernelsDep,
    wait: Annotated[
        float,
        Query(
            ge=0,
            le=MAX_WAIT_S,
            allow_inf_nan=False,
            description="seconds to wait while the study is queued or running (a long poll): the answer "
            "comes as soon as it ends, else at this bound with its progress then; 0 answers at once",
        ),
    ] = 0.0,
) -> StudyDetail:
    """Status, progress, times, error and the definition of one study; while the service compiles the
    engine's kernels (first start only), a study waiting for them says so in ``note``. With ``wait``, the
    answer waits for the study to end, at most that many seconds."""
    if wait > 0:
        await wait_for_end(jobs, study_id, wait, request)
    return await to_thread.run_sync(study_detail, store, study_id, kernels)


@router.delete("/{study_id}", status_code=204, responses=NOT_FOUND, summary="Delete a study")
def delete_study(study_id: StudyId, store: StoreDep, jobs: JobsDep) -> Response:
    """Remove the study with its files, whatever its status: every route answers 404 for it from now on.
    A queued study never runs; a running one stops at its next chunk (its workers finish the chunk they
    hold, and what it leaves behind is removed when it stops)."""
    row = study_row(store, study_id)
    if row["status"] in ("queued", "running"):
        jobs.cancel(study_id, wait=0.0)  # the request does not wait for the running chunk
    store.delete(study_id)
    return Response(status_code=204)


@router.get(
    "/{study_id}/dataset",
    response_class=FileResponse,
    responses={
        **NOT_FOUND,
        **NOT_DONE,
        200: {"content": {"application/x-netcdf": {}}, "description": "the study's netCDF4 file"},
    },
    summary="A study's dataset (netCDF)",
)
def get_dataset(study_id: StudyId, store: StoreDep) -> FileResponse:
    """The study's labelled dataset as a netCDF4 file (streamed); 409 until the study is done."""
    row = study_row(store, study_id)
    require_done(row)
    path = store.path(study_id)
    if not path.is_file():
        raise HTTPException(
            status_code=404, detail=f"study {study_id} is done but its dataset file is missing"
        )
    # the study's name is user text: only letters, digits, _ and - reach the suggested file name
    stem = re.sub(r"[^A-Za-z0-9_-]+", "_", row["name"]).strip("_-")[:100] or "study"
    filename = f"{stem}-{study_id}.nc"
    return FileResponse(path, media_type="application/x-netcdf", filename=filename)


def stored_answer(store: Store, study_id: str) -> dict[str, Any]:
    """What a done study answers; 404 when its dataset file is missing."""
    try:
        return stored_study_answer(store, study_id)
    except (FileNotFoundError, StudyNotFound):
        raise HTTPException(status_code=404, detail=f"study {study_id} has no dataset file") from None


@router.get(
    "/{study_id}/answer",
    response_model=StudyAnswer,
    responses={**NOT_FOUND, **NOT_DONE},
    summary="What a done study answers: scene, question, margins, optimum",
)
async def get_answer(request: Request, study_id: StudyId, store: StoreDep) -> StudyAnswer:
    """The machine in a few facts, the question (design, criteria, objectives), each case's margin to
    each criterion with the value judged (at most 50 cases listed; the case of the largest smallest margin
    always), and for an optimisation its best design, progress per generation, plateau and the parameters
    at an end of their range (:mod:`isolab.studies.answers.study_answer`); SI, units beside."""
    row = study_row(store, study_id)
    require_done(row)
    return StudyAnswer(**await run_heavy(request, stored_answer, store, study_id))


@router.get(
    "/{study_id}/report.html",
    response_class=Response,
    responses={**NOT_FOUND, **NOT_DONE, 200: {"content": {"text/html": {}}, "description": "the report"}},
    summary="The design report: one HTML file to send or print",
)
async def get_report(request: Request, study_id: StudyId, store: StoreDep) -> HTMLResponse:
    """The scene, the question, the answer and its margins, the plots (inline PNG) and the model with its
    measured error, as one self-contained HTML page without script (print it to PDF from a browser); it
    recomputes one case for its time response, so it takes a few seconds."""
    row = study_row(store, study_id)
    require_done(row)
    answer = await run_heavy(request, stored_answer, store, study_id)
    design = await run_heavy(request, design_summary, row)
    try:
        error = await run_heavy(request, stored_error_estimate, store.path(study_id))
    except FileNotFoundError:
        error = None
    table = await run_heavy(request, stored_case_table, store, study_id)
    case = report.report_case(answer)
    try:
        study = await run_heavy(request, case_study, row, case, store)
        history = await run_heavy(request, case_history, study, case, 1)
    except (CaseQueryError, LookupError, ValueError):  # a case too long to recompute: the report goes without
        history = None
    title = f"Time response of case {case}"
    figures = await run_heavy(request, report.report_figures, answer, table, history, title)
    html = report.design_report(answer, design, error, figures)
    return HTMLResponse(
        html, headers={"Content-Security-Policy": report.REPORT_POLICY, "Cache-Control": "no-cache"}
    )
