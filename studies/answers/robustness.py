"""How likely each isolator type, built within the scene's tolerances, is to meet the design criteria; and
the recommendation on that probability.

A comparison judges each type as drawn. When the scene carries a ``tolerances:`` block
(:mod:`isolab.studies.questions.tolerances`), each type is also judged as built: ``samples`` machines are
drawn independently from the tolerances about that type's figures (its preset, or its tuning), each is
run through the engine with the comparison's simulation block, and the share that meets every criterion
is the type's probability, with its Clopper-Pearson interval (exact binomial tails: the draws are
independent, ``sampling: random``). Every type is judged on the same draws of the unit cube (common random
numbers), so a difference between types is the types', not the draws'.

The recommendation on it (:func:`recommend_on_probability`): of the types whose probability reaches the
required one (default :data:`DEFAULT_REQUIRE`), the one with the highest probability; types that tie on it
are separated by their smallest nominal margin, the largest winning.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from isolab.engine import simulate
from isolab.studies.inputs.definitions import DefinitionError, check_definition, detail
from isolab.studies.inputs.study import Study, study_labels
from isolab.studies.questions.criteria import add_criteria
from isolab.studies.questions.tolerances import CONFIDENCE, INTERVAL_METHOD, clopper_pearson, meets_counts
from isolab.studies.results.dataset import to_dataset

if TYPE_CHECKING:
    import xarray as xr

DEFAULT_SAMPLES = 200
"""Machines drawn from the tolerances per type and design, unless asked otherwise."""
DEFAULT_REQUIRE = 0.95
"""The probability of meeting every criterion a recommended type must reach, unless asked otherwise."""
MAX_SAMPLES = 2000
"""Most machines a comparison draws per type and design."""
SAMPLING = "random"
"""Independent draws: the Clopper-Pearson interval then holds as stated."""


def robust_request(samples: int | None, require: float | None) -> tuple[int, float]:
    """A request's number of machines to draw per design and its required probability of meeting every
    criterion (1), defaults filled in.

    Raises:
        DefinitionError: naming ``samples`` (1 to :data:`MAX_SAMPLES`) or ``require`` (in (0, 1]).
    """
    samples = DEFAULT_SAMPLES if samples is None else samples
    require = DEFAULT_REQUIRE if require is None else require
    if not 1 <= samples <= MAX_SAMPLES:
        raise DefinitionError(
            [detail(["body", "samples"], f"draw 1 to {MAX_SAMPLES} machines, got {samples}")]
        )
    if not (math.isfinite(require) and 0.0 < require <= 1.0):
        raise DefinitionError([detail(["body", "require"], f"a probability in (0, 1], got {require}")])
    return samples, require


@dataclass
class Reliability:
    """One type's chance of meeting every criterion when built within the tolerances.

    Attributes:
        isolator_type: the type judged.
        design: ``nominal`` (the type's own figures) or ``tuned`` (the tuning found for it).
        meeting: drawn machines that meet every criterion (a case that did not end ok does not).
        cases: machines drawn.
        probability: ``meeting / cases`` (1).
        interval: its Clopper-Pearson interval at :data:`CONFIDENCE` (lower, upper; 1).
        failure_probability: criterion -> share of the machines that fail it (1).
    """

    isolator_type: str
    design: str
    meeting: int
    cases: int
    probability: float
    interval: tuple[float, float]
    failure_probability: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able: probability, interval [lower, upper], meeting, cases, failure_probability."""
        return {
            "probability": self.probability,
            "interval": list(self.interval),
            "meeting": self.meeting,
            "cases": self.cases,
            "failure_probability": dict(self.failure_probability),
        }

    @classmethod
    def from_dict(cls, isolator_type: str, design: str, data: dict[str, Any]) -> Reliability:
        """A reliability from its :meth:`to_dict`."""
        lo, hi = data["interval"]
        return cls(
            isolator_type,
            design,
            int(data["meeting"]),
            int(data["cases"]),
            float(data["probability"]),
            (float(lo), float(hi)),
            dict(data["failure_probability"]),
        )

    def text(self) -> str:
        """``98.0 % (95 % interval 96.1-99.1 %)``."""
        lo, hi = self.interval
        return f"{self.probability:.1%} ({CONFIDENCE:.0%} interval {lo:.1%}-{hi:.1%})"


def has_tolerances(scene: dict[str, Any]) -> bool:
    """Whether a scene (as data) carries a non-empty ``tolerances:`` block."""
    return bool(scene.get("tolerances"))


def tolerance_study(
    scene: dict[str, Any],
    isolator_type: str,
    simulation: Any,
    samples: int = DEFAULT_SAMPLES,
    seed: int = 0,
    prefix: list[str | int] | None = None,
    choice: str = "preset",
) -> Study:
    """The monte_carlo study of ``scene`` (as data, with its tolerances) on ``isolator_type``: ``samples``
    machines drawn independently about that type's figures (its preset with the scene's tuning of it).
    With ``choice="model"``, ``isolator_type`` is a product of the scene's catalogue and the machines are
    drawn about the product's figures.

    Raises:
        DefinitionError: naming the field under ``prefix`` (default ``["body"]``): a tolerance that cannot
            be drawn (an unknown path, a choice, a spread that is not positive...).
    """
    s = copy.deepcopy(scene)
    iso = s.setdefault("isolators", {})
    if choice == "model":  # the product decides the type
        iso.pop("preset", None)
    iso[choice] = isolator_type
    body: dict[str, Any] = {
        "name": f"tolerances-{isolator_type}",
        "scene": s,
        "design": {"type": "monte_carlo", "samples": int(samples), "seed": int(seed), "sampling": SAMPLING},
    }
    if simulation is not None:
        body["simulation"] = simulation
    return check_definition(body, prefix=["body"] if prefix is None else list(prefix))


def judged_dataset(study: Study) -> xr.Dataset:
    """Every case of ``study`` run through the engine in one batch, in this process, as its labelled
    dataset with the criteria's margins: how a comparison, a tuning, a sizing and a tolerance cloud are
    judged.

    Raises:
        ValueError: a scene the engine refuses.
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
    ds = to_dataset(result, study.design(), isolator_names=iso, point_names=pts)
    return add_criteria(ds, study.criteria)


def reliability(study: Study, isolator_type: str, design: str) -> Reliability:
    """Run a :func:`tolerance_study` through the engine and count the machines that meet the criteria.

    Raises:
        ValueError: a scene the engine refuses.
    """
    k, n, fails, names = meets_counts(judged_dataset(study))
    return Reliability(
        isolator_type,
        design,
        k,
        n,
        k / n if n else math.nan,
        clopper_pearson(k, n, CONFIDENCE),
        {c: float(f) / n for c, f in zip(names, fails, strict=True)} if n else {},
    )


def type_reliabilities(
    scene: dict[str, Any],
    isolator_types: list[str],
    simulation: Any,
    design: str,
    samples: int = DEFAULT_SAMPLES,
    seed: int = 0,
    choice: str = "preset",
) -> dict[str, Reliability]:
    """:func:`reliability` of each type of ``isolator_types`` on ``scene`` (the same draws for each;
    ``choice="model"``: each a product of the scene's catalogue).

    Raises:
        DefinitionError: as :func:`tolerance_study`.
        ValueError: as :func:`reliability`.
    """
    return {
        t: reliability(tolerance_study(scene, t, simulation, samples, seed, choice=choice), t, design)
        for t in isolator_types
    }


def smallest_margin(row: dict[str, Any], criteria: list[str]) -> float:
    """The smallest of a comparison row's ``margin_<criterion>`` (1); -inf when one is unknown."""
    values = [row.get(f"margin_{c}") for c in criteria]
    known = [float(v) for v in values if v is not None and math.isfinite(float(v))]
    return min(known) if len(known) == len(criteria) and known else -math.inf


def recommend_on_probability(
    rows: dict[str, dict[str, Any]],
    criteria: list[str],
    judged: dict[str, Reliability],
    require: float = DEFAULT_REQUIRE,
    cost_order: list[str] | None = None,
) -> dict[str, Any]:
    """The type to buy when the machine is built within tolerances: the cheapest type (first in
    ``cost_order``) whose probability of meeting every criterion (``judged``) reaches ``require``, as
    without tolerances the cheapest type that meets every criterion; types of equal cost rank by
    probability, then by their smallest nominal margin in ``rows``. The reason names the dearer types that
    are more probable still.

    Answers ``isolator_type`` (None when no type reaches ``require``), ``reason`` in words, ``cost_order``
    (as given), ``basis`` (``probability``) and ``require``.
    """
    order = list(cost_order) if cost_order is not None else list(judged)
    answer: dict[str, Any] = {"isolator_type": None, "cost_order": order, "basis": "probability"}
    answer["require"] = float(require)
    if not criteria:
        answer["reason"] = (
            "no criteria given: add a criteria block (limits at the points of interest and on the mounts) "
            "to the scene to get a recommendation"
        )
        return answer
    n = max((r.cases for r in judged.values()), default=0)
    where = f"of {n} machines drawn from the tolerances"
    ranked = sorted(
        judged,
        key=lambda t: (judged[t].probability, smallest_margin(rows.get(t, {}), criteria)),
        reverse=True,
    )
    listing = "; ".join(f"{t} {judged[t].text()}" for t in ranked)
    reaching = [t for t in ranked if judged[t].probability >= require]
    if not reaching:
        best = ranked[0] if ranked else None
        answer["reason"] = (
            f"no type meets every criterion with the required probability {require:.0%} ({where}): {listing}."
            + (f" Closest: {best}" if best else "")
            + "; tune the mounts, tighten the tolerances or relax the criteria"
        )
        return answer
    rank = {t: i for i, t in enumerate(order)}
    pick = min(reaching, key=lambda t: (rank.get(t, len(order)), reaching.index(t)))
    surer = [t for t in reaching if judged[t].probability > judged[pick].probability]
    more = (
        f"; {', '.join(f'{t} ({judged[t].probability:.1%})' for t in surer)} dearer and more probable still"
        if surer
        else ""
    )
    answer["isolator_type"] = pick
    answer["reason"] = (
        f"{pick} is the cheapest type (cost order {' < '.join(order)}) that meets every criterion with the "
        f"required probability {require:.0%}: in {judged[pick].text()} {where}{more}. All: {listing}"
    )
    return answer


def robustness_answer(
    answer: dict[str, Any],
    nominal: dict[str, Any],
    tuned: dict[str, Any] | None,
    simulation: Any,
    criteria: list[str],
    samples: int = DEFAULT_SAMPLES,
    require: float = DEFAULT_REQUIRE,
    seed: int = 0,
    choice: str = "preset",
) -> dict[str, Any]:
    """A comparison's ``answer`` with each type's probability of meeting the criteria under the
    tolerances (``robustness``: per type its ``nominal`` design, and with ``tuned`` its ``tuned`` one)
    and the recommendation on it (:func:`recommend_on_probability`, on the tuned design when there is
    one). ``nominal`` and ``tuned`` are the scenes (as data) the types were compared on before and after
    tuning; with ``choice="model"`` the rows are products of the scene's catalogue.

    Raises:
        DefinitionError: as :func:`tolerance_study`.
        ValueError: as :func:`reliability`.
    """
    types = list(answer["isolator_types"])
    per_type: dict[str, dict[str, Any]] = {t: {} for t in types}
    judged = type_reliabilities(nominal, types, simulation, "nominal", samples, seed, choice)
    for t, r in judged.items():
        per_type[t]["nominal"] = r.to_dict()
    if tuned is not None:
        judged = type_reliabilities(tuned, types, simulation, "tuned", samples, seed, choice)
        for t, r in judged.items():
            per_type[t]["tuned"] = r.to_dict()
    out = dict(answer)
    out["robustness"] = {
        "samples": int(samples),
        "seed": int(seed),
        "sampling": SAMPLING,
        "require": float(require),
        "confidence": CONFIDENCE,
        "interval_method": INTERVAL_METHOD,
        "judged_design": "tuned" if tuned is not None else "nominal",
        "tolerances": copy.deepcopy(nominal.get("tolerances") or {}),
        "types": per_type,
    }
    out["recommendation"] = recommend_on_probability(
        answer["rows"], criteria, judged, require, list(answer["recommendation"]["cost_order"])
    )
    return out
