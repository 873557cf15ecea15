"""Robust optimisation: every candidate judged on its tolerance cloud, not on its nominal case.

An optimize design with a ``robust`` block (``robust: {samples: N, require: 95 %, statistic: mean}``,
read by :func:`studies.questions.goals.plan_robust`) runs each candidate the optimiser asks for as N + 1
cases (:meth:`CloudPlan.cases`): its nominal case and N draws of the study's tolerances about it. The
draws map the same N points of the unit cube (a scrambled Sobol' sequence, or independent draws, from the
design's seed) for every candidate: common random numbers, so two candidates are compared on the same
luck, and a candidate judged twice gets the same answer. A tolerance written as a share (``10 %``) of an
optimised parameter is a share of the candidate's value; one written in units is the same for all.

:meth:`CloudPlan.judge` turns the N + 1 cases back into one row per candidate: the nominal case's outputs
(what the dataset shows for the candidate), the statistic of each objective over the draws that ended ok
(what the optimiser minimises) and the chance constraint (the share of the draws that meet every
constraint of the design must reach ``require``: :func:`studies.questions.goals.robust_values`). The rows
are plain arrays, saved in the optimisation's journal like any generation, so a resumed run replays them.
:func:`add_robustness` stores them in the dataset: ``probability_meets_criteria`` with its interval per
candidate, the failure probability of each constraint, and each objective's cloud and statistic.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from isolab.studies.quantities import output_values
from isolab.studies.questions.goals import PENALTY, Goals, robust_values
from isolab.studies.questions.tolerances import (
    CONFIDENCE,
    INTERVAL_METHOD,
    Spread,
    clopper_pearson,
    cloud,
    unit_draws,
)

if TYPE_CHECKING:
    import xarray as xr

    from isolab.studies.inputs.study import Study

ROBUST_ARRAYS = ("n_meets", "constraint_fails", "cloud", "nominal_G", "cases_failed")
"""The arrays :meth:`CloudPlan.judge` adds to a generation's, per candidate."""


