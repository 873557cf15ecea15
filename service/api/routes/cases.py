"""``/studies/{id}/cases...`` and ``/studies/{id}/plot.png``: a study's case table (filter, sort, columns,
JSON or CSV), one case's recomputed time histories, and figures.

Handlers only translate: the table and its query language are :mod:`isolab.studies.results.cases`, the
histories :mod:`isolab.studies.answers.history`, the figures :mod:`isolab.service.plots.studies`.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, HTTPException, Query, Request, Response
from fastapi import Path as PathParam
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import JSONResponse

from isolab.service.api.routes import (
    INVALID,
    NOT_DONE,
    NOT_FOUND,
    PNG,
    StoreDep,
    invalid,
    require_done,
    run_heavy,
    study_row,
)
from isolab.service.api.routes.studies import MAX_OFFSET, StudyId
from isolab.service.api.schemas import CaseTable, Timeseries
from isolab.service.plots import studies as plots
from isolab.studies.answers.floor_response import FloorSpectra, point_spectra
from isolab.studies.answers.history import (
    case_history,
    case_study,
    history_dataset,
    history_json,
    netcdf_bytes,
)
from isolab.studies.inputs.study import Study
from isolab.studies.results.cases import (
    MAX_CASE_ROWS,
    CaseColumns,
    cases_csv,
    check_page_size,
    json_values,
    select_cases,
    stored_case_table,
)
from isolab.studies.results.store import Store

router = APIRouter(prefix="/studies", tags=["studies"])


def case_table_of(store: Store, study_id: str) -> CaseColumns:
    """The case table of a done study; 404 when its dataset file is missing."""
    try:
        return stored_case_table(store, study_id)
    except FileNotFoundError as err:
        raise HTTPException(status_code=404, detail=str(err)) from None


def stored_case_study(store: Store, study_id: str, case: int) -> Study:
    """The study of one case of a stored study; 404 when there is no such study or case."""
    return case_study(study_row(store, study_id), case, store)


@router.get(
    "/{study_id}/cases",
    response_model=CaseTable,
    responses={
        **NOT_FOUND,
        **NOT_DONE,
        **INVALID,
        200: {"content": {"text/csv": {}}, "description": "the table as JSON or CSV"},
    },
    summary="Per-case table (filter, sort, columns)",
)
def get_cases(
    study_id: StudyId,
    store: StoreDep,
    filter: Annotated[
        str | None,
        Query(
            description="comma-separated clauses, all must hold: column<op>value, op one of < <= > >= == !=; "
            "values: numbers (SI, or with a unit), true, false, null, text",
            examples=[
                "peak_displacement_y<0.005,liftoff_any==false",
                "isolator_type==air,settling_time<=1.5 s",
            ],
        ),
    ] = None,
    sort: Annotated[
        str | None,
        Query(
            description="columns to sort by, comma-separated; prefix - for descending; missing values last",
            examples=["-peak_displacement_y"],
        ),
    ] = None,
    columns: Annotated[
        str | None,
        Query(
            description="comma-separated columns to return, or 'all' "
            "(default: parameters and the main outputs)"
        ),
    ] = None,
    limit: Annotated[int, Query(ge=1, le=MAX_CASE_ROWS)] = 1000,
    offset: Annotated[int, Query(ge=0, le=MAX_OFFSET)] = 0,
    format: Annotated[Literal["json", "csv"], Query(description="json (default) or csv")] = "json",
) -> Any:
    """One row per case: the varied parameters and the outputs flattened to columns
    (``peak_displacement_y``, ``min_isolator_load_min``, ``liftoff_any``, ``natural_frequency_1``...).
    Unknown columns are refused with 422 naming them."""
    row = study_row(store, study_id)
    require_done(row)
    table = case_table_of(store, study_id)
    cols, rows, matched = select_cases(table, filter, sort, columns, limit, offset)
    check_page_size(rows.size, len(cols))
    if format == "csv":
        return Response(
            cases_csv(table, cols, rows),
            media_type="text/csv; charset=utf-8",
            headers={"X-Total-Count": str(matched)},
        )
    values = {c: json_values(table.data[c][rows], table.kinds[c]) for c in cols}
    out_rows = [{c: values[c][i] for c in cols} for i in range(rows.size)]
    return JSONResponse(
        {
            "study_id": study_id,
            "n_cases": table.n_cases,
            "n_matched": matched,
            "offset": offset,
            "limit": limit,
            "columns": cols,
            "units": {c: table.units[c] for c in cols},
            "long_names": {c: table.long_names[c] for c in cols if c in table.long_names},
            "rows": out_rows,
        }
    )


@router.get(
    "/{study_id}/cases/{case}/timeseries",
    response_model=Timeseries,
    responses={
        **NOT_FOUND,
        200: {"content": {"application/x-netcdf": {}}, "description": "time histories as JSON or netCDF"},
    },
    summary="Time histories of one case (recomputed)",
)
async def get_timeseries(
    request: Request,
    study_id: StudyId,
    case: Annotated[int, PathParam(description="case number (the `case` column of the table)")],
    store: StoreDep,
    format: Annotated[Literal["json", "netcdf"], Query()] = "json",
    every: Annotated[int, Query(ge=1, le=10_000, description="keep every n-th sample")] = 1,
) -> Any:
    """Recompute one case from the stored definition with its histories recorded: time, c.g.
    displacement, base rotation, isolator forces and point displacements (SI, units in the answer)."""
    study = await run_heavy(request, stored_case_study, store, study_id, case)
    h = await run_heavy(request, case_history, study, case, every)
    if format == "netcdf":
        data = await run_heavy(request, netcdf_bytes, history_dataset(study_id, case, h, every))
        return Response(
            data,
            media_type="application/x-netcdf",
            headers={"Content-Disposition": f'attachment; filename="{study_id}-case{case}.nc"'},
        )
    content = await run_heavy(request, history_json, study_id, case, h, every)
    return JSONResponse(content)


@router.get(
    "/{study_id}/cases/{case}/floor",
    response_model=FloorSpectra,
    responses={**NOT_FOUND, **NOT_DONE, **INVALID},
    summary="Floor-induced velocity spectrum at every point of one case, with the VC curves",
)
async def get_case_floor(
    request: Request,
    study_id: StudyId,
    case: Annotated[int, PathParam(description="case number")],
    store: StoreDep,
) -> FloorSpectra:
    """The one-third-octave RMS velocity (m/s, bands in Hz) of every point of interest of one case per floor
    axis under its scene's ``floor.spectrum``, on the case's own isolators, with the VC curves and the curve
    each point's velocity criterion names (steady state, nothing integrated); 422 at ``case`` for a study
    whose scene has no floor spectrum."""
    require_done(study_row(store, study_id))
    study = await run_heavy(request, stored_case_study, store, study_id, case)
    return await run_heavy(request, point_spectra, study, None, case)


@router.get(
    "/{study_id}/cases/{case}/plot.png",
    response_class=Response,
    responses={**NOT_FOUND, **PNG},
    summary="Figures of one case (PNG)",
)
async def get_case_plot(
    request: Request,
    study_id: StudyId,
    case: Annotated[int, PathParam(description="case number")],
    store: StoreDep,
) -> Response:
    """C.g. translation, base rotation and isolator forces per axis against time, stacked (mm or um, mrad,
    N or kN as the magnitude reads best); the title gives the case's parameters in the study's units."""
    study = await run_heavy(request, stored_case_study, store, study_id, case)
    h = await run_heavy(request, case_history, study, case, 1)
    params = plots.parameters_text(h.parameters, study.design())
    title = f"{study.name} case {case}" + (f" ({params})" if params else "")
    png = await run_heavy(
        request, plots.case_png, h.time, h.displacement, h.rotation, h.isolator_force, h.isolator_names, title
    )
    return Response(png, media_type="image/png")


@router.get(
    "/{study_id}/plot.png",
    response_class=Response,
    responses={**NOT_FOUND, **NOT_DONE, **INVALID, **PNG},
    summary="An output against one or two varied parameters (PNG)",
)
async def get_study_plot(
    request: Request,
    study_id: StudyId,
    store: StoreDep,
    y: Annotated[
        str, Query(min_length=1, description="output column of the case table, e.g. peak_displacement_y")
    ],
    x: Annotated[str, Query(min_length=1, description="a varied parameter, e.g. stage_y_acceleration")],
    x2: Annotated[
        str | None, Query(min_length=1, description="a second varied parameter: draws a heat map")
    ] = None,
    reduce: Annotated[
        Literal["max", "min", "mean"] | None,
        Query(
            description="how cases that share the plotted parameters combine (default: min for min_* "
            "columns, else max: the worst case)"
        ),
    ] = None,
) -> Response:
    """A line per isolator type when the study varies it (one line otherwise) of ``y`` against ``x``;
    with ``x2`` a heat map per isolator type. Sampled studies give scatter plots. Parameters are drawn in
    the unit the study was written in (on a log axis for a log-scaled range), outputs in mm, um, kN or
    mrad as their magnitude reads best."""
    row = await run_in_threadpool(study_row, store, study_id)
    require_done(row)
    table = await run_in_threadpool(case_table_of, store, study_id)
    for param, name in (("y", y), ("x", x), ("x2", x2)):
        if name is not None and name not in table.data:
            raise invalid(
                ["query", param], f"{param}: unknown column {name!r}; columns: {', '.join(table.names)}"
            )
    for param, name in (("x", x), ("x2", x2)):
        if name is not None and name not in table.parameters:
            raise invalid(
                ["query", param],
                f"{param}: {name!r} is not a varied parameter of this study; "
                f"parameters: {', '.join(table.parameters) or 'none'}",
            )
    if table.kinds[y] == "text":
        raise invalid(["query", "y"], f"y: {y!r} is text; choose a numeric output")
    if x2 is not None and x2 == x:
        raise invalid(["query", "x2"], "x2: must differ from x")
    group = (
        "isolator_type" if "isolator_type" in table.parameters and "isolator_type" not in (x, x2) else None
    )
    how = reduce or ("min" if y.startswith("min_") else "max")
    png = await run_heavy(
        request,
        plots.study_png,
        y=plots.series(table, y),
        x=plots.series(table, x),
        x2=plots.series(table, x2) if x2 else None,
        group=plots.Series(group, table.data[group], "") if group else None,
        sampled=table.design_kind == "sampled",
        reduce=how,
        title=row["name"],
    )
    return Response(png, media_type="image/png")
