"""The engine cost model: how long the engine takes per step of one case, by fidelity and integrator.

Two things are sized with it: the accuracy chooser ranks its candidate models by estimated cost
(:func:`studies.run.accuracy.choose_for_batch`), and the runner sizes chunks, and authoring estimates a
study's
run time, from :func:`estimate_seconds_per_case`. Only rankings and rough sizes depend on it: a factor of a
few changes no result. ``python -m benchmarks accuracy`` prints measured figures beside :data:`STEP_COST`.
"""

from __future__ import annotations

import numpy as np

from isolab.studies.inputs.schema import DEFAULT_DT
from isolab.studies.inputs.study import Study

STEP_COST: dict[tuple[str, str], float] = {
    ("lti", "euler"): 0.65e-6,
    ("lti", "exact"): 0.084e-6,
    ("lti", "rk4"): 2.24e-6,
    ("ltv", "euler"): 1.05e-6,
    ("ltv", "rk4"): 3.28e-6,
    ("nonlinear", "euler"): 1.10e-6,
    ("nonlinear", "rk4"): 3.19e-6,
    ("lti", "reference"): 25e-6,
    ("ltv", "reference"): 25e-6,
    ("nonlinear", "reference"): 30e-6,
}
"""Engine time per step of one case, s, batched, on one core, on the article scene (fixed-step pairs
measured by ``python -m benchmarks accuracy``; the adaptive reference integrator's per output step,
roughly). ``lti``/``exact`` measured again after its kernel got about 5x faster (0.084 us: 500 cases, 3 s
at 1 ms, 0.306 ms a case with the batch, less 0.055 ms a case at 10 ms). The other fixed-step pairs now
run 1.5-6x faster than their figures here, and not in the same order (``ltv``/``rk4`` 0.52 us against
``lti``/``rk4`` 1.33 us): new figures would change the accuracy chooser's ranking, which wants a measured
check of its choices of its own."""
LEVELLING_STEP_FACTOR: dict[tuple[str, str], float] = {
    ("lti", "exact"): 3.6,
    ("lti", "rk4"): 1.3,
    ("ltv", "rk4"): 1.3,
}
"""How much dearer a step is with levelling valves (three extra linear states: the exact integrator's dense
maps instead of its lean whole step, the slot's rates in every RK4 slope), measured on
``studies/examples/scriber-levelling.yaml`` against the same scene without valves (64 cases, 5 s at 1 ms,
CPU: 384 / 106, 1690 / 1326 and 668 / 516 ns per step and case). The levels and integrators that refuse
valves are not in it."""
STATE_STEP_COST: dict[tuple[str, str], tuple[float, float]] = {
    ("lti", "exact"): (0.47e-6, 28.5e-9),
    ("lti", "rk4"): (98e-9, 3.9e-9),
    ("ltv", "rk4"): (145e-9, 6.3e-9),
}
"""What ``nz`` extra linear states (a flexible base's modes, the mounts' relaxation branches, one per branch
and axis) add to the time per step of one case: ``a nz + b nz^2`` s, ``(a, b)`` fitted to the article
scene with 4 states (air mounts' orifices) and 36 (elastomer ladders of 3 branches on 3 axes), 16 cases a
batch (``python -m benchmarks mount_states``: lti/exact 429 -> 2,747 -> 54,240 ns, lti/rk4 2,221 -> 2,674
-> 11,502 ns, ltv/rk4 1,017 -> 1,699 -> 14,764 ns; the exact integrator's dense maps grow as nz^2). Only
these pairs model the states; the others refuse them."""
UNKNOWN_STEP_COST = 30e-6
"""Time per step assumed for a pair the table lacks, s (the dearest)."""
CASE_OVERHEAD = 0.1e-3
"""Fixed engine time per case, s (building its batch row; the exact integrator's step maps; the modes): the
article scene's cases simulated for 10 ms take 0.055 (``lti``/``exact``) to 0.30 ms (``nonlinear``/``rk4``)
each, batch included."""
UNKNOWN_DURATION = 10.0
"""Simulated time assumed for a study whose first case cannot be built, s."""


def step_cost(fidelity: str | None, integrator: str | None, states: int = 0) -> float:
    """Engine time per step of one case, s (:data:`STEP_COST`, plus :data:`STATE_STEP_COST` per extra
    linear state; a pair not chosen yet costs :data:`UNKNOWN_STEP_COST`)."""
    if fidelity is None or integrator is None:
        return UNKNOWN_STEP_COST
    a, b = STATE_STEP_COST.get((fidelity, integrator), (UNKNOWN_STEP_COST, 0.0))
    extra = a * states + b * states * states
    return STEP_COST.get((fidelity, integrator), UNKNOWN_STEP_COST) + extra


def estimate_seconds_per_case(study: Study) -> float:
    """Rough engine time per case of ``study``, s: :data:`CASE_OVERHEAD` plus ``duration / dt`` steps at
    :func:`step_cost` of its fidelity and integrator (the duration of its first case; a study that leaves the
    step to the accuracy chooser is taken at :data:`studies.inputs.schema.DEFAULT_DT`)."""
    sim = study.simulation
    steps = max(1.0, _duration(study) / float(sim.dt if sim.dt is not None else DEFAULT_DT))
    factor = 1.0
    if _has_valves(study) and sim.fidelity is not None and sim.integrator is not None:
        factor = LEVELLING_STEP_FACTOR.get((sim.fidelity, sim.integrator), 1.0)
    return CASE_OVERHEAD + steps * step_cost(sim.fidelity, sim.integrator) * factor


def _has_valves(study: Study) -> bool:
    """Whether the study's scene gives some mount a levelling valve."""
    iso = study.base_scene.isolators
    return iso.levelling is not None or any(m.levelling is not None for m in iso.listed)


def _duration(study: Study) -> float:
    """Simulated time of the study's first case, s (``duration: auto`` depends on the motion)."""
    d = study.simulation.duration
    if isinstance(d, int | float):
        return float(d)
    try:
        return float(np.max(np.asarray(study.batch(np.array([0])).duration)))
    except Exception:  # sizing only: a case that cannot be built fails in its own chunk
        return UNKNOWN_DURATION
