"""What a done study answers, in one summary an engineer reads: the scene, the question, the answer and the
margins, read from the study's stored dataset.

:func:`study_answer` gathers it (``GET /studies/{id}/answer``, the study page's answer views and the design
report):

- ``scene``: the machine's mass (kg, from its block's size and density when it is a block), its mounts
  (type and number), stages (mass, travel, axis) and points of interest;
- ``question``: the design (type, cases, varied parameters), the criteria (name, what it judges, limit
  and unit, SI) and, for an optimisation, its objectives and constraints;
- ``criteria``: each case's margin to each criterion (fraction of the limit to spare, positive: met) and
  the value judged (:func:`criterion_value`), for studies of at most :data:`MAX_LISTED_CASES` cases, and
  for every study the number of cases meeting every criterion and the case with the largest smallest
  margin;
- ``optimisation``: the optimiser's summary (best case, its parameters and objectives, the plateau, the
  parameters at an end of their range) with the best objective of each generation and the best so far, and
  the best case's margins.

Every number is SI, with its unit beside it; the views choose the units they show.
"""

from __future__ import annotations

import json
import math
from typing import TYPE_CHECKING, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from isolab.studies.inputs.block import block_properties
from isolab.studies.inputs.study import study_from_json
from isolab.studies.quantities import output_values
from isolab.studies.questions.criteria import Criteria, judged_criteria
from isolab.studies.results.cases import CaseColumns, stored_case_table
from isolab.studies.results.store import Store

if TYPE_CHECKING:  # the caller opens the dataset: xarray loads with it
    import xarray as xr

MAX_LISTED_CASES = 50
"""A study of at most this many cases lists every case's margins (a larger one: the best case's only)."""
NO_LIFTOFF = "isolators_no_liftoff"
"""The criterion whose margin is its value: the share of its preload the most unloaded mount keeps."""


class StudyAnswer(BaseModel):
    """What a done study answers (see :mod:`isolab.studies.answers.study_answer`); SI, units beside."""

    model_config = ConfigDict(extra="allow")

    study_id: str
    name: str
    description: str = ""
    created: str | None = None
    n_cases: int
    scene: dict[str, Any] = Field(description="the machine's mass (kg), mounts, stages and points")
    question: dict[str, Any] = Field(description="design, varied parameters, criteria, objectives")
    criteria: dict[str, Any] | None = Field(
        None, description="cases meeting every criterion, the case of the largest smallest margin, margins"
    )
    optimisation: dict[str, Any] | None = Field(
        None, description="an optimisation's best case, per-generation progress, plateau, range limits"
    )
    model: dict[str, Any] = Field(description="fidelity, integrator, step (s) and why they were chosen")


def criterion_value(name: str, limit: float, margin: float) -> float:
    """The value a criterion judged, from its ``margin`` (unit 1) and ``limit`` (SI): ``limit * (1 -
    margin)``; for ``isolators_no_liftoff`` the share of its preload the most unloaded mount keeps (the
    margin itself). NaN for a NaN margin."""
    if not math.isfinite(margin):
        return math.nan
    return float(margin) if name == NO_LIFTOFF else float(limit) * (1.0 - float(margin))


def _finite(value: Any) -> float | None:
    v = float(value)
    return v if math.isfinite(v) else None


def scene_summary(scene: dict[str, Any]) -> dict[str, Any]:
    """The machine of a stored (SI) scene in a few facts: mass (kg) and how it was given, mounts, stages,
    points of interest."""
    machine = scene.get("machine") or {}
    block = machine.get("block")
    mass: float | None = machine.get("mass")
    given = "mass"
    if mass is None and block:
        m, _, _ = block_properties(block["size"], block["density"], block.get("corner") or [0.0, 0.0, 0.0])
        mass, given = float(m), "block"
    iso = scene.get("isolators") or {}
    mounts = iso.get("mounts") or []
    layout = iso.get("layout") or {}
    n_mounts = len(mounts) if mounts else int(layout.get("n", 4) or 4)
    stages = [
        {
            "name": s.get("name"),
            "mass": s.get("mass"),
            "axis": s.get("axis"),
            "travel": (s.get("profile") or {}).get("travel"),
            "profile": (s.get("profile") or {}).get("type"),
        }
        for s in scene.get("stages") or []
    ]
    return {
        "mass": mass,
        "mass_from": given,
        "block": block,
        "isolator_type": iso.get("preset"),
        "n_mounts": n_mounts,
        "stages": stages,
        "points": sorted((scene.get("points") or {}).keys()),
        "units": {"mass": "kg", "travel": "m", "block.size": "m", "block.density": "kg/m^3"},
    }


