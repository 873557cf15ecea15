"""Optimisation studies: a pymoo optimiser picks the cases, a generation at a time, on the study's cluster.

An ``optimize`` design (``design: {type: optimize, objective: ..., budget: ...}``, its goals read by
:mod:`studies.questions.goals`) runs an ask-and-tell loop (:func:`optimise`): the algorithm proposes a
generation of
cases (``algorithm.ask()``), the generation runs as one batch of cases through the same Dask fan-out as any
study (a list-design study of those cases, :func:`studies.run.fanout.run_chunks`), their objective and
constraint values go back (``algorithm.tell``), until the ``budget`` of cases would be exceeded.

The optimiser works in the unit box: each parameter's range maps to [0, 1] (a log-scale range in log
space, :meth:`studies.questions.designs.Factor.from_unit`), so every variable has the same reach whatever its
unit.
A case that fails (unstable, tipping, a scene that cannot be built) or lacks a value is infeasible with
:data:`studies.questions.goals.PENALTY` in every objective and constraint: never NaN.

Resume: every evaluated generation is saved in the study's store directory as it finishes
(``<id>.chunks/generation-<g>.npz``: the unit-box and SI values, ``F``, ``G`` and the cases' result
arrays, plain arrays that ``numpy.load`` reads with ``allow_pickle=False``). The algorithm's state is not
stored: nothing in the store is ever unpickled or executed. A run called again with the same study id
(cancel, crash, a service restart: the job queue requeues unfinished studies) rebuilds the algorithm from
its seed and replays it through the saved generations: each generation the algorithm asks for that matches
a saved one (same unit-box values) is told the saved objectives and constraints, without evaluating it
again. The algorithm draws from its own seeded generator, so the replayed state is the uninterrupted run's
and an interrupted run ends with the same cases, and the same optimum, as an uninterrupted one.

The dataset (:func:`optimum_dataset`) is a sampled design of every evaluated case (``case`` dimension,
parameters as coordinates) with ``generation``, ``feasible``, ``pareto`` and ``best`` per case and the
optimum's summary in the ``optimisation`` attribute. ``best`` is the feasible case with the lowest first
objective (with one objective: the optimum; with several: the end of the Pareto front that is best on the
first objective).
"""

from __future__ import annotations

import contextlib
import json
import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from isolab.studies.inputs.study import Study
from isolab.studies.quantities import output_values
from isolab.studies.questions.criteria import add_criteria
from isolab.studies.questions.designs import Design
from isolab.studies.questions.goals import PENALTY, STALL_IMPROVEMENT, Goals, goal_values
from isolab.studies.results.dataset import from_chunks, result_arrays, to_dataset
from isolab.studies.results.store import Store, atomic_path

log = logging.getLogger(__name__)

LEGACY_STATE_FILE = "optimiser.pkl"
"""A pickled algorithm state older versions left in a study's store directory: removed unread on resume."""
GENERATION_FILE = "generation-{}.npz"
"""One evaluated generation in a study's store directory."""
POPULATION_ALGORITHMS = ("ga", "de", "pso", "nsga2")
"""Algorithms whose every generation is ``population`` cases (the local searches ask one or a few)."""

Evaluate = Callable[[int, dict[str, np.ndarray]], dict[str, np.ndarray] | None]
"""``evaluate(generation, values)``: the cases of one generation, ``values`` parameter name -> (n,) SI
values; returns at least ``F`` (n, objectives) and ``G`` (n, constraints)
(:func:`studies.questions.goals.goal_values`)
plus any per-case arrays to keep, or None when it was cancelled."""


# ------------------------------------------------------------------------------------------ algorithms
def _pattern_search() -> Any:
    """pymoo's Hooke-Jeeves pattern search, drawing its exploration order from the algorithm's own seeded
    generator (pymoo's draws from an unseeded one, so two runs of one seed would differ)."""
    from pymoo.algorithms.soo.nonconvex.pattern import (
        PatternSearch,
        calc_sign,
        exploration_move,
        is_better,
        pattern_move,
    )
    from pymoo.core.population import Population

    class SeededPatternSearch(PatternSearch):
        def _next(self) -> Any:  # pymoo 0.6's PatternSearch._next, with random_state passed on
            me: Any = self  # pymoo's attributes are untyped
            rs = me.random_state
            if not is_better(me._explr, me._center):
                me.n_not_improved += 1
                me._rho = me.init_rho**me.n_not_improved
                me._explr = yield from exploration_move(
                    me.problem, me._center, me._sign, me._delta, me._rho, random_state=rs
                )
            else:
                me._direction = me._explr.X - me._center.X
                me._center = me._explr
                me._trial = yield pattern_move(me.problem, me._center, me._direction, me.step_size)
                me._sign = calc_sign(me._direction)
                me._explr = yield from exploration_move(
                    me.problem, me._trial, me._sign, me._delta, me._rho, random_state=rs
                )
            me.pop = Population.create(me._center, me._explr)

    return SeededPatternSearch()