@dataclass(frozen=True)
class CloudPlan:
    """How a robust design's candidates are judged: its goals, the spreads and the common unit-cube points.

    Attributes:
        goals: the optimize design (``goals.robust`` set).
        spreads: the tolerances (:meth:`studies.inputs.study.Study.spreads`), an optimised parameter's
            re-centred on each candidate.
        unit: (N, len(spreads)) points of the unit cube every candidate's draws map from.
    """

    goals: Goals
    spreads: tuple[Spread, ...]
    unit: np.ndarray

    @classmethod
    def of(cls, study: Study) -> CloudPlan | None:
        """The plan of a robust optimize study; None for any other study."""
        goals = study.goals
        if goals is None or goals.robust is None:
            return None
        spreads = tuple(study.spreads)
        r = goals.robust
        return cls(goals, spreads, unit_draws(r.samples, len(spreads), goals.seed, r.sampling))

    @property
    def samples(self) -> int:
        return int(len(self.unit))

    def definition(self, base: dict[str, Any]) -> dict[str, Any]:
        """``base`` (a study definition without its design) with a parameter for each tolerance path no
        optimised parameter sets, so a list design of :meth:`cases` can set it."""
        optimised = {f.name for f in self.goals.factors}
        extra = [{"name": s.name, "path": s.path} for s in self.spreads if s.name not in optimised]
        return {**base, "parameters": [*base.get("parameters", []), *extra]}

    def cases(self, values: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The cases of P candidates (``values``: parameter name -> (P,) SI values): for each candidate in
        turn its nominal case, then its N draws; (P (N + 1),) values per parameter and tolerance path."""
        names = list(values)
        p = len(values[names[0]]) if names else 0
        n = self.samples
        optimised = set(names)
        rows: dict[str, list[np.ndarray]] = {k: [] for k in [*names, *self._extra_names()]}
        for i in range(p):
            mine = {k: float(values[k][i]) for k in names}
            drawn = cloud(list(self.spreads), self.unit, {k: v for k, v in mine.items() if k in optimised})
            for k in names:
                rows[k].append(np.full(n + 1, mine[k]))
            for j, s in enumerate(self.spreads):
                column = np.concatenate([[mine.get(s.name, s.nominal)], drawn[:, j]])
                if s.name in optimised:
                    rows[s.name][-1] = column
                else:
                    rows[s.name].append(column)
        return {k: np.concatenate(v) if v else np.zeros(0) for k, v in rows.items()}

    def _extra_names(self) -> list[str]:
        optimised = {f.name for f in self.goals.factors}
        return [s.name for s in self.spreads if s.name not in optimised]

    def judge(self, arrays: dict[str, np.ndarray], F: np.ndarray, G: np.ndarray) -> dict[str, np.ndarray]:
        """One row per candidate from the results of :meth:`cases` (``arrays``, as
        :func:`studies.results.dataset.result_arrays`, and ``F``, ``G`` per case,
        :func:`studies.questions.goals.goal_values`): the nominal case's arrays, ``F`` and ``G`` judged on the
        draws (:func:`studies.questions.goals.robust_values`), and :data:`ROBUST_ARRAYS`: ``n_meets``
        (draws meeting every constraint), ``constraint_fails`` (draws failing each constraint column),
        ``cloud`` (P, N, objectives: each objective's value per draw, NaN where a draw did not end ok),
        ``nominal_G`` (the nominal case's constraints) and ``cases_failed`` (cases of the N + 1 that did
        not end ok)."""
        robust = self.goals.robust
        assert robust is not None  # a CloudPlan is made for a robust design only
        n = self.samples
        status = np.asarray(arrays["status"]).reshape(-1)
        p = status.size // (n + 1)
        nominal = np.arange(p) * (n + 1)
        F = np.asarray(F, dtype=np.float64).reshape(p, n + 1, -1)
        G = np.asarray(G, dtype=np.float64).reshape(p, n + 1, -1)
        Fd, Gd = F[:, 1:, :], G[:, 1:, :]
        judged_F, judged_G, meets = robust_values(Fd, Gd, robust)
        ok = Gd[..., 0] <= 0.0
        signs = np.array([1.0 if o.sense == "minimize" else -1.0 for o in self.goals.objectives])
        values = np.where(ok[..., None] & (Fd != PENALTY), Fd * signs, np.nan)
        return {
            **{k: np.asarray(v)[nominal] for k, v in arrays.items()},
            "F": judged_F,
            "G": judged_G,
            "n_meets": meets.sum(axis=1).astype(np.int64),
            "constraint_fails": (Gd > 0.0).sum(axis=1).astype(np.int64),
            "cloud": values,
            "nominal_G": G[:, 0, :],
            "cases_failed": (status.reshape(p, n + 1) != 0).sum(axis=1).astype(np.int64),
        }


def variable_name(quantity: str, kind: str) -> str:
    """The dataset variable of an objective's ``kind`` (``cloud`` or ``statistic``): ``settling_time.tool``
    -> ``settling_time_tool_cloud``."""
    return re.sub(r"\W+", "_", quantity).strip("_") + f"_{kind}"


def add_robustness(ds: xr.Dataset, generations: list[dict[str, np.ndarray]], plan: CloudPlan) -> xr.Dataset:
    """``ds`` (one case per candidate, in order) with what :meth:`CloudPlan.judge` found, per candidate:
    ``probability_meets_criteria`` (case) and its ``_interval`` (case, bound), ``constraint_failure_
    probability`` (case, constraint), ``nominal_feasible`` (case), each objective's ``<q>_cloud``
    (case, draw) and ``<q>_statistic`` (case), the common ``unit_draws`` (draw, tolerance) and the spreads
    in the ``tolerances`` attribute."""
    import xarray as xr

    goals, robust = plan.goals, plan.goals.robust
    assert robust is not None
    n = plan.samples

    def joined(key: str, tail: tuple[int, ...]) -> np.ndarray:
        parts = [np.asarray(g[key]) for g in generations]
        return np.concatenate(parts) if parts else np.zeros((0, *tail))

    k = joined("n_meets", ()).astype(np.int64)
    fails = joined("constraint_fails", (len(goals.constraint_names),))
    values = joined("cloud", (n, len(goals.objectives)))
    nominal_G = joined("nominal_G", (len(goals.constraint_names),))
    F = joined("F", (len(goals.objectives),))
    out = ds.copy()
    bound = xr.Variable("bound", np.array(["lower", "upper"]), {"units": "1", "long_name": "interval bound"})
    out = out.assign_coords(
        bound=bound,
        draw=xr.Variable("draw", np.arange(n), {"units": "1", "long_name": "draw of the tolerances"}),
        tolerance=xr.Variable(
            "tolerance",
            np.array([s.name for s in plan.spreads]),
            {"units": "1", "long_name": "toleranced input"},
        ),
        constraint=xr.Variable(
            "constraint",
            np.array(goals.constraint_names),
            {"units": "1", "long_name": "constraint of the design"},
        ),
    )
    how = f"{INTERVAL_METHOD} {CONFIDENCE:.0%} interval over the candidate's {n} draws, as if independent"
    common = {"units": "1", "confidence": CONFIDENCE, "interval_method": INTERVAL_METHOD}
    out["probability_meets_criteria"] = xr.Variable(
        "case",
        k / n,
        {
            **common,
            "long_name": "probability that the candidate, within its tolerances, meets every constraint of "
            f"the design (share of its {n} draws; a draw that did not end ok does not); feasible from "
            f"{robust.require:.3g}",
            "require": robust.require,
        },
    )
    out["probability_meets_criteria_interval"] = xr.Variable(
        ("case", "bound"),
        np.array([clopper_pearson(int(x), n) for x in k]).reshape(len(k), 2),
        {**common, "long_name": f"interval of probability_meets_criteria: {how}"},
    )
    out["constraint_failure_probability"] = xr.Variable(
        ("case", "constraint"),
        fails / n,
        {
            **common,
            "long_name": "probability that the candidate, within its tolerances, fails the constraint",
        },
    )
    flags = {"flag_values": np.array([0, 1], dtype=np.int8), "flag_meanings": "false true"}
    out["nominal_feasible"] = xr.Variable(
        "case",
        (nominal_G <= 0.0).all(axis=1),
        {"units": "1", "long_name": "the candidate as drawn (no tolerances) meets every constraint", **flags},
    )
    stat = "mean" if robust.statistic == "mean" else f"{robust.quantile:.3g} quantile"
    for j, o in enumerate(goals.objectives):
        unit = str(output_values(out, o.quantity).attrs.get("units", "1"))
        out[variable_name(o.quantity, "cloud")] = xr.Variable(
            ("case", "draw"),
            values[:, :, j],
            {
                "units": unit,
                "long_name": f"{o.quantity} of each draw of the candidate's tolerances (NaN: "
                "the draw did not end ok)",
            },
        )
        sign = 1.0 if o.sense == "minimize" else -1.0
        out[variable_name(o.quantity, "statistic")] = xr.Variable(
            "case",
            np.where(F[:, j] >= PENALTY, np.nan, sign * F[:, j]),
            {
                "units": unit,
                "long_name": f"{stat} of {o.quantity} over the candidate's draws that ended ok "
                f"(what the optimiser {o.sense}s; NaN: no draw ended ok)",
            },
        )
    out["unit_draws"] = xr.Variable(
        ("draw", "tolerance"),
        plan.unit,
        {
            "units": "1",
            "long_name": "the points of the unit cube every candidate's draws map from (common "
            "to all candidates)",
        },
    )
    out.attrs["tolerances"] = json.dumps({s.name: s.described() for s in plan.spreads})
    out.attrs["tolerance_sampling"] = robust.sampling
    return out


def describe_robustness(ds: xr.Dataset, summary: dict[str, Any]) -> list[str]:
    """Lines that report a robust optimum: how the candidates were judged and the best's probability of
    meeting the constraints with its interval (empty for an optimisation that is not robust)."""
    robust = summary.get("robust")
    b = summary.get("best_case")
    if robust is None or b is None or "probability_meets_criteria" not in ds:
        return []
    stat = "mean" if robust["statistic"] == "mean" else f"{robust['quantile']:.3g} quantile"
    p = float(ds["probability_meets_criteria"].values[b])
    lo, hi = (float(v) for v in ds["probability_meets_criteria_interval"].values[b])
    nominal = bool(ds["nominal_feasible"].values[b])
    return [
        f"  (the {stat} over {robust['samples']} draws of the tolerances, the same for every candidate)",
        f"  meets the constraints in {p:.1%} of its draws (95% interval {lo:.1%} to {hi:.1%}; required "
        f"{robust['require']:.1%}); as drawn it {'meets' if nominal else 'fails'} them",
    ]
