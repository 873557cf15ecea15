"""What an optimisation answers: the dataset of every case it evaluated, with the optimum marked.

:func:`optimum_dataset` builds it from the evaluated generations of :func:`studies.run.optimisation.optimise`:
a sampled design of every evaluated case (``case`` dimension, parameters as coordinates) with
``generation``, ``feasible``, ``pareto`` and ``best`` per case (:func:`mark_optimum`), the ``plateau`` of
designs as good as the best and the parameters whose best value sits at an end of its range
(:func:`mark_plateau`), and the optimum's summary in the ``optimisation`` attribute. ``best`` is the
feasible case with the lowest first objective (with one objective: the optimum; with several: the end of
the Pareto front that is best on the first objective). A robust design's candidates carry, besides, the
probability of meeting its constraints within tolerances and the statistic of each objective over their
tolerance cloud (:func:`studies.run.robust.add_robustness`); their feasibility is the chance constraint's.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any

import numpy as np

from isolab.studies.quantities import output_values
from isolab.studies.questions.criteria import add_criteria
from isolab.studies.questions.designs import Design
from isolab.studies.questions.goals import PENALTY, Goals
from isolab.studies.results.dataset import from_chunks, to_dataset
from isolab.studies.run.robust import CloudPlan, add_robustness, describe_robustness

if TYPE_CHECKING:  # xarray loads with the first optimum marked (the command line's `run` starts without it)
    import xarray as xr


def non_dominated(F: np.ndarray) -> np.ndarray:
    """(n,) bool: the rows of ``F`` (n, objectives; lower is better) that no other row dominates (no worse
    in every objective and better in one). Equal rows do not dominate each other."""
    F = np.asarray(F, dtype=np.float64)
    if F.ndim == 2 and F.shape[1] == 1 and len(F):
        # one objective: a row is dominated exactly when another is lower (a NaN row by none, none by it)
        f = F[:, 0]
        finite = ~np.isnan(f)
        return ~(f > f[finite].min()) if finite.any() else np.ones(len(F), dtype=bool)
    keep = np.ones(len(F), dtype=bool)
    for i in range(len(F)):
        no_worse = (F <= F[i]).all(axis=1)
        better = (F < F[i]).any(axis=1)
        keep[i] = not (no_worse & better).any()
    return keep


def mark_optimum(
    ds: xr.Dataset, F: np.ndarray, G: np.ndarray, generation: np.ndarray, goals: Goals
) -> xr.Dataset:
    """``ds`` (a sampled dataset of the evaluated cases, in order) with ``generation``, ``feasible``,
    ``pareto``, ``best`` and ``constraint_violation`` per case, and the ``optimisation`` summary attribute
    (algorithm, generations, best case and its parameter values and objectives)."""
    import xarray as xr

    n = len(F)
    feasible = (np.asarray(G) <= 0.0).all(axis=1)
    pareto = np.zeros(n, dtype=bool)
    best = np.zeros(n, dtype=bool)
    idx = np.flatnonzero(feasible)
    if idx.size:
        pareto[idx[non_dominated(F[idx])]] = True
        front = np.flatnonzero(pareto)
        best[front[np.lexsort(F[front].T[::-1])[0]]] = True  # lowest first objective (ties: the next ones)
    out = ds.copy()
    flags = {"flag_values": np.array([0, 1], dtype=np.int8), "flag_meanings": "false true"}
    meets = "the case ended ok and meets every constraint of the design"
    if goals.robust is not None:
        require = goals.robust.require
        meets = f"the candidate meets the chance constraint: probability_meets_criteria >= {require:g}"
    out["generation"] = xr.Variable(
        "case", np.asarray(generation, dtype=np.int32), {"units": "1", "long_name": "optimiser generation"}
    )
    out["feasible"] = xr.Variable(
        "case",
        feasible,
        {"units": "1", "long_name": meets, **flags},
    )
    out["pareto"] = xr.Variable(
        "case",
        pareto,
        {
            "units": "1",
            "long_name": "feasible and no other feasible case is better in every objective",
            **flags,
        },
    )
    rule = "lowest" if goals.objectives[0].sense == "minimize" else "highest"
    out["best"] = xr.Variable(
        "case",
        best,
        {
            "units": "1",
            "long_name": f"the feasible case of {rule} {goals.objectives[0].quantity}"
            + (" (the Pareto front's end on the first objective)" if len(goals.objectives) > 1 else ""),
            **flags,
        },
    )
    out["constraint_violation"] = xr.Variable(
        "case",
        np.maximum(np.asarray(G, dtype=np.float64), 0.0).sum(axis=1),
        {
            "units": "1",
            "long_name": "sum of the constraints' violations as fractions of their bounds (0: feasible; "
            f"{PENALTY:g} per constraint for a case that failed)",
        },
    )
    summary: dict[str, Any] = {
        "algorithm": goals.algorithm,
        "objectives": [o.text for o in goals.objectives],
        "constraints": [c.text for c in goals.constraints],
        "budget": goals.budget,
        "population": goals.population,
        "seed": goals.seed,
        "generations": int(np.max(generation)) + 1 if n else 0,
        "n_cases": n,
        "n_feasible": int(feasible.sum()),
        "n_pareto": int(pareto.sum()),
        "best_rule": out["best"].attrs["long_name"],
        "best_case": None,
    }
    if best.any():
        b = int(np.flatnonzero(best)[0])
        summary["best_case"] = b
        summary["best_generation"] = int(generation[b])
        summary["best_parameters"] = {f.name: float(out[f.name].values[b]) for f in goals.factors}
        summary["parameter_units"] = {f.name: f.unit for f in goals.factors}
        summary["best_objectives"] = {
            o.quantity: float(F[b, k] if o.sense == "minimize" else -F[b, k])
            for k, o in enumerate(goals.objectives)
        }
    out = mark_plateau(out, F, np.asarray(feasible, dtype=bool), best, goals, summary)
    out.attrs["optimisation"] = json.dumps(summary)
    return out


LIMIT_SHARE = 0.01
"""A variable whose best value lies within this share of its range from an end is flagged at that limit."""


def unit_position(factor: Any, x: np.ndarray) -> np.ndarray:
    """Where values ``x`` (SI) lie in ``factor``'s range: 0 at ``low``, 1 at ``high`` (in log space for a log
    scale): the inverse of :meth:`studies.questions.designs.Factor.from_unit`."""
    x = np.asarray(x, dtype=np.float64)
    if factor.scale == "log":
        return np.log(np.abs(x) / abs(factor.low)) / np.log(abs(factor.high) / abs(factor.low))
    return (x - factor.low) / (factor.high - factor.low)


def mark_plateau(
    out: xr.Dataset,
    F: np.ndarray,
    feasible: np.ndarray,
    best: np.ndarray,
    goals: Goals,
    summary: dict[str, Any],
) -> xr.Dataset:
    """``out`` with ``plateau`` per case (feasible, first objective within ``goals.plateau`` of the best's)
    and ``at_range_limit`` per parameter (-1 the best sits at the low end of its range, +1 at the high end,
    0 inside); ``summary`` gains the plateau's size and each variable's range over it, and the limits."""
    import xarray as xr

    n = len(F)
    plateau = np.zeros(n, dtype=bool)
    names = [f.name for f in goals.factors]
    limit = np.zeros(len(names), dtype=np.int8)
    if best.any():
        b = int(np.flatnonzero(best)[0])
        f0 = np.asarray(F, dtype=np.float64)[:, 0]
        plateau = feasible & (f0 <= f0[b] + goals.plateau * abs(f0[b]))
        for j, f in enumerate(goals.factors):
            u = float(unit_position(f, out[f.name].values[b]))
            limit[j] = -1 if u <= LIMIT_SHARE else (1 if u >= 1.0 - LIMIT_SHARE else 0)
        summary["plateau"] = goals.plateau
        summary["n_plateau"] = int(plateau.sum())
        summary["plateau_ranges"] = {
            name: [float(out[name].values[plateau].min()), float(out[name].values[plateau].max())]
            for name in names
        }
        summary["at_limit"] = {
            name: "low" if lim < 0 else "high" for name, lim in zip(names, limit, strict=True) if lim != 0
        }
    flags = {"flag_values": np.array([0, 1], dtype=np.int8), "flag_meanings": "false true"}
    out["plateau"] = xr.Variable(
        "case",
        plateau,
        {
            "units": "1",
            "long_name": f"feasible, with {goals.objectives[0].quantity} within {goals.plateau:.3g} of the "
            "best case's (a share of it): the designs as good as the optimum",
            **flags,
        },
    )
    out = out.assign_coords(
        parameter=xr.Variable(
            "parameter", np.array(names, dtype=np.str_), {"units": "1", "long_name": "optimised parameter"}
        )
    )
    out["at_range_limit"] = xr.Variable(
        "parameter",
        limit,
        {
            "units": "1",
            "long_name": "the best case's value at an end of the parameter's range (within "
            f"{LIMIT_SHARE:.0%} of it): -1 the low end, 1 the high end, 0 inside",
            "flag_values": np.array([-1, 0, 1], dtype=np.int8),
            "flag_meanings": "at_low_end inside at_high_end",
        },
    )
    return out


def optimum_dataset(
    generations: list[dict[str, np.ndarray]],
    goals: Goals,
    *,
    stopped: str,
    isolator_names: list[str],
    point_names: list[str],
    criteria: Any = None,
    attrs: dict[str, Any] | None = None,
    cloud: CloudPlan | None = None,
) -> xr.Dataset:
    """The dataset of every case an optimisation evaluated (see the module docstring), from the arrays of
    its ``generations`` (each holding ``x``, ``F``, ``G`` and the cases' result arrays; a robust design's
    also the arrays of :meth:`studies.run.robust.CloudPlan.judge`, with its ``cloud`` plan given);
    ``stopped`` says why the run ended (``budget``, ``stalled`` or ``cancelled``)."""
    gens = generations
    sizes = [len(a["u"]) for a in gens]
    starts = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    chunks = [np.arange(starts[k], starts[k + 1], dtype=np.int64) for k in range(len(gens))]
    result = from_chunks(
        dict(enumerate(gens)), chunks, n_isolators=len(isolator_names), n_points=len(point_names)
    )
    x = np.concatenate([a["x"] for a in gens]) if gens else np.zeros((0, len(goals.factors)))
    names = [f.name for f in goals.factors]
    design = Design(
        "sampled",
        names,
        {n: x[:, j] for j, n in enumerate(names)},
        {},
        {f.name: f.path for f in goals.factors},
        {f.name: f.unit for f in goals.factors},
    )
    ds = to_dataset(result, design, isolator_names=isolator_names, point_names=point_names, attrs=attrs)
    ds = add_criteria(ds, criteria)
    F = np.concatenate([a["F"] for a in gens]) if gens else np.zeros((0, len(goals.objectives)))
    G = np.concatenate([a["G"] for a in gens]) if gens else np.zeros((0, len(goals.told_constraints)))
    generation = np.repeat(np.arange(len(gens)), sizes)
    if cloud is not None:
        ds = add_robustness(ds, gens, cloud)
    out = mark_optimum(ds, F, G, generation, goals)
    summary = json.loads(out.attrs["optimisation"])
    summary["stopped"] = stopped
    summary["stall"] = goals.stall
    if goals.robust is not None:
        summary["robust"] = goals.robust.described()
    out.attrs["optimisation"] = json.dumps(summary)
    return out


def describe_optimum(ds: xr.Dataset) -> list[str]:
    """Lines that report an optimisation's dataset: algorithm and cases, the best case with its parameter
    values and objectives (empty for a dataset that is not an optimisation's)."""
    if "optimisation" not in ds.attrs:
        return []
    s = json.loads(ds.attrs["optimisation"])
    robust = s.get("robust")
    cases = f"{s['n_cases']} cases"
    if robust is not None:  # each candidate ran as its nominal case and its draws
        cases = f"{s['n_cases']} candidates ({s['n_cases'] * (robust['samples'] + 1):,} cases simulated)"
    lines = [
        f"{s['algorithm']}: {s['generations']} generations, {cases}, "
        f"{s['n_feasible']} feasible, {s['n_pareto']} on the Pareto front"
    ]
    if s.get("best_case") is None:
        return [*lines, "no feasible case: no optimum"]
    units = s.get("parameter_units", {})
    values = ", ".join(f"{k} = {v:.4g} {units.get(k, '')}".rstrip() for k, v in s["best_parameters"].items())
    lines.append(f"best: case {s['best_case']} (generation {s['best_generation']}): {values}")
    for q, v in s["best_objectives"].items():
        unit = str(output_values(ds, q).attrs.get("units", ""))
        lines.append(f"  {q} = {v:.6g} {'' if unit == '1' else unit}".rstrip())
    lines += describe_robustness(ds, s)
    for name, end in s.get("at_limit", {}).items():
        lines.append(f"  {name} is at the {end} end of its range: the optimum may lie beyond it")
    if "plateau_ranges" in s:
        lines.append(
            f"plateau: {s['n_plateau']} feasible cases within {s['plateau']:.3g} of the best objective, over"
        )
        for k, (lo, hi) in s["plateau_ranges"].items():
            lines.append(f"  {k} = {lo:.4g} to {hi:.4g} {units.get(k, '')}".rstrip())
    if s.get("stopped") == "stalled":
        lines.append(f"stopped early: {s.get('stall')} generations without improving the best by 0.1 %")
    return lines
