"""Tuning one isolator type to a scene's design criteria, within what that type can physically reach.

Before types are compared (``POST /comparisons`` with ``tune: true``), each type's natural frequencies and
damping may be set to the values that serve the scene best: those that maximise the smallest criterion
margin (:mod:`isolab.studies.questions.criteria`), so that a type which can meet every criterion when tuned
is not
ruled out by its catalogue defaults. The search is scipy's differential evolution, evaluating each
generation as one batch of cases through the engine (``vectorized``), over the ranges of
:data:`TUNING_RANGES`.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import differential_evolution

from isolab.studies.answers.robustness import judged_dataset
from isolab.studies.inputs.isolators import PRESETS
from isolab.studies.inputs.study import validate_study

#: What each isolator type can be built or set to: (low, high) of f_vertical (Hz), f_horizontal (Hz),
#: zeta (1). Active systems: their controller sets 0.5-2 Hz and 20-70 % damping. Air springs: 1.5 Hz
#: (large auxiliary volume) to 5 Hz vertically, 1.5-6 Hz laterally (pendulum or rolling-lobe guides), orifice
#: damping 5-30 %. Elastomer pads and springs: 6-25 Hz vertically, 4-25 Hz laterally, 2-15 % damping.
TUNING_RANGES: dict[str, dict[str, tuple[float, float]]] = {
    "active": {"f_vertical": (0.5, 2.0), "f_horizontal": (0.5, 2.0), "zeta": (0.2, 0.7)},
    "air": {"f_vertical": (1.5, 5.0), "f_horizontal": (1.5, 6.0), "zeta": (0.05, 0.3)},
    "elastomer": {"f_vertical": (6.0, 25.0), "f_horizontal": (4.0, 25.0), "zeta": (0.02, 0.15)},
}
TUNED = ("f_vertical", "f_horizontal", "zeta")
"""The tuned inputs of a type, in the order of :data:`TUNING_RANGES`' entries."""
UNITS = {"f_vertical": "Hz", "f_horizontal": "Hz", "zeta": "1"}


@dataclass
class TunedType:
    """The tuning found for one type: ``values`` (f_vertical, f_horizontal in Hz, zeta), its smallest
    criterion margin (positive: every criterion met), and the number of cases evaluated."""

    isolator_type: str
    values: dict[str, float]
    worst_margin: float
    evaluations: int

    def to_dict(self) -> dict[str, Any]:
        return {
            "isolator_type": self.isolator_type,
            "values": self.values,
            "units": {k: UNITS[k] for k in self.values},
            "ranges": {k: list(TUNING_RANGES[self.isolator_type][k]) for k in TUNED},
            "worst_margin": self.worst_margin,
            "evaluations": self.evaluations,
        }


def _untuned(scene: dict[str, Any], isolator_type: str) -> dict[str, Any]:
    """``scene`` on ``isolator_type`` with the group's own frequency/damping removed (they are tuned)."""
    s = copy.deepcopy(scene)
    iso = s.setdefault("isolators", {})
    iso["preset"] = isolator_type
    for key in TUNED:
        iso.pop(key, None)
    return s


def worst_margins(
    scene: dict[str, Any], isolator_type: str, x: np.ndarray, simulation: Any = None
) -> np.ndarray:
    """Smallest criterion margin of each tuning in ``x`` ((S, 3): f_vertical Hz, f_horizontal Hz,
    zeta), one engine batch; -inf for a case that did not end ok.

    Raises:
        pydantic.ValidationError: the scene or a tuning is not valid.
    """
    x = np.atleast_2d(np.asarray(x, dtype=float))
    names = [f"tuned_{k}" for k in TUNED]
    body: dict[str, Any] = {
        "name": f"tune-{isolator_type}",
        "scene": _untuned(scene, isolator_type),
        "parameters": [
            {"name": n, "path": f"isolators.{k}", "values": [float(v) for v in x[:, j]]}
            for j, (n, k) in enumerate(zip(names, TUNED, strict=True))
        ],
        "design": {"type": "list", "cases": [dict(zip(names, map(float, row), strict=True)) for row in x]},
    }
    if simulation is not None:
        body["simulation"] = simulation
    study = validate_study(body)
    ds = judged_dataset(study)
    worst = ds["criterion_margin"].min("criterion", skipna=False).values
    return np.where(np.isfinite(worst), worst, -np.inf)


def tune(
    scene: dict[str, Any],
    isolator_type: str,
    simulation: Any = None,
    *,
    generations: int = 15,
    population: int = 12,
    seed: int = 0,
) -> TunedType:
    """The tuning of ``isolator_type`` within :data:`TUNING_RANGES` that maximises the smallest criterion
    margin of ``scene`` (which must carry criteria), by differential evolution (``population`` cases per
    generation, at most ``generations`` + 1 generations).

    Raises:
        ValueError: no criteria, or an unknown type.
    """
    if isolator_type not in TUNING_RANGES:
        raise ValueError(f"isolator_types: cannot tune {isolator_type!r}; types: {', '.join(TUNING_RANGES)}")
    if not scene.get("criteria"):
        raise ValueError("tune: tuning serves the design criteria; give the scene a criteria block")
    bounds = [TUNING_RANGES[isolator_type][k] for k in TUNED]
    count = {"cases": 0}

    def cost(x: np.ndarray) -> np.ndarray:  # x: (3, S) with vectorized=True
        count["cases"] += x.shape[1]
        worst = worst_margins(scene, isolator_type, x.T, simulation)
        return np.where(np.isfinite(worst), -worst, 1e6)

    # start from the type's catalogue figures (clipped to its range): the search never ends worse than them
    preset = PRESETS[isolator_type]
    start = [float(np.clip(getattr(preset, k), *b)) for k, b in zip(TUNED, bounds, strict=True)]
    popsize = max(1, int(np.ceil(population / len(bounds))))
    found = differential_evolution(
        cost,
        bounds,
        maxiter=generations,
        popsize=popsize,
        seed=seed,
        polish=False,
        vectorized=True,
        updating="deferred",
        init="sobol" if (popsize * len(bounds)) & (popsize * len(bounds) - 1) == 0 else "latinhypercube",
        tol=0.0,
        atol=1e-3,
        x0=start,
    )
    values = {k: float(v) for k, v in zip(TUNED, found.x, strict=True)}
    return TunedType(isolator_type, values, float(-found.fun), count["cases"])


def tuned_scene(scene: dict[str, Any], tuned: list[TunedType]) -> dict[str, Any]:
    """``scene`` with each tuned type's values in ``isolators.tuning`` (and the group's own frequency and
    damping removed, so the tuning applies whichever type a case uses)."""
    s = copy.deepcopy(scene)
    iso = s.setdefault("isolators", {})
    for key in TUNED:
        iso.pop(key, None)
    tuning = iso.setdefault("tuning", {})
    for t in tuned:
        tuning[t.isolator_type] = {**tuning.get(t.isolator_type, {}), **t.values}
    return s
