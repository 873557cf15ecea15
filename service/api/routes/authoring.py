"""Writing studies as text and reading them back as written: example studies, checking a study without
submitting it, a stored definition as YAML, a study's design in its author's units and its measured error.

Handlers only translate: everything is :mod:`isolab.studies.authoring.authoring`.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Body, HTTPException, Request, Response
from fastapi import Path as PathParam

from isolab.service.api.request_limits import JsonParsedOffLoop
from isolab.service.api.routes import (
    INVALID,
    NOT_DONE,
    NOT_FOUND,
    SettingsDep,
    StoreDep,
    require_done,
    run_heavy,
    study_row,
)
from isolab.service.api.routes.studies import StudyId
from isolab.service.api.schemas import (
    EXAMPLE_STUDY_TEXT,
    ErrorEstimate,
    ExampleList,
    ExampleStudy,
    MessageBody,
    StudyCheck,
    StudyDesign,
    StudyText,
    TextValidationErrorBody,
)
from isolab.studies.authoring.authoring import (
    check_text,
    definition_yaml,
    design_summary,
    example_names,
    example_text,
    stored_error_estimate,
)
from isolab.studies.authoring.scene_view import (
    SceneExample,
    SceneRequest,
    SceneView,
    example_scene,
    example_scene_names,
    scene_view,
)

router = APIRouter(tags=["authoring"], route_class=JsonParsedOffLoop)


@router.get("/examples", response_model=ExampleList, summary="Example studies")
def list_examples() -> ExampleList:
    """Names of the example studies shipped with isolab."""
    return ExampleList(names=example_names())


@router.get(
    "/examples/{name}",
    response_model=ExampleStudy,
    responses={404: {"model": MessageBody, "description": "no example of that name"}},
    summary="One example study as YAML text",
)
def get_example(name: Annotated[str, PathParam(description="example name, e.g. isolator-comparison")]):
    """The example as YAML text with its scene file inlined under ``scene:``, ready to check and submit."""
    return ExampleStudy(name=name, text=example_text(name))


@router.get("/scenes/examples", response_model=ExampleList, summary="Examples that hold a scene")
def list_example_scenes() -> ExampleList:
    """Names of the shipped examples that hold a scene: scene files and example studies."""
    return ExampleList(names=example_scene_names())


@router.get(
    "/scenes/examples/{name}",
    response_model=SceneExample,
    responses={404: {"model": MessageBody, "description": "no example scene of that name"}},
    summary="The scene of an example, as data",
)
def get_example_scene(name: Annotated[str, PathParam(description="example name, e.g. article-scriber")]):
    """The scene of a shipped example (a scene file, or an example study's scene) as written, its units
    as text: ready to edit and to send to POST /scenes/check or POST /simulations."""
    return SceneExample(**example_scene(name))


@router.post(
    "/scenes/check",
    response_model=SceneView,
    responses=INVALID,
    summary="Check a scene and answer what follows from it: base mass, inertia, c.g., mounts, modes",
)
async def check_scene(request: Request, body: SceneRequest) -> SceneView:
    """Check the scene as POST /simulations would (the same 422 details, nothing runs) and answer the
    base's mass, inertia about its c.g. and c.g. (computed from size and density for a block), the box
    it is drawn as, each mount's place, static load, stiffness, damping and frequencies on its load, each
    stage at home with the ends of its travel, the points of interest, the natural modes with the stages at
    home (each with its shape: the base's rigid-body motion), and the scene as YAML."""
    return SceneView(**await run_heavy(request, scene_view, body.scene))


@router.post(
    "/studies/validate",
    response_model=StudyCheck,
    responses={
        422: {
            "model": TextValidationErrorBody,
            "description": "the study is refused; each detail has the `line` of the text it points at",
        }
    },
    summary="Check a study given as YAML text, without submitting it",
)
async def validate_study_text(
    request: Request,
    settings: SettingsDep,
    body: StudyText = Body(
        openapi_examples={
            "grid": {
                "summary": "3 isolator types x 2 Y accelerations, as YAML",
                "value": {"text": EXAMPLE_STUDY_TEXT},
            }
        }
    ),
) -> StudyCheck:
    """Check the study as ``POST /studies`` would (nothing is stored or run): answer the definition as
    data (submit it as it is), the case count and a rough run time; or 422 with one detail per problem,
    each placed at its line of the text."""
    answer = await run_heavy(request, check_text, body.text, settings.max_cases, settings.workers)
    return StudyCheck(**answer)


@router.get(
    "/studies/{study_id}/definition.yaml",
    response_class=Response,
    responses={**NOT_FOUND, 200: {"content": {"application/yaml": {}}, "description": "YAML text"}},
    summary="A study's stored definition as YAML",
)
def get_definition_yaml(study_id: StudyId, store: StoreDep) -> Response:
    """The definition as stored (parameters as written, the scene in SI with defaults filled in)."""
    row = study_row(store, study_id)
    return Response(definition_yaml(row["definition"]), media_type="application/yaml; charset=utf-8")


@router.get(
    "/studies/{study_id}/design",
    response_model=StudyDesign,
    responses=NOT_FOUND,
    summary="A study's parameters in the units its author wrote",
)
async def get_design(request: Request, study_id: StudyId, store: StoreDep) -> StudyDesign:
    """Each varied parameter with its case-table column, its values or range as written, its scale
    (linear or log) and the unit its author wrote it in; the design type."""
    row = study_row(store, study_id)
    return StudyDesign(**await run_heavy(request, design_summary, row))


@router.get(
    "/studies/{study_id}/error-estimate",
    response_model=ErrorEstimate,
    responses={**NOT_FOUND, **NOT_DONE},
    summary="A done study's measured error and the model it ran with",
)
async def get_error_estimate(request: Request, study_id: StudyId, store: StoreDep) -> ErrorEstimate:
    """The fidelity, integrator and step the cases ran with, and the largest error of each output over
    the sampled cases against the reference level."""
    row = study_row(store, study_id)
    require_done(row)
    try:
        found = await run_heavy(request, stored_error_estimate, store.path(study_id))
    except FileNotFoundError:
        raise HTTPException(status_code=404, detail=f"study {study_id} has no dataset file") from None
    return ErrorEstimate(fidelity=row["fidelity"], integrator=row["integrator"], dt=row["dt"], **found)