def make_algorithm(name: str, population: int) -> Any:
    """The pymoo algorithm ``name`` (one of :data:`studies.questions.goals.ALGORITHMS`) with ``population``
    cases per
    generation (the local searches, ``nelder-mead`` and ``pattern``, take no population)."""
    from pymoo.config import Config

    Config.warnings["not_compiled"] = False  # pymoo's compiled extensions are optional speed-ups
    if name == "ga":
        from pymoo.algorithms.soo.nonconvex.ga import GA

        return GA(pop_size=population, eliminate_duplicates=True)
    if name == "de":
        from pymoo.algorithms.soo.nonconvex.de import DE

        return DE(pop_size=population)
    if name == "pso":
        from pymoo.algorithms.soo.nonconvex.pso import PSO

        return PSO(pop_size=population)
    if name == "nelder-mead":
        from pymoo.algorithms.soo.nonconvex.nelder import NelderMead

        return NelderMead()
    if name == "pattern":
        return _pattern_search()
    if name == "nsga2":
        from pymoo.algorithms.moo.nsga2 import NSGA2

        return NSGA2(pop_size=population)
    raise ValueError(f"design.algorithm: {name!r} is not a known algorithm")


def planned_generations(goals: Goals) -> int | None:
    """Generations the budget allows: ``budget // population`` for the population algorithms; None for the
    local searches (their generations are one or a few cases each)."""
    return goals.budget // goals.population if goals.algorithm in POPULATION_ALGORITHMS else None


def _fresh(goals: Goals) -> Any:
    from pymoo.core.problem import Problem
    from pymoo.core.termination import NoTermination

    d = len(goals.factors)
    problem = Problem(
        n_var=d,
        n_obj=len(goals.objectives),
        n_ieq_constr=len(goals.constraint_names),
        xl=np.zeros(d),
        xu=np.ones(d),
    )
    algorithm = make_algorithm(goals.algorithm, goals.population)
    algorithm.setup(problem, termination=NoTermination(), seed=goals.seed, verbose=False)
    return algorithm


# ---------------------------------------------------------------------------------------------- journal
class Journal:
    """An optimisation's record in a directory (a study's ``<id>.chunks/``): each evaluated generation and
    the algorithm's state after the last finished one. Files are written atomically."""

    def __init__(self, directory: str | Path):
        self.directory = Path(directory)

    def save_generation(self, g: int, arrays: dict[str, np.ndarray]) -> None:
        path = self.directory / GENERATION_FILE.format(int(g))
        with atomic_path(path) as tmp, open(tmp, "wb") as f:
            np.savez(f, **{k: np.asarray(v) for k, v in arrays.items()})  # type: ignore[arg-type]

    def load_generations(self) -> dict[int, dict[str, np.ndarray]]:
        out: dict[int, dict[str, np.ndarray]] = {}
        for path in self.directory.glob(GENERATION_FILE.format("*")):
            g = path.stem.removeprefix("generation-")
            if not g.isdigit():
                continue
            try:
                with np.load(path, allow_pickle=False) as z:
                    arrays = {name: z[name] for name in z.files}
                missing = {"u", "x", "F", "G"} - set(arrays)
                if missing:
                    raise KeyError(f"no {', '.join(sorted(missing))}")
                out[int(g)] = arrays
            except (OSError, ValueError, KeyError) as err:  # damaged, or not plain arrays: run it again
                log.warning("generation file %s does not load as arrays (%s): its cases run again", path, err)
        return out

    def drop_generations(self, start: int) -> None:
        """Remove the saved generations from ``start`` on (they no longer follow from the state)."""
        for g in [g for g in self.load_generations() if g >= start]:
            with contextlib.suppress(FileNotFoundError):
                (self.directory / GENERATION_FILE.format(g)).unlink()

    def discard_legacy_state(self) -> bool:
        """Remove a pickled algorithm state an older version saved, without reading it (a pickle runs code
        when loaded; the state is rebuilt by replaying the saved generations instead). True if there was
        one."""
        path = self.directory / LEGACY_STATE_FILE
        if not path.exists() and not path.is_symlink():
            return False
        log.warning(
            "optimiser state %s is a pickle: removed unread, the saved generations are replayed", path
        )
        with contextlib.suppress(FileNotFoundError):
            path.unlink()
        return True


