"""One scene under several isolator types, side by side: which type is best on each output.

A comparison is a small grid study (``isolators.preset`` over the requested types) run directly through the
engine: three cases take well under a second. Its outputs are the columns of a study's case table
(:func:`isolab.studies.results.cases.case_table`), so a comparison and a study read the same.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from isolab.engine.results import LARGER, OUTPUTS
from isolab.studies.inputs.definitions import DefinitionError, check_definition, detail
from isolab.studies.inputs.schema.scene_paths import ISOLATOR_PRESET
from isolab.studies.inputs.study import Study
from isolab.studies.results.cases import CaseColumns, case_table, json_values
from isolab.studies.run.accuracy import resolved_study

if TYPE_CHECKING:
    from isolab.studies.questions.criteria import Criteria

SHOWN_UNJUDGED = ("settled", "status")
"""Summary columns a comparison shows without judging them (whether the motion settled: its settling time
is judged)."""


def comparison_study(
    scene: Any,
    isolator_types: list[str],
    simulation: Any = None,
    prefix: list[str | int] | None = None,
    path: str = ISOLATOR_PRESET,
) -> Study:
    """The grid study behind a comparison of ``scene`` (a scene definition as data) on each of
    ``isolator_types``: the values of ``path``, the isolator type (``isolators.preset``) or a product of
    the scene's catalogue (``isolators.model``).

    Raises:
        DefinitionError: naming the request's field (``scene``, ``simulation`` or ``isolator_types``; with
            products ``catalogue``) under ``prefix`` (default ``["body"]``).
    """
    pre: list[str | int] = ["body"] if prefix is None else list(prefix)
    body: dict[str, Any] = {
        "name": "comparison",
        "scene": scene,
        "parameters": [{"path": path, "values": list(dict.fromkeys(isolator_types))}],
        "design": {"type": "grid"},
    }
    if simulation is not None:
        body["simulation"] = simulation
    try:
        return check_definition(body, prefix=pre)
    except DefinitionError as err:
        for d in err.details:  # the parameter is the request's isolator_types
            if d["loc"][len(pre) : len(pre) + 1] == ["parameters"]:
                d["loc"] = [*pre, "isolator_types" if path == ISOLATOR_PRESET else "catalogue"]
            elif d["loc"] == pre and "cannot be computed" in d["msg"]:
                d["loc"] = [*pre, "scene"]
        raise


def run_comparison(study: Study) -> CaseColumns:
    """Run every case of the comparison through the engine; the case table of the result.

    Raises:
        ValueError: a scene the engine refuses under one of the types.
    """
    from isolab.studies.answers.robustness import judged_dataset

    return case_table(judged_dataset(study))


def criterion(table: CaseColumns, column: str) -> str | None:
    """The rule (\"lowest\", \"highest\", \"false\" or \"true\") a column of ``table`` is judged by, or None.

    An output's column is judged as the catalogue judges the output (:data:`isolab.engine.results.OUTPUTS`):
    the lowest number (the highest where a smaller value is worse, as the smallest isolator load: the
    farthest from lift-off), or no (yes) for a yes/no output. So the lowest peaks, settling times and
    natural frequencies (the softest suspension isolates best from the floor) win; and the types that meet
    the criteria (``meets_criteria``) with the highest margins (``margin_<criterion>``).
    """
    if column == "meets_criteria":
        return "true"
    if column.startswith("margin_"):
        return "highest"
    output = table.outputs.get(column)
    if output is None or column in SHOWN_UNJUDGED:
        return None
    spec = OUTPUTS[output]
    if spec.flag:
        return "false" if spec.worse == LARGER else "true"
    return "lowest" if spec.worse == LARGER else "highest"


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
    if rule in ("false", "true"):
        winners = [t for t, v in known.items() if v is (rule == "true")]
        return winners[0] if 0 < len(winners) < len(values) else None
    pick = min if rule == "lowest" else max
    target = float(pick(known.values()))
    tol = max(NOISE.get(unit, 0.0), 1e-9 * max(abs(float(v)) for v in known.values()))
    winners = [t for t, v in known.items() if abs(float(v) - target) <= tol]
    if len(winners) == len(values) and len(values) > 1:
        return None
    return winners[0]


def failed_criteria(row: dict[str, Any], criteria: list[str]) -> str:
    """Why a comparison's ``row`` misses ``criteria`` in words: ``fails tool_displacement (-12%)``, or
    that its case did not end ok."""
    bad = [
        f"{c} ({float(row[f'margin_{c}']):+.0%})"
        for c in criteria
        if row.get(f"margin_{c}") is not None and float(row[f"margin_{c}"]) < 0
    ]
    if not bad:
        return f"its case did not end ok ({row.get('status')}: {row.get('message', '')})"
    return "fails " + ", ".join(bad)


COST_ORDER: tuple[str, ...] = ("elastomer", "air", "active")
"""Isolator types from the cheapest to the dearest: a passive elastomer pad costs least, an air spring
needs air supply and levelling valves, an active system adds sensors, actuators and a controller."""


def recommend(
    rows: dict[str, dict[str, Any]], criteria: list[str], cost_order: list[str] | tuple[str, ...] = COST_ORDER
) -> dict[str, Any]:
    """The one isolator type to buy: the cheapest (first in ``cost_order``) that meets every criterion.

    ``rows``: isolator type -> column -> value (a comparison's rows: ``meets_criteria`` and
    ``margin_<criterion>`` for each name in ``criteria``). Answers ``isolator_type`` (None when there are
    no criteria or no type meets them all), the ``reason`` in words, and the ``cost_order`` used.
    """
    order = [t for t in cost_order if t in rows] + [t for t in rows if t not in cost_order]
    answer: dict[str, Any] = {"isolator_type": None, "cost_order": order}
    if not criteria:
        answer["reason"] = (
            "no criteria given: add a criteria block (limits at the points of interest and on the mounts) "
            "to the scene to get a recommendation"
        )
        return answer

    def worst(t: str) -> tuple[float, str]:
        margins = {c: rows[t].get(f"margin_{c}") for c in criteria}
        known = {c: float(m) for c, m in margins.items() if m is not None and math.isfinite(float(m))}
        if len(known) < len(criteria):
            return -math.inf, next(c for c in criteria if c not in known)
        c = min(known, key=lambda k: known[k])
        return known[c], c

    def failing(t: str) -> str:
        return failed_criteria(rows[t], criteria)

    cost = " < ".join(order)
    meeting = [t for t in order if rows[t].get("meets_criteria") is True]
    if meeting:
        pick = meeting[0]
        m, c = worst(pick)
        cheaper = [f"{t} {failing(t)}" for t in order[: order.index(pick)]]
        answer["isolator_type"] = pick
        answer["reason"] = (
            f"{pick} is the cheapest type (cost order {cost}) that meets every criterion; its smallest "
            f"margin is {m:+.0%} on {c}" + (f". Cheaper: {'; '.join(cheaper)}" if cheaper else "")
        )
        return answer
    ranked = sorted(order, key=lambda t: worst(t)[0], reverse=True)
    closest = ranked[0]
    answer["reason"] = (
        f"no type meets every criterion: {'; '.join(f'{t} {failing(t)}' for t in order)}. "
        f"Closest: {closest} (smallest margin {worst(closest)[0]:+.0%} on {worst(closest)[1]}); relax the "
        "criteria, or tune or place the mounts differently"
    )
    return answer


def comparison_table(
    table: CaseColumns,
    study: Study,
    cost_order: list[str] | tuple[str, ...] = COST_ORDER,
    key: str = "isolator_type",
) -> dict[str, Any]:
    """The side-by-side answer: one row per isolator type (per value of the parameter ``key``: with a
    catalogue, per ``product``; outputs in SI), the units, the rule of each criterion and the best type on
    each (``best``), and the simulation block the cases ran with."""
    types = [str(t) for t in table.data[key]]
    columns = [c for c in table.default if criterion(table, c) is not None or c in SHOWN_UNJUDGED]
    rows: dict[str, dict[str, Any]] = {t: {} for t in types}
    for c in columns + ["message"]:
        for t, v in zip(types, json_values(table.data[c], table.kinds[c]), strict=True):
            rows[t][c] = v
    best, criteria = {}, {}
    for c in columns:
        rule = criterion(table, c)
        if rule is None:
            continue
        criteria[c] = rule
        winner = best_of({t: rows[t][c] for t in types}, rule, table.units[c])
        if winner is not None:
            best[c] = winner
    judged = study.criteria.names() if study.criteria is not None else []
    return {
        "isolator_types": types,
        "columns": columns,
        "units": {c: table.units[c] for c in columns},
        "rows": rows,
        "best": best,
        "criteria": criteria,
        "requirements": requirements(study.criteria),
        "recommendation": recommend(rows, judged, cost_order),
        "simulation": study.simulation.model_dump(mode="json"),
    }


def requirements(criteria: Criteria | None) -> list[dict[str, Any]]:
    """The design criteria the types were judged by: name, limit (SI), unit and meaning."""
    if criteria is None:
        return []
    from isolab.studies.questions.criteria import judged_criteria

    return [
        {"name": c.name, "limit": c.limit, "unit": c.unit, "description": c.description}
        for c in judged_criteria(criteria)
    ]


def compare(
    scene: Any,
    isolator_types: list[str],
    simulation: Any = None,
    cost_order: list[str] | tuple[str, ...] | None = None,
    tune: bool = False,
    samples: int | None = None,
    require: float | None = None,
    seed: int = 0,
) -> dict[str, Any]:
    """Validate, run and tabulate a comparison in one call (see :func:`comparison_table`), with the
    recommended type (:func:`recommend`; ``cost_order`` default :data:`COST_ORDER`). With ``tune``, each
    type is first tuned to the scene's criteria within its physical range
    (:func:`studies.answers.tuning.tune`);
    the answer's ``tuning`` gives the values found.

    When the scene has a ``tolerances:`` block, each type is also judged on ``samples`` machines drawn
    from it (default :data:`~studies.answers.robustness.DEFAULT_SAMPLES`, seeded by ``seed``), as
    drawn and, with ``tune``, as tuned: the answer's ``robustness`` gives each type's probability of
    meeting every criterion, and the recommendation is the most probable type that reaches ``require``
    (default :data:`~studies.answers.robustness.DEFAULT_REQUIRE`; see
    :func:`studies.answers.robustness.robustness_answer`). Without tolerances these are ignored.

    Raises:
        DefinitionError: bad input, naming the field.
    """
    from isolab.studies.answers import robustness

    study = resolved_study(comparison_study(scene, isolator_types, simulation))
    robust = study.scene is not None and bool(study.scene.tolerances)
    if robust:
        samples, require = robustness.robust_request(samples, require)
        assert study.scene is not None
        nominal = study.scene.model_dump(mode="json", exclude_none=True)
        sim = study.simulation.model_dump(mode="json")
        for t in map(str, study.design().levels["isolator_type"]):  # a bad tolerance: 422 before any run
            robustness.tolerance_study(nominal, t, sim, samples, seed)
    tuned: list[Any] = []
    if tune:
        from isolab.studies.answers.tuning import tune as tune_type
        from isolab.studies.answers.tuning import tuned_scene

        if study.criteria is None or not study.criteria.names():
            raise DefinitionError(
                [
                    detail(
                        ["body", "tune"], "tuning serves the design criteria: give the scene a criteria block"
                    )
                ]
            )
        assert study.scene is not None  # a validated study has its scene
        data = study.scene.model_dump(mode="json", exclude_none=True)
        try:
            tuned = [
                tune_type(data, t, study.simulation.model_dump(mode="json"))
                for t in map(str, study.design().levels["isolator_type"])
            ]
        except ValueError as err:
            raise DefinitionError([detail(["body", "scene"], str(err))]) from None
        study = resolved_study(comparison_study(tuned_scene(data, tuned), isolator_types, simulation))
    try:
        table = run_comparison(study)
    except ValueError as err:
        raise DefinitionError([detail(["body", "scene"], str(err))]) from None
    answer = comparison_table(table, study, COST_ORDER if cost_order is None else cost_order)
    if tuned:
        answer["tuning"] = {t.isolator_type: t.to_dict() for t in tuned}
    if robust:
        assert study.scene is not None and samples is not None and require is not None
        judged = study.criteria.names() if study.criteria is not None else []
        tuned_data = study.scene.model_dump(mode="json", exclude_none=True) if tuned else None
        try:
            answer = robustness.robustness_answer(
                answer, nominal, tuned_data, sim, judged, samples, require, seed
            )
        except DefinitionError:
            raise
        except ValueError as err:
            raise DefinitionError([detail(["body", "scene"], str(err))]) from None
    return answer


def comparison_frame(answer: dict[str, Any]) -> Any:
    """A comparison's answer (:func:`comparison_table`, or the JSON of ``POST /comparisons``) as a pandas
    DataFrame: one row per isolator type (index ``isolator_type``), one column per output, then
    ``meets_criteria`` and the margins; ``attrs`` carries ``recommendation``, ``requirements``, ``units``,
    ``best`` and ``simulation``."""
    import pandas as pd

    types = list(answer["isolator_types"])
    columns = list(answer["columns"])
    first = [c for c in columns if c != "meets_criteria" and not c.startswith("margin_")]
    last = [c for c in columns if c == "meets_criteria"] + [c for c in columns if c.startswith("margin_")]
    df = pd.DataFrame(
        [[answer["rows"][t].get(c) for c in first + last] for t in types],
        index=pd.Index(types, name="isolator_type"),
        columns=first + last,
    )
    for key in ("recommendation", "requirements", "units", "best", "simulation"):
        df.attrs[key] = answer.get(key)
    if answer.get("robustness") is not None:  # with tolerances: each type's probability of meeting them
        df.attrs["robustness"] = answer["robustness"]
    return df
