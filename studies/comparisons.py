"""One scene under several isolator types, side by side: which type is best on each output.

A comparison is a small grid study (``isolators.preset`` over the requested types) run directly through the
engine: three cases take well under a second. Its outputs are the columns of a study's case table
(:func:`isolab.studies.cases.case_table`), so a comparison and a study read the same.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from isolab.engine import simulate
from isolab.studies.accuracy import resolved_study
from isolab.studies.cases import CaseColumns, case_table, json_values
from isolab.studies.dataset import to_dataset
from isolab.studies.definitions import DefinitionError, check_definition, detail
from isolab.studies.runner import study_labels
from isolab.studies.study import Study

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


def comparison_study(
    scene: Any, isolator_types: list[str], simulation: Any = None, prefix: list[str | int] | None = None
) -> Study:
    """The grid study behind a comparison of ``scene`` (a scene definition as data) on each of
    ``isolator_types``.

    Raises:
        DefinitionError: naming the request's field (``scene``, ``simulation`` or ``isolator_types``)
            under ``prefix`` (default ``["body"]``).
    """
    pre: list[str | int] = ["body"] if prefix is None else list(prefix)
    body: dict[str, Any] = {
        "name": "comparison",
        "scene": scene,
        "parameters": [{"path": "isolators.preset", "values": list(dict.fromkeys(isolator_types))}],
        "design": {"type": "grid"},
    }
    if simulation is not None:
        body["simulation"] = simulation
    try:
        return check_definition(body, prefix=pre)
    except DefinitionError as err:
        for d in err.details:  # the parameter is the request's isolator_types
            if d["loc"][len(pre) : len(pre) + 1] == ["parameters"]:
                d["loc"] = [*pre, "isolator_types"]
            elif d["loc"] == pre and "cannot be computed" in d["msg"]:
                d["loc"] = [*pre, "scene"]
        raise


def run_comparison(study: Study) -> CaseColumns:
    """Run every case of the comparison through the engine; the case table of the result.

    Raises:
        ValueError: a scene the engine refuses under one of the types.
    """
    sim = study.simulation
    fidelity, integrator, dt = sim.engine_choice()
    result = simulate(
        study.batch(np.arange(study.n_cases)),
        fidelity=fidelity,
        integrator=integrator,
        dt=dt,
        auto_step=sim.auto_step,
    )
    iso, pts = study_labels(study)
    return case_table(to_dataset(result, study.design(), isolator_names=iso, point_names=pts))


def criterion(column: str) -> str | None:
    """The rule (\"lowest\", \"highest\" or \"false\") a column is judged by, or None."""
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


def comparison_table(table: CaseColumns, study: Study) -> dict[str, Any]:
    """The side-by-side answer: one row per isolator type (outputs in SI), the units, the rule of each
    criterion and the best type on each (``best``), and the simulation block the cases ran with."""
    types = [str(t) for t in table.data["isolator_type"]]
    columns = [c for c in table.default if criterion(c) is not None or c in ("settled", "status")]
    rows: dict[str, dict[str, Any]] = {t: {} for t in types}
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
    return {
        "isolator_types": types,
        "columns": columns,
        "units": {c: table.units[c] for c in columns},
        "rows": rows,
        "best": best,
        "criteria": criteria,
        "simulation": study.simulation.model_dump(mode="json"),
    }


def compare(scene: Any, isolator_types: list[str], simulation: Any = None) -> dict[str, Any]:
    """Validate, run and tabulate a comparison in one call (see :func:`comparison_table`).

    Raises:
        DefinitionError: bad input, naming the field.
    """
    study = resolved_study(comparison_study(scene, isolator_types, simulation))
    try:
        table = run_comparison(study)
    except ValueError as err:
        raise DefinitionError([detail(["body", "scene"], str(err))]) from None
    return comparison_table(table, study)
