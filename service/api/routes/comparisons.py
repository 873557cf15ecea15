"""``POST /comparisons``: one scene under several isolator types, side by side.

The comparison itself is :mod:`isolab.studies.answers.comparisons` (a small grid study run directly through
the
engine in a worker thread of the API process: three cases take well under a second, far less than
queueing them behind the studies on the Dask cluster would).
"""

from __future__ import annotations

from fastapi import APIRouter, Body, Request, Response

from isolab.service.api.routes import INVALID, PNG, invalid, run_heavy
from isolab.service.api.schemas import (
    EXAMPLE_COMPARISON,
    EXAMPLE_FLOOR_PLOT,
    Comparison,
    ComparisonRequest,
    FloorPlotRequest,
)
from isolab.service.plots.studies import floor_velocity_png
from isolab.studies.answers.comparisons import compare as run_compare
from isolab.studies.answers.floor_response import velocity_spectra

router = APIRouter(prefix="/comparisons", tags=["comparisons"])


@router.post("", response_model=Comparison, responses=INVALID, summary="Compare isolator types on one scene")
async def compare(
    http: Request,
    request: ComparisonRequest = Body(
        openapi_examples={
            "three types": {
                "summary": "the article's scriber on active, air and elastomer isolators",
                "value": EXAMPLE_COMPARISON,
            },
        }
    ),
) -> Comparison:
    """Run the same machine and stages on each isolator type and answer a side-by-side table: peak
    displacement and rotation per axis, peak isolator force, smallest isolator load and lift-off,
    settling time and natural frequencies, with the best type per column in ``best``; with design criteria
    in the scene, each type's margin to each and ``meets_criteria``, and the one ``recommendation``: the
    cheapest type (``cost_order``) that meets them all."""
    answer = await run_heavy(
        http,
        run_compare,
        request.scene,
        request.isolator_types,
        request.simulation,
        request.cost_order,
        request.tune,
    )
    if len(answer["isolator_types"]) != len(set(request.isolator_types)):
        raise invalid(["body", "isolator_types"], "the comparison did not produce one case per isolator type")
    return Comparison(**answer)


@router.post(
    "/floor.png",
    response_class=Response,
    responses={**PNG, **INVALID},
    summary="Floor-induced velocity spectrum of a point, per isolator type, against the VC curves",
)
async def floor_png(
    http: Request,
    request: FloorPlotRequest = Body(
        openapi_examples={
            "VC-D floor": {
                "summary": "the article's scriber on a VC-D floor, at the tool, on all three isolator types",
                "value": EXAMPLE_FLOOR_PLOT,
            },
        }
    ),
) -> Response:
    """The one-third-octave RMS velocity of ``point`` per floor axis under the scene's ``floor.spectrum``,
    one line per isolator type, against the VC-A .. VC-G curves (log-log, um/s): a PNG. Steady state at
    the ``lti`` level, nothing is integrated
    (:func:`isolab.studies.answers.floor_response.velocity_spectra`)."""
    if getattr(request, "tune", False):
        raise invalid(
            ["body", "tune"],
            "the floor plot draws the isolators as the scene gives them; tune them with POST /comparisons "
            "and write the tuning into the scene",
        )
    spectra = await run_heavy(
        http,
        velocity_spectra,
        request.scene,
        request.isolator_types,
        request.point,
        simulation=request.simulation,
    )
    return Response(await run_heavy(http, floor_velocity_png, spectra), media_type="image/png")
