"""Scenes run at once, in the API process: ``POST /simulations`` (one case: its summary and traces) and
``POST /comparisons`` (one scene under several isolator types, side by side).

A single case is :mod:`isolab.studies.answers.single_case`, sized before it runs and run in a worker
thread under a time limit (:data:`SIMULATION_TIME_LIMIT`).

The comparison itself is :mod:`isolab.studies.answers.comparisons` (a small grid study run directly through
the
engine in a worker thread of the API process: three cases take well under a second, far less than
queueing them behind the studies on the Dask cluster would).
"""

from __future__ import annotations

import anyio
from anyio import to_thread
from fastapi import APIRouter, Body, HTTPException, Request, Response
from pydantic import ValidationError

from isolab.service.api.catalogue_schemas import (
    EXAMPLE_CATALOGUE_COMPARISON,
    CatalogueComparisonRequest,
    CatalogueFile,
    CatalogueRead,
    ProductComparison,
)
from isolab.service.api.request_limits import JsonParsedOffLoop
from isolab.service.api.routes import INVALID, PNG, invalid, run_heavy
from isolab.service.api.schemas import (
    EXAMPLE_COMPARISON,
    EXAMPLE_FLOOR_PLOT,
    EXAMPLE_SCENE,
    ComparisonRequest,
    FloorPlotRequest,
    MessageBody,
    SimulationAnswer,
    SimulationRequest,
)
from isolab.service.plots.studies import floor_velocity_png
from isolab.studies.answers.comparisons import compare as run_compare
from isolab.studies.answers.floor_response import FloorSpectra, point_spectra, velocity_spectra
from isolab.studies.answers.product_comparison import compare_products
from isolab.studies.answers.single_case import MAX_CASE_SECONDS, run_single_case, single_case_study
from isolab.studies.answers.sizing import SizingAnswer, SizingRequest
from isolab.studies.answers.sizing import size as run_size
from isolab.studies.authoring.authoring import parse_text
from isolab.studies.inputs.catalogues import DEFAULT_LOAD_MARGIN, Catalogue, read_catalogue_text
from isolab.studies.inputs.definitions import DefinitionError, validation_details

router = APIRouter(tags=["comparisons"], route_class=JsonParsedOffLoop)

SIMULATION_TIME_LIMIT = 3.0 * MAX_CASE_SECONDS
"""Longest a single case may run, s: three times the longest estimate it is admitted with. Past it the
answer is a 503 at once; the engine's thread (which cannot be interrupted) runs to its end unheard."""


@router.post(
    "/simulations",
    response_model=SimulationAnswer,
    responses={
        **INVALID,
        503: {"model": MessageBody, "description": "the case ran past the time limit of a single case"},
    },
    summary="Run one scene now: its summary and traces",
)
async def simulate_scene(
    http: Request,
    request: SimulationRequest = Body(
        openapi_examples={
            "scriber": {
                "summary": "the article's scriber on air isolators",
                "value": {"scene": EXAMPLE_SCENE},
            }
        }
    ),
) -> SimulationAnswer:
    """Run the scene as a one-case study, synchronously: its summary (the case-table columns a study's case
    has: peaks, loads, natural frequencies, settling, the margins of the scene's criteria; SI, each with its
    unit and long name), its modes, where each isolator stands, and its time traces thinned to at most
    ``max_points`` samples. A case past 5 million recorded values (steps x series) or 10 s of estimated
    engine time is refused with a 422 naming the limit and the field; one that runs past the time limit is
    answered 503. A study runs larger cases."""
    study = await run_heavy(http, single_case_study, request.scene, request.simulation)
    limiter = getattr(http.app.state, "heavy_work", None)
    try:
        with anyio.fail_after(SIMULATION_TIME_LIMIT):
            answer = await to_thread.run_sync(
                run_single_case, study, request.max_points, abandon_on_cancel=True, limiter=limiter
            )
    except TimeoutError:
        raise HTTPException(
            status_code=503,
            detail=f"the case ran past the {SIMULATION_TIME_LIMIT:g} s limit of a single case run at once; "
            "submit it as a study (POST /studies)",
        ) from None
    return SimulationAnswer(**answer)