# ------------------------------------------------------------------------------------------------- loop
@dataclass
class Outcome:
    """What :func:`optimise` did.

    Attributes:
        generations: the arrays of each evaluated generation, in order (``u`` unit-box values, ``x`` SI
            values (n, parameters), ``F``, ``G`` and whatever the evaluation returned).
        cancelled: it stopped because ``cancel`` was set (the finished generations are kept).
        replayed: generations taken from the journal without evaluating them again (0 for a fresh start).
    """

    generations: list[dict[str, np.ndarray]] = field(default_factory=list)
    cancelled: bool = False
    replayed: int = 0
    stalled: bool = False
    """It stopped before the budget: the best feasible objective stopped improving (:func:`stalled`)."""

    @property
    def n_cases(self) -> int:
        return int(sum(len(g["u"]) for g in self.generations))


def _sanitised(arrays: dict[str, np.ndarray], n: int, goals: Goals) -> dict[str, np.ndarray]:
    """``F`` and ``G`` as (n, k) float64, non-finite rows replaced by the penalty (never NaN to pymoo)."""
    F = np.asarray(arrays["F"], dtype=np.float64).reshape(n, len(goals.objectives))
    G = np.asarray(arrays["G"], dtype=np.float64).reshape(n, len(goals.constraint_names))
    bad = ~np.isfinite(F).all(axis=1) | ~np.isfinite(G).all(axis=1)
    F, G = F.copy(), G.copy()
    F[bad], G[bad] = PENALTY, PENALTY
    return {**arrays, "F": F, "G": G}


def optimise(
    goals: Goals,
    evaluate: Evaluate,
    journal: Journal | None = None,
    cancel: threading.Event | None = None,
    on_generation: Callable[[int, int], None] | None = None,
) -> Outcome:
    """Run the ask-and-tell loop of ``goals`` until the next generation would exceed the budget.

    Args:
        goals: the optimize design (:func:`studies.questions.goals.plan_goals`).
        evaluate: runs one generation's cases (see :data:`Evaluate`).
        journal: where generations are saved and replayed from on a resume (None: nowhere).
        cancel: set it to stop after (or, through ``evaluate``, during) the running generation.
        on_generation: called as ``on_generation(finished_generations, evaluated_cases)``.
    """
    from pymoo.core.population import Population

    names = [f.name for f in goals.factors]
    if journal is not None:
        journal.discard_legacy_state()
    saved = journal.load_generations() if journal is not None else {}
    outcome = Outcome()
    algorithm = _fresh(goals)
    g, evaluated = 0, 0
    while True:
        if cancel is not None and cancel.is_set():
            outcome.cancelled = True
            break
        pop = algorithm.ask()
        batch = pop if isinstance(pop, Population) else Population.create(pop)
        U = np.asarray(batch.get("X"), dtype=np.float64).reshape(len(batch), len(names))
        if len(U) == 0 or evaluated + len(U) > goals.budget:
            break
        old = saved.get(g)
        if old is not None and old["u"].shape == U.shape and np.array_equal(old["u"], U):
            arrays = old  # evaluated before an interruption
            outcome.replayed += 1
        else:
            if old is not None and journal is not None:  # saved cases that no longer follow: run anew
                journal.drop_generations(g)
                saved = {k: v for k, v in saved.items() if k < g}
            x = np.stack([f.from_unit(U[:, j]) for j, f in enumerate(goals.factors)], axis=1)
            got = evaluate(g, {n: x[:, j] for j, n in enumerate(names)})
            if got is None:
                outcome.cancelled = True
                return outcome
            arrays = _sanitised({**got, "u": U, "x": x}, len(U), goals)
            if journal is not None:
                journal.save_generation(g, arrays)
        batch.set("F", arrays["F"], "G", arrays["G"])
        algorithm.tell(infills=pop)
        outcome.generations.append(arrays)
        g, evaluated = g + 1, evaluated + len(U)
        if on_generation is not None:
            on_generation(g, evaluated)
        if goals.stall is not None and stalled(
            [a["F"] for a in outcome.generations], [a["G"] for a in outcome.generations], goals.stall
        ):
            outcome.stalled = True
            break
    return outcome