def _criteria_of(ds: xr.Dataset) -> list[dict[str, Any]]:
    if "criterion_margin" not in ds:
        return []
    c = ds["criterion_margin"].coords
    names = [str(n) for n in c["criterion"].values]
    limits = c["criterion_limit"].values if "criterion_limit" in c else np.full(len(names), np.nan)
    units = c["criterion_unit"].values if "criterion_unit" in c else [""] * len(names)
    descriptions: dict[str, str] = {}
    try:
        block = Criteria.model_validate(json.loads(ds.attrs.get("criteria", "{}") or "{}"))
        descriptions = {c.name: c.description for c in judged_criteria(block)}
    except (ValueError, TypeError):  # a block this version cannot read: the names speak alone
        pass
    return [
        {
            "name": n,
            "limit": float(limits[k]),
            "unit": "1" if n == NO_LIFTOFF else str(units[k]),
            "description": descriptions.get(n, n.replace("_", " ")),
        }
        for k, n in enumerate(names)
    ]


def _case_label(table: CaseColumns, row: int) -> str:
    parts = []
    for p in table.parameters:
        v = table.data[p][row]
        parts.append(f"{p} = {v:.4g}" if isinstance(v, float | np.floating) else f"{p} = {v}")
    return ", ".join(parts) or f"case {row}"


def _case_margins(table: CaseColumns, criteria: list[dict[str, Any]], row: int) -> dict[str, Any]:
    margins = {c["name"]: _finite(table.data[f"margin_{c['name']}"][row]) for c in criteria}
    values = {
        c["name"]: _finite(criterion_value(c["name"], c["limit"], math.nan if m is None else m))
        for c, m in zip(criteria, margins.values(), strict=True)
    }
    meets = table.data.get("meets_criteria")
    return {
        "case": int(table.data["case"][row]),
        "label": _case_label(table, row),
        "meets_criteria": bool(meets[row] == 1) if meets is not None else None,
        "margins": margins,
        "values": values,
    }