@router.post(
    "/comparisons",
    response_model=ProductComparison,
    responses=INVALID,
    summary="Compare isolator types, or the products of a catalogue, on one scene",
)
async def compare(
    http: Request,
    request: CatalogueComparisonRequest = Body(
        openapi_examples={
            "three types": {
                "summary": "the article's scriber on active, air and elastomer isolators",
                "value": EXAMPLE_COMPARISON,
            },
            "catalogue": {
                "summary": "the article's scriber on the products of the shipped catalogue",
                "value": EXAMPLE_CATALOGUE_COMPARISON,
            },
        }
    ),
) -> ProductComparison:
    """Run the same machine and stages on each isolator type and answer a side-by-side table: peak
    displacement and rotation per axis, peak isolator force, smallest isolator load and lift-off,
    settling time and natural frequencies, with the best type per column in ``best``; with design criteria
    in the scene, each type's margin to each and ``meets_criteria``, and the one ``recommendation``: the
    cheapest type (``cost_order``) that meets them all. With a ``tolerances:`` block in the scene, each
    type is also judged on ``samples`` machines drawn from it (``robustness``: the probability of meeting
    every criterion with its interval, as drawn and, with ``tune``, as tuned), and the recommendation is
    the most probable type that reaches ``require``.

    With a ``catalogue`` the rows are its products (of ``isolator_types``) instead: each at the fewest
    isolators per mount (of ``per_corner``) that carry the scene's static loads inside its rated range with
    ``margin``, a product they do not fit skipped with the reason (``catalogue.products``); the
    recommendation is the cheapest priced product that meets every criterion (with tolerances: reaches
    ``require``), else the unpriced one with the largest smallest margin. A catalogue none of whose products
    fits is answered with no rows and the reasons."""
    if request.catalogue is not None:
        if request.tune:
            raise invalid(["body", "tune"], "a product's figures are its datasheet's: tune the generic types")
        if request.cost_order is not None:
            raise invalid(["body", "cost_order"], "with a catalogue the products' prices order them")
        answer = await run_heavy(
            http,
            compare_products,
            request.scene,
            request.catalogue,
            request.simulation,
            isolator_types=list(request.isolator_types),
            margin=request.margin,
            per_corner=request.per_corner,
            samples=request.samples,
            require=request.require,
            seed=request.seed,
        )
        return ProductComparison(**answer)
    if request.margin != DEFAULT_LOAD_MARGIN or request.per_corner is not None:
        field = "margin" if request.margin != DEFAULT_LOAD_MARGIN else "per_corner"
        raise invalid(["body", field], "applies to a comparison of a catalogue's products: give catalogue")
    answer = await run_heavy(
        http,
        run_compare,
        request.scene,
        request.isolator_types,
        request.simulation,
        request.cost_order,
        request.tune,
        request.samples,
        request.require,
        request.seed,
    )
    if len(answer["isolator_types"]) != len(set(request.isolator_types)):
        raise invalid(["body", "isolator_types"], "the comparison did not produce one case per isolator type")
    return ProductComparison(**answer)


def refuse_tuning(request: ComparisonRequest, what: str) -> None:
    """A 422 naming ``tune`` when ``request`` asks to tune the isolators of an answer that ``what`` (the
    answer, in words: "the floor plot draws") the isolators as the scene gives them."""
    if getattr(request, "tune", False):
        raise invalid(
            ["body", "tune"],
            f"{what} the isolators as the scene gives them; tune them with POST /comparisons and write the "
            "tuning into the scene",
        )