def stalled(F: list[np.ndarray], G: list[np.ndarray], generations: int) -> bool:
    """Whether each of the last ``generations`` generations (``F``, ``G`` per generation) improved the best
    feasible first objective so far by less than :data:`STALL_IMPROVEMENT` of it (a generation that finds
    the first feasible case improves it)."""
    best = np.inf
    quiet = 0
    for f, g in zip(F, G, strict=True):
        ok = (np.asarray(g) <= 0.0).all(axis=1)
        now = min(best, float(np.min(np.asarray(f)[ok, 0]))) if ok.any() else best
        improved = np.isfinite(now) and (not np.isfinite(best) or best - now > STALL_IMPROVEMENT * abs(best))
        quiet = 0 if improved else quiet + 1
        best = now
    return quiet >= generations


# --------------------------------------------------------------------------------------------- optimum
def non_dominated(F: np.ndarray) -> np.ndarray:
    """(n,) bool: the rows of ``F`` (n, objectives; lower is better) that no other row dominates (no worse
    in every objective and better in one). Equal rows do not dominate each other."""
    F = np.asarray(F, dtype=np.float64)
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
    out["generation"] = xr.Variable(
        "case", np.asarray(generation, dtype=np.int32), {"units": "1", "long_name": "optimiser generation"}
    )
    out["feasible"] = xr.Variable(
        "case",
        feasible,
        {"units": "1", "long_name": "the case ended ok and meets every constraint of the design", **flags},
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
    outcome: Outcome,
    goals: Goals,
    *,
    isolator_names: list[str],
    point_names: list[str],
    criteria: Any = None,
    attrs: dict[str, Any] | None = None,
) -> xr.Dataset:
    """The dataset of every case an optimisation evaluated (see the module docstring), from the arrays of
    its generations (each holding ``x``, ``F``, ``G`` and the cases' result arrays)."""
    gens = outcome.generations
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
    G = np.concatenate([a["G"] for a in gens]) if gens else np.zeros((0, len(goals.constraint_names)))
    generation = np.repeat(np.arange(len(gens)), sizes)
    out = mark_optimum(ds, F, G, generation, goals)
    summary = json.loads(out.attrs["optimisation"])
    summary["stopped"] = "stalled" if outcome.stalled else ("cancelled" if outcome.cancelled else "budget")
    summary["stall"] = goals.stall
    out.attrs["optimisation"] = json.dumps(summary)
    return out


