"""``POST /comparisons``: one scene under several isolator types, side by side.

The comparison is a small grid study (``isolators.preset`` over the requested types) that runs directly
through the engine in a worker thread of the API process: three cases take well under a second, far less
than queueing them behind the studies on the Dask cluster would. Outputs are the columns of a study's
case table (:func:`service.routes.studies.case_table`), so a comparison and a study read the same.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from fastapi import APIRouter, Body, HTTPException, Request
from pydantic import ValidationError

from isolab.service.request_limits import screen_definition
from isolab.service.routes import run_heavy
from isolab.service.routes.studies import CaseColumns, case_table, invalid, validation_details
from isolab.service.schemas import EXAMPLE_COMPARISON, Comparison, ComparisonRequest, ValidationErrorBody
from isolab.studies.accuracy import resolved_study

router = APIRouter(prefix="/comparisons", tags=["comparisons"])

#: Column prefix -> what "best" means for it.
CRITERIA: tuple[tuple[str, str], ...] = (
    ("peak_displacement_", "lowest"),
    ("peak_rotation_", "lowest"),
    ("peak_point_displacement_", "lowest"),
    ("peak_isolator_force_", "lowest"),
    ("min_isolator_load_min", "highest"),
    ("liftoff_any", "false"),
    ("settling_time", "lowest"),
    ("natural_frequency_", "lowest"),
)
"""Lowest peaks and settling time; the highest smallest isolator load (farthest from lift-off); no
lift-off; the lowest natural frequencies (the softest suspension isolates best from the floor)."""


def comparison_study(request: ComparisonRequest) -> Any:
    """The grid study behind a comparison; 422 naming the request field on bad input."""
    from isolab.studies.study import Study

    problems = screen_definition({"scene": request.scene, "simulation": request.simulation}, ["body"])
    if problems:
        raise HTTPException(status_code=422, detail=problems)
    body: dict[str, Any] = {
        "name": "comparison",
        "scene": request.scene,
        "parameters": [{"path": "isolators.preset", "values": list(dict.fromkeys(request.isolator_types))}],
        "design": {"type": "grid"},
    }
    if request.simulation is not None:
        body["simulation"] = request.simulation
    try:
        return Study.model_validate(body)
    except ValidationError as err:
        details = validation_details(err, ["body"])
        for d in details:  # the parameter is the request's isolator_types
            if d["loc"][1:2] == ["parameters"]:
                d["loc"] = ["body", "isolator_types"]
        raise HTTPException(status_code=422, detail=details) from None
    except (OverflowError, RecursionError) as err:
        raise invalid(
            ["body", "scene"], f"the scene cannot be computed: {type(err).__name__}: {err}"
        ) from None


def run_comparison(study: Any) -> CaseColumns:
    """Run every case of the comparison through the engine; the case table of the result."""
    from isolab.engine import simulate
    from isolab.studies.dataset import to_dataset
    from isolab.studies.runner import study_labels

    sim = study.simulation
    result = simulate(
        study.batch(np.arange(study.n_cases)),
        fidelity=sim.fidelity,
        integrator=sim.integrator,
        dt=sim.dt,
        auto_step=sim.auto_step,
    )
    iso, pts = study_labels(study)
    return case_table(to_dataset(result, study.design(), isolator_names=iso, point_names=pts))


def criterion(column: str) -> str | None:
    for prefix, rule in CRITERIA:
        if column == prefix or (prefix.endswith("_") and column.startswith(prefix)):
            return rule
    return None


#: Differences below these are numerical noise, not a better isolator (SI unit -> absolute tolerance).
NOISE: dict[str, float] = {"m": 1e-12, "rad": 1e-12, "N": 1e-6, "s": 1e-9, "Hz": 1e-9}


def best_of(values: dict[str, Any], rule: str, unit: str = "") -> str | None:
    """The type with the best value under ``rule`` ("lowest", "highest" or "false"); None when no type
    has a value or every type ties (within numerical noise: :data:`NOISE`, or 1e-9 relative)."""
    known = {
        t: v for t, v in values.items() if v is not None and not (isinstance(v, float) and math.isnan(v))
    }
    if not known:
        return None
    if rule == "false":
        winners = [t for t, v in known.items() if v is False]
        return winners[0] if 0 < len(winners) < len(values) else None
    pick = min if rule == "lowest" else max
    target = float(pick(known.values()))
    tol = max(NOISE.get(unit, 0.0), 1e-9 * max(abs(float(v)) for v in known.values()))
    winners = [t for t, v in known.items() if abs(float(v) - target) <= tol]
    if len(winners) == len(values) and len(values) > 1:
        return None
    return winners[0]


def comparison_table(table: CaseColumns, study: Any) -> Comparison:
    from isolab.service.routes.studies import json_values

    types = [str(t) for t in table.data["isolator_type"]]
    columns = [c for c in table.default if criterion(c) is not None or c in ("settled", "status")]
    rows = {t: {} for t in types}
    for c in columns + ["message"]:
        for t, v in zip(types, json_values(table.data[c], table.kinds[c]), strict=True):
            rows[t][c] = v
    best, criteria = {}, {}
    for c in columns:
        rule = criterion(c)
        if rule is None:
            continue
        criteria[c] = rule
        winner = best_of({t: rows[t][c] for t in types}, rule, table.units[c])
        if winner is not None:
            best[c] = winner
    return Comparison(
        isolator_types=types,
        columns=columns,
        units={c: table.units[c] for c in columns},
        rows=rows,
        best=best,
        criteria=criteria,
        simulation=study.simulation.model_dump(mode="json"),
    )


@router.post(
    "",
    response_model=Comparison,
    responses={422: {"model": ValidationErrorBody, "description": "invalid input; `loc` names the field"}},
    summary="Compare isolator types on one scene",
)
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
    study = await run_heavy(http, comparison_study, request)
    # an accuracy request runs (and the answer reports) the model chosen for it
    study = await run_heavy(http, resolved_study, study)
    try:
        table = await run_heavy(http, run_comparison, study)
    except ValueError as err:  # a scene the engine refuses under one of the types
        raise invalid(["body", "scene"], str(err)) from None
    if table.n_cases != len(set(request.isolator_types)):
        raise invalid(["body", "isolator_types"], "the comparison did not produce one case per isolator type")
    return comparison_table(table, study)