@router.post(
    "/comparisons/floor.png",
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
    refuse_tuning(request, "the floor plot draws")
    spectra = await run_heavy(
        http,
        velocity_spectra,
        request.scene,
        request.isolator_types,
        request.point,
        simulation=request.simulation,
    )
    return Response(await run_heavy(http, floor_velocity_png, spectra), media_type="image/png")


@router.post(
    "/comparisons/floor",
    response_model=FloorSpectra,
    responses=INVALID,
    summary="Floor-induced velocity spectrum at every point, per isolator type, with the VC curves",
)
async def floor_spectra(
    http: Request,
    request: ComparisonRequest = Body(
        openapi_examples={
            "VC-D floor": {
                "summary": "the article's scriber on a VC-D floor, on all three isolator types",
                "value": {key: v for key, v in EXAMPLE_FLOOR_PLOT.items() if key != "point"},
            },
        }
    ),
) -> FloorSpectra:
    """The one-third-octave RMS velocity (m/s, bands in Hz) of every point of interest per floor axis under
    the scene's ``floor.spectrum``, per isolator type, with the floor's own spectrum, each point's largest
    band, the VC-A .. VC-G curves (and the ISO 2631-2 lines) and the curve each point's velocity criterion
    names: what the page's floor view draws (:func:`isolab.studies.answers.floor_response.point_spectra`).
    Steady state at the ``lti`` level; the comparison's tolerance fields are not used."""
    refuse_tuning(request, "the floor spectra are of")
    return await run_heavy(
        http, point_spectra, request.scene, request.isolator_types, simulation=request.simulation
    )


@router.post(
    "/sizings",
    response_model=SizingAnswer,
    responses=INVALID,
    summary="Choose the isolators from a catalogue: product, count, pressure, margins",
)
async def sizing(
    http: Request,
    request: SizingRequest = Body(
        openapi_examples={
            "scriber": {
                "summary": "the article's scriber sized from the shipped catalogue",
                "value": {"scene": EXAMPLE_SCENE, "catalogue": "representative", "per_corner": [1, 2]},
            },
        }
    ),
) -> SizingAnswer:
    """For each mount position the product of the catalogue (and the number side by side, of
    ``per_corner``) that carries its static load inside the rated range with ``margin``, meets the scene's
    criteria and costs least: candidate designs run cheapest first, at most ``max_cases`` of them. The
    answer gives per mount the static load, load margin, air pressure (products with an effective area),
    stroke used, and why each cheaper product fails; with no product fitting, ``feasible`` is false and
    ``summary`` says why."""
    answer = await run_heavy(
        http,
        run_size,
        request.scene,
        request.catalogue,
        margin=request.margin,
        per_corner=request.per_corner,
        simulation=request.simulation,
        max_cases=request.max_cases,
    )
    return SizingAnswer(**answer)


@router.post(
    "/catalogues/read",
    response_model=CatalogueRead,
    responses=INVALID,
    summary="Read a catalogue file (YAML, JSON or CSV) into the catalogue a comparison takes",
)
def read_catalogue(request: CatalogueFile) -> CatalogueRead:
    """Parse and check the text of a catalogue file, as the page reads a file the user uploads: answered
    as the mapping ``POST /comparisons`` and ``POST /sizings`` take as their ``catalogue`` (every quantity
    in SI), with the products' ids. Text that does not parse is a 422 naming ``body.text`` and the line; a
    product that does not check, one naming its field (``body.text.products.2.rated_load.max``)."""
    if request.format == "csv":
        try:
            data = read_catalogue_text(request.text, request.format, request.name)
        except ValueError as err:
            raise invalid(["body", "text"], str(err)) from None
    else:
        # YAML and JSON through the studies' bounded reader: aliases, depth and size checked before loading
        data, _ = parse_text(request.text, ["body", "text"])
    try:
        catalogue = Catalogue.model_validate(data)
    except ValidationError as err:
        raise DefinitionError(validation_details(err, ["body", "text"])) from None
    return CatalogueRead(
        catalogue=catalogue.model_dump(mode="json", exclude_none=True), products=catalogue.ids
    )
