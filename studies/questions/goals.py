"""What an optimisation study seeks: its objectives and constraints, read from the ``design:`` block.

An ``optimize`` design names its goals as text::

    design:
      type: optimize
      objective: minimize settling_time.tool          # or a list: several objectives (Pareto front)
      constraints: [criteria, "peak_isolator_force.z <= 5 kN"]

An objective is ``minimize <quantity>`` or ``maximize <quantity>``, a quantity as
:func:`isolab.studies.quantities.output_values` reads it (``settling_time.tool``,
``peak_point_displacement.tool.z``, ``natural_frequency.1``). A constraint is the word ``criteria`` (every
criterion of the study's ``criteria:`` block is met: one constraint per criterion, its margin >= 0) or
``<quantity> <= <value>`` / ``<quantity> >= <value>`` with the value in the quantity's units (SI when
bare).

A ``robust`` block (``robust: {samples: 32, require: 95 %, statistic: mean | quantile, quantile: 90 %}``)
judges every candidate on its tolerance cloud instead of its nominal case (:mod:`studies.run.robust`):
the objective is the statistic of its draws (:func:`robust_values`) and the constraints become one chance
constraint, the share of the draws that meet every constraint at least ``require``.

:func:`plan_goals` checks the names against the outputs a study's dataset will hold, without running
anything: it reads them from the output catalogue (:data:`isolab.engine.results.OUTPUTS`) and the scene's
labels (:func:`quantity_layout`). :func:`goal_values` turns a dataset of evaluated cases into the objective
values ``F`` (to minimise) and constraint values ``G`` (met when <= 0) an optimiser takes: always finite,
with :data:`PENALTY` where a case failed or a value is missing.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from isolab.engine.results import DIMENSION_LABELS, ISOLATOR, OK, OUTPUTS, POINT
from isolab.studies.quantities import output_values, pick_quantity
from isolab.studies.questions.criteria import Criteria, judged_criteria
from isolab.studies.questions.designs import Factor
from isolab.studies.units import dimension_of, to_si

if TYPE_CHECKING:  # xarray loads where a dataset is read, not where a scene is
    import xarray as xr

CRITERIA = "criteria"
"""The constraint that every criterion of the study's ``criteria:`` block is met."""
PENALTY = 1e9
"""Objective and constraint value given to a case that failed (or whose value is missing): far worse than
any real case, and finite (an optimiser never sees NaN). Such a case is infeasible."""

SINGLE_OBJECTIVE = ("ga", "de", "pso", "nelder-mead", "pattern")
MULTI_OBJECTIVE = ("nsga2",)
ALGORITHMS = SINGLE_OBJECTIVE + MULTI_OBJECTIVE
"""The pymoo algorithms an optimize design may name (see :mod:`studies.run.optimisation`)."""
DEFAULT_POPULATION = 40
"""Cases per generation when the design does not say."""
DEFAULT_PLATEAU = 0.01
"""The plateau of an optimum when the design does not say: objective within 1 % of the best's."""
STALL_IMPROVEMENT = 1e-3
"""The smallest improvement of the best feasible objective, as a share of it, that a generation must make
not to count towards a stall (0.1 %)."""

_OBJECTIVE = re.compile(r"^\s*(minimi[sz]e|maximi[sz]e)\s+(\S+)\s*$", re.IGNORECASE)
_CONSTRAINT = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_.]*)\s*(<=|>=)\s*(.+?)\s*$")


@dataclass(frozen=True)
class Objective:
    """One objective: ``quantity`` to ``sense`` ("minimize" or "maximize")."""

    quantity: str
    sense: str

    @property
    def text(self) -> str:
        return f"{self.sense} {self.quantity}"


@dataclass(frozen=True)
class Constraint:
    """One constraint: ``quantity`` ``op`` ``bound`` (SI, in ``unit``), or the criteria block (``quantity``
    :data:`CRITERIA`, one constraint per criterion)."""

    quantity: str
    op: str = ""
    bound: float = 0.0
    unit: str = ""

    @property
    def text(self) -> str:
        if self.quantity == CRITERIA:
            return CRITERIA
        return f"{self.quantity} {self.op} {self.bound:g} {self.unit}".strip()


