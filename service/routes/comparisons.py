"""``POST /comparisons``: one scene under several isolator types, side by side.

The comparison itself is :mod:`isolab.studies.comparisons` (a small grid study run directly through the
engine in a worker thread of the API process: three cases take well under a second, far less than
queueing them behind the studies on the Dask cluster would).
"""

from __future__ import annotations

from fastapi import APIRouter, Body, Request

from isolab.service.routes import INVALID, invalid, run_heavy, unprocessable
from isolab.service.schemas import EXAMPLE_COMPARISON, Comparison, ComparisonRequest
from isolab.studies.comparisons import compare as run_compare
from isolab.studies.definitions import DefinitionError

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
    settling time and natural frequencies, with the best type per column in ``best``."""
    try:
        answer = await run_heavy(http, run_compare, request.scene, request.isolator_types, request.simulation)
    except DefinitionError as err:
        raise unprocessable(err.details) from None
    if len(answer["isolator_types"]) != len(set(request.isolator_types)):
        raise invalid(["body", "isolator_types"], "the comparison did not produce one case per isolator type")
    return Comparison(**answer)