def criteria_answer(table: CaseColumns, criteria: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The cases' margins to ``criteria`` (see the module); None without criteria."""
    if not criteria or any(f"margin_{c['name']}" not in table.data for c in criteria):
        return None
    m = np.column_stack([table.data[f"margin_{c['name']}"] for c in criteria]).astype(np.float64)
    worst = np.where(np.isnan(m).any(axis=1), -np.inf, np.nanmin(np.where(np.isnan(m), 0.0, m), axis=1))
    meets = table.data.get("meets_criteria")
    out: dict[str, Any] = {
        "n_meeting": int(np.sum(meets == 1)) if meets is not None else int(np.sum(worst >= 0)),
        "best_case": None,
        "cases": None,
    }
    if np.isfinite(worst).any():
        out["best_case"] = _case_margins(table, criteria, int(np.argmax(worst)))
    if table.n_cases <= MAX_LISTED_CASES:
        out["cases"] = [_case_margins(table, criteria, r) for r in range(table.n_cases)]
    return out


def optimisation_answer(
    ds: xr.Dataset, table: CaseColumns, criteria: list[dict[str, Any]]
) -> dict[str, Any] | None:
    """An optimisation's summary with its progress per generation, each varied parameter's range, best value
    and range-limit flag, and the best case's margins; None for a study that is not an optimisation."""
    if "optimisation" not in ds.attrs or "generation" not in ds:
        return None
    s = json.loads(ds.attrs["optimisation"])
    objective = str(s["objectives"][0]) if s.get("objectives") else ""
    sense, _, quantity = objective.partition(" ")
    generation = ds["generation"].values.astype(np.int64)
    feasible = ds["feasible"].values.astype(bool)
    try:
        values = np.asarray(output_values(ds, quantity).values, dtype=np.float64).reshape(-1)
        unit = str(output_values(ds, quantity).attrs.get("units", ""))
        long_name = str(output_values(ds, quantity).attrs.get("long_name", quantity))
    except (KeyError, ValueError):
        values, unit, long_name = np.full(len(generation), np.nan), "", quantity
    better = np.nanmin if sense == "minimize" else np.nanmax
    progress = []
    so_far: float | None = None
    for g in range(int(generation.max()) + 1 if generation.size else 0):
        ok = (generation == g) & feasible & np.isfinite(values)
        best = float(better(values[ok])) if ok.any() else None
        if best is not None:
            so_far = best if so_far is None else float(better([so_far, best]))
        progress.append(
            {
                "generation": g,
                "n_cases": int(np.sum(generation == g)),
                "n_feasible": int(np.sum((generation == g) & feasible)),
                "best": best,
                "best_so_far": so_far,
            }
        )
    limits = dict(
        zip(
            [str(p) for p in ds["parameter"].values] if "parameter" in ds.coords else [],
            [int(v) for v in ds["at_range_limit"].values] if "at_range_limit" in ds else [],
            strict=True,
        )
    )
    parameters = []
    best_case = s.get("best_case")
    goals = study_from_json(ds.attrs["study"]).goals if "study" in ds.attrs else None
    factors = {f.name: f for f in goals.factors} if goals is not None else {}
    for name, value in (s.get("best_parameters") or {}).items():
        coord = ds[name] if name in ds else None
        factor = factors.get(name)
        parameters.append(
            {
                "name": name,
                "long_name": str(coord.attrs.get("long_name", name)) if coord is not None else name,
                "unit": (s.get("parameter_units") or {}).get(name, ""),
                "best": value,
                "low": _finite(factor.low) if factor is not None and factor.low is not None else None,
                "high": _finite(factor.high) if factor is not None and factor.high is not None else None,
                "display_unit": factor.display_unit if factor is not None else "",
                "at_limit": {-1: "low", 1: "high"}.get(limits.get(name, 0)),
                "plateau": (s.get("plateau_ranges") or {}).get(name),
            }
        )
    best_margins = None
    if best_case is not None and criteria and all(f"margin_{c['name']}" in table.data for c in criteria):
        best_margins = _case_margins(table, criteria, int(best_case))
    cloud = {
        "case": [int(c) for c in table.data["case"]],
        "generation": [int(g) for g in generation],
        "objective": [_finite(v) for v in values],
        "feasible": [bool(f) for f in feasible],
        "pareto": [bool(f) for f in ds["pareto"].values] if "pareto" in ds else [False] * len(generation),
        "plateau": [bool(f) for f in ds["plateau"].values] if "plateau" in ds else [False] * len(generation),
    }
    return {
        **s,
        "objective": {"quantity": quantity, "sense": sense, "unit": unit, "long_name": long_name},
        "cloud": cloud,
        "progress": progress,
        "parameters": parameters,
        "best_margins": best_margins,
    }


def study_answer(ds: xr.Dataset, table: CaseColumns, study_id: str) -> dict[str, Any]:
    """What the done study of dataset ``ds`` (its case table ``table``) answers (see the module)."""
    definition = json.loads(ds.attrs.get("study", "{}") or "{}")
    design = json.loads(ds.attrs.get("design", "{}") or "{}")
    criteria = _criteria_of(ds)
    question: dict[str, Any] = {
        "design": design.get("type") or design.get("kind"),
        "parameters": [
            {
                "name": p,
                "unit": table.units.get(p, ""),
                "display_unit": table.display_units.get(p, table.units.get(p, "")),
                "long_name": table.long_names.get(p, p),
            }
            for p in table.parameters
        ],
        "criteria": criteria,
    }
    if "optimisation" in ds.attrs:
        s = json.loads(ds.attrs["optimisation"])
        question["objectives"] = s.get("objectives", [])
        question["constraints"] = s.get("constraints", [])
    dt = ds.attrs.get("dt")
    return {
        "study_id": study_id,
        "name": str(definition.get("name", ds.attrs.get("title", ""))),
        "description": str(definition.get("description") or ""),
        "created": ds.attrs.get("created"),
        "n_cases": table.n_cases,
        "scene": scene_summary(definition.get("scene") or {}),
        "question": question,
        "criteria": criteria_answer(table, criteria),
        "optimisation": optimisation_answer(ds, table, criteria),
        "model": {
            "fidelity": ds.attrs.get("fidelity"),
            "integrator": ds.attrs.get("integrator"),
            "dt": float(dt) if dt is not None else None,
            "reason": ds.attrs.get("accuracy_reason"),
        },
    }


def stored_study_answer(store: Store, study_id: str) -> dict[str, Any]:
    """:func:`study_answer` of a done study in ``store``.

    Raises:
        StudyNotFound: the study has no dataset file.
    """
    ds = store.open_dataset(study_id)
    try:
        return study_answer(ds, stored_case_table(store, study_id), study_id)
    finally:
        ds.close()