@dataclass(frozen=True)
class Goals:
    """An optimize design's objectives, constraints and settings, checked."""

    objectives: tuple[Objective, ...]
    constraints: tuple[Constraint, ...]
    algorithm: str
    budget: int
    population: int
    seed: int
    constraint_names: tuple[str, ...]
    """One name per column of ``G``: ``case_ok``, then each constraint (each criterion for ``criteria``)."""
    factors: tuple[Factor, ...]
    """The varied parameters, each a continuous range (the optimiser's variables, log-scaled ones in log
    space: :meth:`studies.questions.designs.Factor.from_unit`)."""
    plateau: float = DEFAULT_PLATEAU
    """The plateau answered beside the best: feasible designs whose first objective is within this share of
    the best's (1)."""
    stall: int | None = None
    """Stop once this many generations in a row improve the best feasible objective by less than
    :data:`STALL_IMPROVEMENT` (None: the budget alone stops the run)."""

    robust: Robust | None = None
    """A robust design's cloud and chance constraint (None: each candidate judged on its nominal case)."""

    @property
    def told_constraints(self) -> tuple[str, ...]:
        """The columns of ``G`` the optimiser is told: :attr:`constraint_names`, or a robust design's one
        chance constraint."""
        if self.robust is None:
            return self.constraint_names
        return (f"probability_meets_criteria >= {self.robust.require:g}",)

    @property
    def cases_per_candidate(self) -> int:
        """Cases simulated per candidate: 1, or a robust design's nominal case and its draws."""
        return 1 if self.robust is None else self.robust.samples + 1


STATISTICS = ("mean", "quantile")
"""What a robust design minimises over each candidate's cloud."""


@dataclass(frozen=True)
class Robust:
    """A robust design: each candidate judged on ``samples`` draws of its tolerances, the same unit-cube
    points for every candidate (common random numbers, drawn by ``sampling`` from the design's seed).

    Attributes:
        samples: draws per candidate.
        require: the least share of the draws that must meet every constraint (the chance constraint, 1).
        statistic: ``mean`` or ``quantile`` of each objective over the draws that ended ok.
        quantile: the share (1) of the quantile statistic: of the value to minimise, so ``maximize`` with
            quantile 0.9 is the value 90 % of the draws reach or exceed.
        sampling: ``sobol`` (scrambled Sobol' points) or ``random``.
    """

    samples: int
    require: float
    statistic: str = "mean"
    quantile: float = 0.9
    sampling: str = "sobol"

    @property
    def text(self) -> str:
        stat = "mean" if self.statistic == "mean" else f"{self.quantile:.3g} quantile"
        return (
            f"{stat} over {self.samples} draws, probability of meeting the constraints >= {self.require:.3g}"
        )

    def described(self) -> dict[str, Any]:
        out: dict[str, Any] = {"samples": self.samples, "require": self.require, "statistic": self.statistic}
        if self.statistic == "quantile":
            out["quantile"] = self.quantile
        return {**out, "sampling": self.sampling}


def _share(value: Any, where: str, *, low_open: bool, high_closed: bool) -> float:
    """A share written as a fraction or with ``%``, in (0, 1] or (0, 1)."""
    share = float(f"{to_si(value, 'dimensionless', where):.12g}")  # 95 % is 0.95, not 0.9500000000000001
    if not (0.0 < share < 1.0 or (high_closed and share == 1.0)) or (not low_open and share == 0.0):
        upper = "100 %" if high_closed else "below 100 %"
        raise ValueError(f"{where}: a share above 0 and up to {upper} (e.g. 95 % or 0.95), got {value!r}")
    return float(share)


