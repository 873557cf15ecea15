"""``/studies/{id}/sensitivity`` and ``/studies/{id}/sensitivity.png``: how much each varied parameter of a
done study drives one of its outputs.

Handlers only translate: the analysis and its cache are :mod:`isolab.studies.answers.sensitivity`, the figure
:mod:`isolab.service.plots.sensitivity`.
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, HTTPException, Query, Request, Response
from fastapi.concurrency import run_in_threadpool
from pydantic import BaseModel, Field

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
from isolab.service.api.routes.studies import StudyId
from isolab.service.plots.sensitivity import sensitivity_png
from isolab.studies.answers.sensitivity import stored_sensitivity
from isolab.studies.results.store import Store

router = APIRouter(prefix="/studies", tags=["studies"])

OutputQuery = Annotated[
    str,
    Query(
        min_length=1,
        max_length=200,
        description="the output: a dataset variable and labels picking along its dimensions, dotted; "
        "unnamed dimensions take the worst value",
        examples=["peak_point_displacement.tool.z", "settling_time", "natural_frequency.1"],
    ),
]


class SecondOrder(BaseModel):
    pairs: list[list[str]] = Field(description="parameter pairs")
    S2: list[float | None] = Field(description="second-order Sobol' index of each pair")
    S2_conf: list[float | None] = Field(description="half-width of its confidence interval")


class Sensitivity(BaseModel):
    """Sensitivity indices of one output of a study (every index in [0, 1] up to estimation noise)."""

    method: str = Field(description="sobol (saltelli design) or delta (any other sample, or a grid)")
    method_name: str
    design: str = Field(description="the study's design type")
    output: str
    long_name: str
    unit: str = Field(description="SI unit of the output")
    parameters: list[str]
    parameter_long_names: list[str]
    parameter_units: list[str]
    indices: dict[str, list[float | None]] = Field(
        description="index name (S1, ST, delta) -> one value per parameter; null where not estimable"
    )
    conf: dict[str, list[float | None]] = Field(
        description="index name -> half-width of its confidence interval, per parameter"
    )
    conf_level: float
    interval_method: str = Field(default="", description="how the confidence intervals are formed, in words")
    replicates: int = Field(
        default=1, description="independent replicates of a saltelli design the intervals were read from"
    )
    n_cases: int = Field(description="cases the indices were estimated from")
    n_total: int = Field(description="cases of the study")
    n_excluded: int = Field(description="cases left out: status not ok, or no value of the output")
    n_dropped: int = Field(description="ok cases left out with a Saltelli block that lost a case")
    second_order: SecondOrder | None = None
    notes: list[str]
    index_meanings: dict[str, str]


def _analysis(store: Store, study_id: str, output: str) -> dict[str, Any]:
    try:
        return stored_sensitivity(store, study_id, output).to_dict()
    except FileNotFoundError as err:
        raise HTTPException(status_code=404, detail=str(err)) from None
    except ValueError as err:
        raise invalid(["query", "output"], f"output: {err}") from None


async def _answer(request: Request, store: Store, study_id: str, output: str) -> dict[str, Any]:
    row = await run_in_threadpool(study_row, store, study_id)
    require_done(row)
    answer = await run_heavy(request, _analysis, store, study_id, output)
    answer["_name"] = row["name"]
    return answer


@router.get(
    "/{study_id}/sensitivity",
    response_model=Sensitivity,
    responses={**NOT_FOUND, **NOT_DONE, **INVALID},
    summary="Sensitivity indices of one output",
)
async def get_sensitivity(request: Request, study_id: StudyId, output: OutputQuery, store: StoreDep) -> Any:
    """Global sensitivity of ``output`` to each varied parameter: Sobol' S1 and ST with 95 % confidence
    intervals for a saltelli design; Borgonovo's delta and S1 from the given data for lhs, sobol, random
    and grid designs. Cases that are not ok are left out and counted. Computed once per output and
    dataset, then read from the study's cache."""
    answer = await _answer(request, store, study_id, output)
    answer.pop("_name")
    return answer


@router.get(
    "/{study_id}/sensitivity.png",
    response_class=Response,
    responses={**NOT_FOUND, **NOT_DONE, **INVALID, **PNG},
    summary="Sensitivity indices of one output (PNG)",
)
async def get_sensitivity_plot(
    request: Request, study_id: StudyId, output: OutputQuery, store: StoreDep
) -> Response:
    """Bars of each index per parameter with their confidence intervals (see ``/sensitivity``)."""
    answer = await _answer(request, store, study_id, output)
    png = await run_heavy(request, sensitivity_png, answer, answer.pop("_name"))
    return Response(png, media_type="image/png")