# ------------------------------------------------------------------------------------------ the runner
def run_optimisation(
    study: Study,
    run_json: str,
    store: Store,
    client: Any,
    study_id: str,
    model_attrs: dict[str, Any],
    workers: int,
    progress: Callable[[int, int], None] | None = None,
    cancel: threading.Event | None = None,
) -> str:
    """Run an optimize study whose catalog row is ``running`` and store its dataset; returns the study id.

    :func:`studies.run.runner.run_study` calls it for an optimize design once the model is resolved: the row,
    its status and any failure are the runner's (which marks the row failed if this raises).

    Args:
        study: the :class:`studies.inputs.study.Study` (its ``goals`` set).
        run_json: the study's definition with the model it runs at (an accuracy request resolved).
        store: the study store; the journal lives in the study's chunk directory.
        client: the Dask client.
        study_id: the study's catalog row.
        model_attrs: dataset attributes of the model (engine version, fidelity, integrator, step...).
        workers: Dask worker threads (for the chunk size).
        progress: called as ``progress(evaluated_cases, budget)``.
        cancel: set it to stop; finished generations stay saved, the row goes ``cancelled``.

    The row's ``n_cases`` is the budget while it runs and the cases evaluated once done; ``n_done`` and
    ``n_failed`` follow the chunks, ``generation``/``generations`` the finished and planned generations.
    """
    from isolab.studies.inputs.study import study_from_json, study_labels
    from isolab.studies.results.store import utc_now
    from isolab.studies.run.costs import estimate_seconds_per_case
    from isolab.studies.run.fanout import choose_chunk_size, plan_chunks, run_chunks

    goals = study.goals
    if goals is None:
        raise ValueError(f"study {study_id}: its design is not optimize (no goals)")
    store.update(study_id, n_cases=goals.budget, generations=planned_generations(goals))
    base = {k: v for k, v in json.loads(run_json).items() if k not in ("design", "design_spec")}
    checks = study.design()
    first = study_from_json(json.dumps({**base, "design": _list_design(checks.values, checks.names)}))
    seconds_per_case = estimate_seconds_per_case(first)
    iso_names, point_names = study_labels(study)
    counts = {"done": 0, "failed": 0}
    key_prefix = f"isolab-{study_id}"

    def evaluate(g: int, values: dict[str, np.ndarray]) -> dict[str, np.ndarray] | None:
        names = list(values)
        n = len(values[names[0]])
        gen_json = json.dumps({**base, "design": _list_design(values, names)})
        run = study_from_json(gen_json)
        chunks = plan_chunks(n, choose_chunk_size(n, workers, seconds_per_case))
        parts: dict[int, dict[str, np.ndarray]] = {}
        before = dict(counts)

        def on_chunk(k: int, arrays: dict[str, np.ndarray]) -> None:
            parts[k] = arrays
            done = sum(len(chunks[j]) for j in parts)
            failed = sum(int(np.count_nonzero(np.asarray(a["status"]) != 0)) for a in parts.values())
            store.update(study_id, n_done=before["done"] + done, n_failed=before["failed"] + failed)

        def generation_progress(done: int, _total: int) -> None:
            if progress is not None:
                progress(before["done"] + done, goals.budget)

        report = run_chunks(
            client,
            gen_json,
            chunks,
            on_chunk=on_chunk,
            progress=generation_progress,
            cancel=cancel,
            key_prefix=f"{key_prefix}-g{g}",
        )
        if report.cancelled:
            return None
        result = from_chunks(parts, chunks, n_isolators=len(iso_names), n_points=len(point_names))
        ds = to_dataset(result, run.design(), isolator_names=iso_names, point_names=point_names)
        F, G = goal_values(add_criteria(ds, run.criteria), goals)
        arrays = result_arrays(result)
        counts["done"] += n
        counts["failed"] += int(np.count_nonzero(arrays["status"] != 0))
        return {**arrays, "F": F, "G": G}

    def on_generation(g: int, evaluated: int) -> None:
        counts["done"] = evaluated
        store.update(study_id, generation=g, n_done=evaluated)

    journal = Journal(store.chunk_dir(study_id))
    journal.directory.mkdir(parents=True, exist_ok=True)
    outcome = optimise(goals, evaluate, journal, cancel, on_generation)
    done = outcome.n_cases
    failed = int(sum(np.count_nonzero(np.asarray(a["status"]) != 0) for a in outcome.generations))
    if outcome.replayed:
        log.info("study %s: resumed, %d generations replayed from the store", study_id, outcome.replayed)
    if outcome.cancelled:
        store.update(study_id, status="cancelled", finished=utc_now(), n_done=done, n_failed=failed)
        return study_id
    attrs = {
        "title": f"isolab study {study.name}",
        "study": json.dumps(study.model_dump(mode="json")),
        "study_id": study_id,
        "design": {
            "type": "optimize",
            "seed": goals.seed,
            "budget": goals.budget,
            "population": goals.population,
            "algorithm": goals.algorithm,
        },
        **model_attrs,
    }
    labels = {"isolator_names": iso_names, "point_names": point_names}
    ds = optimum_dataset(outcome, goals, **labels, criteria=study.criteria, attrs=attrs)
    store.write_dataset(study_id, ds)
    store.clear_chunks(study_id)
    n_gen = len(outcome.generations)
    fields = {"finished": utc_now(), "n_done": done, "n_cases": done, "n_failed": failed}
    fields.update(generation=n_gen, generations=n_gen)
    if done and failed >= done:
        store.update(study_id, status="failed", error="every case failed", **fields)
    else:
        store.update(study_id, status="done", **fields)
    return study_id


def _list_design(values: dict[str, np.ndarray], names: list[str]) -> dict[str, Any]:
    """A list design of the cases ``values`` (parameter name -> SI values), as a definition's block."""
    n = len(values[names[0]]) if names else 0
    return {"type": "list", "cases": [{k: float(values[k][i]) for k in names} for i in range(n)]}


def describe_optimum(ds: xr.Dataset) -> list[str]:
    """Lines that report an optimisation's dataset: algorithm and cases, the best case with its parameter
    values and objectives (empty for a dataset that is not an optimisation's)."""
    if "optimisation" not in ds.attrs:
        return []
    s = json.loads(ds.attrs["optimisation"])
    lines = [
        f"{s['algorithm']}: {s['generations']} generations, {s['n_cases']} cases, "
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