def plan_robust(spec: Any, constraints: tuple[Constraint, ...]) -> Robust:
    """The :class:`Robust` of a design's ``robust`` block (:class:`studies.inputs.schema.RobustSpec`).

    Raises:
        ValueError: ``design.robust.<field>: reason``, or ``design.constraints`` when there is nothing for
            the chance constraint to hold.
    """
    if not constraints:
        raise ValueError(
            "design.constraints: a robust design's chance constraint is the probability of meeting the "
            "design's constraints; give at least one (e.g. constraints: [criteria])"
        )
    require = _share(spec.require, "design.robust.require", low_open=True, high_closed=True)
    if spec.statistic != "quantile" and spec.quantile is not None:
        raise ValueError("design.robust.quantile: only statistic: quantile takes it")
    quantile = 0.9
    if spec.quantile is not None:
        quantile = _share(spec.quantile, "design.robust.quantile", low_open=True, high_closed=False)
    return Robust(int(spec.samples), require, spec.statistic, quantile, spec.sampling)


def robust_values(F: np.ndarray, G: np.ndarray, robust: Robust) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Candidates judged on their clouds: ``F`` (P, N, objectives) and ``G`` (P, N, constraints) of each
    candidate's N draws (:func:`goal_values`, column 0 the case's own ``case_ok``) -> ``(F, G, meets)``.

    ``F`` (P, objectives): the statistic (``robust.statistic``) of each objective over the draws that ended
    ok, :data:`PENALTY` when none did. ``G`` (P, 1): ``(require - p) / require``, p the share of the N
    draws that meet every constraint (a draw that failed meets none): met (<= 0) when p >= require.
    ``meets`` (P, N): which draws meet every constraint.
    """
    F = np.asarray(F, dtype=np.float64)
    G = np.asarray(G, dtype=np.float64)
    ok = G[..., 0] <= 0.0
    meets = (G <= 0.0).all(axis=2)
    p = meets.mean(axis=1)
    values = np.where(ok[..., None], F, np.nan)
    stat = np.full((F.shape[0], F.shape[2]), PENALTY)
    some = ok.any(axis=1)
    if some.any():
        if robust.statistic == "mean":
            stat[some] = np.nanmean(values[some], axis=1)
        else:
            stat[some] = np.nanquantile(values[some], robust.quantile, axis=1)
    chance = np.asarray((robust.require - p) / robust.require, dtype=np.float64)[:, None]
    return stat, chance, np.asarray(meets, dtype=bool)


QuantityLayout = dict[str, dict[str, list[str]]]
"""The quantities a study's dataset holds: name -> its dimensions after the case's -> their labels."""


def quantity_layout(
    isolator_names: list[str], point_names: list[str], criteria: Criteria | None = None
) -> QuantityLayout:
    """The quantities a study's dataset will hold, in its order, without building it: the catalogue's
    outputs (:data:`isolab.engine.results.OUTPUTS`) over the scene's isolators and points, then, for a
    study with criteria, ``criterion_margin`` (one per criterion) and ``meets_criteria``
    (:func:`studies.questions.criteria.add_criteria`)."""
    labels = {
        **{d: [str(v) for v in values] for d, values in DIMENSION_LABELS.items()},
        ISOLATOR: [str(n) for n in isolator_names],
        POINT: [str(n) for n in point_names],
    }
    layout = {name: {d: labels[d] for d in spec.dims} for name, spec in OUTPUTS.items()}
    judged = judged_criteria(criteria) if criteria is not None else []
    if judged:
        layout["criterion_margin"] = {"criterion": [c.name for c in judged]}
        layout["meets_criteria"] = {}
    return layout


def quantity_unit(layout: QuantityLayout, quantity: str) -> str:
    """The SI unit of the quantity ``quantity`` (``"1"`` for a dimensionless one or a yes/no).

    Raises:
        ValueError: an unknown variable or label, naming ``quantity`` and the valid choices
            (:func:`studies.quantities.pick_quantity`).
    """
    name, _, _ = pick_quantity(quantity, list(layout), layout.__getitem__)
    return OUTPUTS[name].unit if name in OUTPUTS else "1"


def _objectives(spec: Any, layout: QuantityLayout) -> tuple[Objective, ...]:
    given = spec.objective
    if given is None:
        raise ValueError(
            "design.objective: an optimize design needs an objective, e.g. 'minimize settling_time.tool'"
        )
    texts = [given] if isinstance(given, str) else list(given)
    if not texts:
        raise ValueError("design.objective: give at least one objective")
    out = []
    for i, text in enumerate(texts):
        where = "design.objective" if isinstance(given, str) else f"design.objective[{i}]"
        m = _OBJECTIVE.match(str(text))
        if m is None:
            raise ValueError(
                f"{where}: {text!r} is not 'minimize <quantity>' or 'maximize <quantity>' "
                "(e.g. 'minimize settling_time.tool')"
            )
        sense = "minimize" if m.group(1).lower().startswith("min") else "maximize"
        try:
            quantity_unit(layout, m.group(2))
        except ValueError as err:
            raise ValueError(f"{where}: {err}") from None
        out.append(Objective(m.group(2), sense))
    return tuple(out)


def _constraints(spec: Any, layout: QuantityLayout, criteria: Criteria | None) -> tuple[Constraint, ...]:
    out = []
    for i, text in enumerate(spec.constraints or []):
        where = f"design.constraints[{i}]"
        if str(text).strip() == CRITERIA:
            if criteria is None or not judged_criteria(criteria):
                raise ValueError(
                    f"{where}: 'criteria' constrains the cases to meet the study's criteria, but neither "
                    "the study nor its scene has a criteria block (e.g. criteria: {isolators: "
                    "{no_liftoff: true}})"
                )
            out.append(Constraint(CRITERIA))
            continue
        m = _CONSTRAINT.match(str(text))
        if m is None:
            raise ValueError(
                f"{where}: {text!r} is not 'criteria', '<quantity> <= <value>' or '<quantity> >= <value>' "
                "(e.g. 'min_isolator_load >= 0 N')"
            )
        quantity, op, value = m.groups()
        try:
            unit = quantity_unit(layout, quantity)
        except ValueError as err:
            raise ValueError(f"{where}: {err}") from None
        dimension = dimension_of(unit)
        if dimension is None:
            try:
                bound = float(value)
            except ValueError:
                raise ValueError(
                    f"{where}: give the bound of {quantity} in SI ({unit}), got {value!r}"
                ) from None
        else:
            bound = to_si(value.strip(), dimension, where)
        out.append(Constraint(quantity, op, bound, "" if unit == "1" else unit))
    return tuple(out)


def plan_goals(
    spec: Any,
    factors: list[Factor],
    isolator_names: list[str],
    point_names: list[str],
    criteria: Criteria | None = None,
) -> Goals:
    """Check an optimize design block (``spec``, a :class:`studies.inputs.schema.DesignSpec`) against the
    study's
    parameters (``factors``), its scene's labels and its criteria; nothing runs.

    Raises:
        ValueError: ``design.<field>: reason`` (``design.objective``, ``design.constraints[1]``,
            ``design.algorithm``, ``design.budget``, ``design.population``) or ``parameters[i]...: reason``
            for a parameter an optimiser cannot vary, listing the valid choices.
    """
    for i, f in enumerate(factors):
        if f.levels is not None:
            kind = "categorical" if f.categorical else "a list of values"
            raise ValueError(
                f"parameters[{i}].values: {f.name} ({f.path}) is {kind}; an optimize design varies "
                "continuous ranges only: give it a range (start, stop), or fix it in the scene"
            )
        if f.low == f.high:
            raise ValueError(f"parameters[{i}].range: {f.name}'s range is empty (start == stop)")
    if not factors:
        raise ValueError("parameters: an optimize design needs at least one parameter with a range")
    layout = quantity_layout(isolator_names, point_names, criteria)
    objectives = _objectives(spec, layout)
    constraints = _constraints(spec, layout, criteria)
    algorithm = (spec.algorithm or ("ga" if len(objectives) == 1 else "nsga2")).strip().lower()
    if algorithm not in ALGORITHMS:
        raise ValueError(f"design.algorithm: {spec.algorithm!r} is not one of {', '.join(ALGORITHMS)}")
    if len(objectives) > 1 and algorithm not in MULTI_OBJECTIVE:
        raise ValueError(
            f"design.algorithm: {algorithm} optimises one objective, the design has {len(objectives)}; "
            f"use {' or '.join(MULTI_OBJECTIVE)}"
        )
    if spec.budget is None:
        raise ValueError("design.budget: an optimize design needs its budget (the total number of cases)")
    population = int(spec.population or min(DEFAULT_POPULATION, spec.budget))
    if population > spec.budget:
        raise ValueError(
            f"design.population: {population} cases per generation exceed the budget of {spec.budget} cases"
        )
    plateau = DEFAULT_PLATEAU
    if spec.plateau is not None:
        plateau = to_si(spec.plateau, "dimensionless", "design.plateau")
        if not 0.0 <= plateau <= 1.0:
            raise ValueError(f"design.plateau: must be from 0 to 100 %, got {spec.plateau!r}")
    names = ["case_ok"]
    for c in constraints:
        if c.quantity == CRITERIA and criteria is not None:  # checked above: the study has criteria
            names += [f"criterion {n}" for n in criteria.names()]
        else:
            names.append(c.text)
    return Goals(
        objectives,
        constraints,
        algorithm,
        int(spec.budget),
        population,
        int(spec.seed),
        tuple(names),
        tuple(factors),
        float(plateau),
        None if spec.stall is None else int(spec.stall),
        None if spec.robust is None else plan_robust(spec.robust, constraints),
    )


def goal_values(ds: xr.Dataset, goals: Goals) -> tuple[np.ndarray, np.ndarray]:
    """``(F, G)`` of the cases of a sampled dataset (``case`` dimension) that carries the criteria when
    the goals constrain them (:func:`studies.questions.criteria.add_criteria`).

    ``F`` is (n, objectives): the objective values, negated for ``maximize``, in their SI units. ``G`` is
    (n, constraints): met where <= 0: first 0 for a case that ended ``ok`` (else :data:`PENALTY`), then
    per constraint ``-margin`` for each criterion and ``(value - bound) / scale`` (``<=``) or
    ``(bound - value) / scale`` (``>=``) with ``scale = |bound|`` (1 SI unit for a zero bound). A failed case
    or a missing value gets :data:`PENALTY` in every column: finite, and infeasible.
    """
    ok = np.asarray(ds["status"].values).reshape(-1) == OK
    n = ok.size
    cols_f = []
    for obj in goals.objectives:
        v = np.asarray(output_values(ds, obj.quantity).values, dtype=np.float64).reshape(n)
        cols_f.append(v if obj.sense == "minimize" else -v)
    cols_g = [np.where(ok, 0.0, PENALTY)]
    for c in goals.constraints:
        if c.quantity == CRITERIA:
            margin = ds["criterion_margin"].transpose("case", "criterion").values
            margin = np.asarray(margin, dtype=np.float64)
            cols_g += [-margin[:, j] for j in range(margin.shape[1])]
            continue
        v = np.asarray(output_values(ds, c.quantity).values, dtype=np.float64).reshape(n)
        scale = abs(c.bound) if c.bound != 0.0 else 1.0
        cols_g.append((v - c.bound) / scale if c.op == "<=" else (c.bound - v) / scale)
    F = np.stack(cols_f, axis=1)
    G = np.stack(cols_g, axis=1)
    bad = ~ok | ~np.isfinite(F).all(axis=1) | ~np.isfinite(G).all(axis=1)
    F[bad] = PENALTY
    G[bad] = PENALTY
    return F, G
