"""Speed against accuracy: pick the cheapest model for an accuracy request, and the study as it runs.

**Choosing.** A simulation block may ask for an accuracy instead of naming the model (``accuracy: fast |
balanced | reference`` or ``tolerance: "10 um" | "1 %"``, see :class:`studies.inputs.schema.Simulation`).
:func:`choose` then measures: it runs a few pilot cases of the study (:func:`pilot_cases`: the hardest case of
each isolator type and the stiffest case, found by a cheap screening run) at the reference level (nonlinear
model, adaptive reference integrator, at the finest candidate step: the "truth"; with extra linear states,
which that level does not model, the pair :func:`~isolab.studies.run.error_estimate.reference_pair` names:
ltv/rk4, ``error_estimate.STATES_REFERENCE_PAIR``, or lti/exact with a stage on a servo), then tries the
candidate fidelity/integrator/step triples in order of their estimated cost
(:data:`studies.run.costs.STEP_COST`, stability sub-steps included) and takes the first whose largest error on
the pilot cases stays inside the tolerance. A relative tolerance applies to every sizing output
(:data:`~isolab.studies.run.error_estimate.SIZING_OUTPUTS`: peak c.g. and point displacement, peak rotation,
peak isolator force, relative to the reference's largest of each; the smallest isolator load relative to the
largest preload); an absolute one (metres) to the peak displacements. A per-output tolerance (``tolerance:
{settling_time: 5 ms, peak_point_displacement: 1 %}``) bounds instead the worst component of each named output
(:func:`~isolab.studies.run.error_estimate.component_errors`). A candidate the stability guard would sub-step
on a pilot case is never chosen, nor, for a relative tolerance, RK4 at a step whose damping of the pilot
cases' fastest mode per cycle exceeds the tolerance (:func:`rk4_step_too_long`). ``fast`` allows 5 %,
``balanced`` 0.5 %; ``reference`` runs the nonlinear level with the reference integrator at the requested step
(default 1 ms). When no candidate meets the tolerance the reference itself is chosen.
Choices are cached per study definition.

How an error is measured, and the error estimate every stored study carries, are
:mod:`isolab.studies.run.error_estimate`'s.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from types import SimpleNamespace
from typing import Any, cast

import numpy as np

from isolab.engine import modal, model, simulate, stability
from isolab.engine.results import OK, STATUS_NAMES, SimulationResult
from isolab.engine.scene import SceneBatch
from isolab.engine.simulation import SERVO_LEVELS, SLOT_INTEGRATORS, SLOT_LEVELS
from isolab.studies.inputs.schema import (
    ACCURACY_LEVELS,
    DEFAULT_DT,
    TOLERANCE_OUTPUTS,
    Simulation,
    parse_output_tolerance,
    parse_tolerance,
    tolerance_text,
)
from isolab.studies.inputs.study import Study, study_from_json
from isolab.studies.results.dataset import result_arrays
from isolab.studies.run.costs import step_cost
from isolab.studies.run.error_estimate import (
    REFERENCE_PAIR,
    case_groups,
    component_errors,
    output_errors,
    reference_pair,
    sizing_error,
    valve_dead_band,
)

CANDIDATE_STEPS = (1e-4, 2e-4, 5e-4, 1e-3, 2e-3, 5e-3)
"""Steps the chooser tries, s (those at or below a requested ``dt``)."""
CANDIDATE_PAIRS = (
    ("lti", "euler"),
    ("lti", "exact"),
    ("lti", "rk4"),
    ("ltv", "euler"),
    ("ltv", "rk4"),
    ("nonlinear", "euler"),
    ("nonlinear", "rk4"),
)
"""Fidelity/integrator pairs the chooser tries, cheapest level first (the order breaks cost ties)."""
PILOT_MARGIN = 0.5
"""A candidate must meet this fraction of the tolerance on the pilot cases: the other cases of a study
can err more (on the isolator-comparison example, before the fixed-step integrators split steps at profile
breakpoints, balanced without a margin erred 0.79 % on a case the pilot did not hold, 0.39 % on those it
did)."""
PILOT_LIMIT = 4
"""Most pilot cases the chooser measures on."""
SCREEN_LIMIT = 48
"""Most cases of a study the pilot screening simulates (a seeded sample of larger studies)."""
SCREEN_STEP = 2e-3
"""Step of the screening run (lti, exact), s."""


@dataclass(frozen=True)
class Choice:
    """The fidelity, integrator and step a study runs with, and why.

    Attributes:
        request: the accuracy request (``"fast"``, ``"tolerance 1 %"``) or None when the study named the
            model itself.
        fidelity, integrator, dt: the choice (dt in s).
        tolerance: the error allowed (1 when ``relative``, else m), None for an explicit or reference choice.
        relative: whether ``tolerance`` is relative.
        reason: one sentence saying why.
        pilot_cases: study cases the choice was measured on.
        pilot: one row per candidate tried, in the order tried: fidelity, integrator, dt (s), step_used (s,
            after stability sub-steps), cost_s (estimated engine time on the pilot cases), error (the
            largest sizing error, 1 or m, None when a case was not OK), status, meets.
    """

    request: str | None
    fidelity: str
    integrator: str
    dt: float
    tolerance: float | None = None
    relative: bool = True
    reason: str = ""
    pilot_cases: tuple[int, ...] = ()
    pilot: tuple[dict[str, Any], ...] = field(default_factory=tuple)
    per_output: dict[str, str] | None = None
    """A per-output tolerance (output -> its text, ``"1 %"``, ``"0.005 s"``) instead of ``tolerance``;
    the ``error`` of the pilot rows is then the worst named output's error as a fraction of its
    tolerance."""

    def attrs(self) -> dict[str, Any]:
        """Dataset attributes recording the choice (JSON-able)."""
        out: dict[str, Any] = {
            "accuracy_request": self.request or "none (fidelity, integrator and dt given)",
            "fidelity": self.fidelity,
            "integrator": self.integrator,
            "dt": float(self.dt),
            "accuracy_reason": self.reason,
        }
        if self.per_output:
            out["accuracy_tolerance"] = ", ".join(f"{k} {v}" for k, v in self.per_output.items())
        elif self.tolerance is not None:
            out["accuracy_tolerance"] = (
                f"{self.tolerance * 100:.6g} %" if self.relative else f"{self.tolerance:.6g} m"
            )
        if self.request is not None and self.pilot:
            out["accuracy_pilot_cases"] = list(self.pilot_cases)
            out["accuracy_pilot"] = json.dumps(list(self.pilot))
        return out


def request_tolerance(sim: Simulation) -> tuple[float | None, bool]:
    """The error a simulation block's request allows: (value, relative); (None, True) for ``reference``
    or an explicit choice."""
    if isinstance(sim.tolerance, dict):
        return None, True
    if sim.tolerance is not None:
        return parse_tolerance(sim.tolerance)
    if sim.accuracy is not None:
        return ACCURACY_LEVELS[sim.accuracy], True
    return None, True


def request_output_tolerances(sim: Simulation) -> dict[str, tuple[float, bool]] | None:
    """A per-output tolerance of a simulation block: output -> (value, relative); None when it has none."""
    if not isinstance(sim.tolerance, dict):
        return None
    return {k: parse_output_tolerance(k, v, f"simulation.tolerance.{k}") for k, v in sim.tolerance.items()}


def candidate_steps(dt_cap: float | None) -> tuple[float, ...]:
    """The candidate steps at or below ``dt_cap`` (s); the cap itself when it is below them all."""
    if dt_cap is None:
        return CANDIDATE_STEPS
    steps = tuple(s for s in CANDIDATE_STEPS if s <= dt_cap * (1 + 1e-9))
    return steps or (float(dt_cap),)


def _fmt_error(e: float | None, relative: bool | None) -> str:
    if e is None or not math.isfinite(e):
        return "not ok"
    if relative is None:  # a per-output tolerance: the error as a fraction of it
        return f"{e:.3g} of the tolerance"
    return f"{e * 100:.3g} %" if relative else f"{e * 1e6:.3g} um"


def choose_for_batch(
    batch: SceneBatch,
    tolerance: float | None,
    relative: bool = True,
    *,
    steps: Sequence[float] = CANDIDATE_STEPS,
    auto_step: bool = True,
    pairs: Sequence[tuple[str, str]] = CANDIDATE_PAIRS,
    case_numbers: Sequence[int] | None = None,
    margin: float = PILOT_MARGIN,
    per_output: Mapping[str, tuple[float, bool]] | None = None,
) -> Choice:
    """The cheapest (fidelity, integrator, step) whose error on every case of ``batch`` (the pilot cases)
    stays within ``margin`` times ``tolerance`` (relative, 1, or absolute on peak displacement, m), or,
    with ``per_output`` (output -> (value, relative)) instead, whose worst component of every named output
    stays within ``margin`` times that output's tolerance (:func:`component_errors`).

    The truth is the nonlinear level with the reference integrator at the smallest of ``steps``.
    Candidates are tried in order of estimated cost (:func:`studies.run.costs.step_cost` times the steps each
    case takes). A candidate the stability guard would refuse or sub-step on any pilot case (with the stages
    at home, or, found when it runs, at the ends of their travel) is never chosen: a step cut to the
    stability limit is stable, not accurate, and the study's other cases may need it cut further. When
    none meets the tolerance the reference itself is returned.
    """
    from isolab.engine.integrators import INTEGRATORS  # the kernels, on use (not with the service)

    steps = tuple(sorted(float(s) for s in steps))
    fmt: bool | None = None if per_output else relative  # how errors read: of the tolerance, %, um
    # per output: errors are fractions of the tolerance; without per-output tolerances the request has one
    bound = 1.0 if per_output else float(cast(float, tolerance))
    texts = {k: tolerance_text(v, r, TOLERANCE_OUTPUTS[k]) for k, (v, r) in (per_output or {}).items()}
    shown = ", ".join(f"{k} {v}" for k, v in texts.items()) if per_output else _fmt_error(tolerance, relative)
    cases = tuple(int(c) for c in (case_numbers if case_numbers is not None else range(batch.n_cases)))
    fine = steps[0]
    states = model.linear_slot(batch).A.shape[1]  # extra linear states: only some pairs model them
    truth_pair = reference_pair(batch)
    if states:
        levels = SERVO_LEVELS if len(batch.servo_stages) else SLOT_LEVELS  # a servo stage: lti only
        pairs = [p for p in pairs if p[0] in levels and p[1] in SLOT_INTEGRATORS]
        if valve_dead_band(batch):
            pairs = [p for p in pairs if p[1] != "exact"]  # a valve's dead band: stepped, not mapped
    truth_name = "/".join(truth_pair)
    truth: SimulationResult | SimpleNamespace = simulate(batch, *truth_pair, dt=fine, auto_step=auto_step)
    usable = np.flatnonzero(truth.status == OK)
    if usable.size == 0:
        why = "; ".join(
            sorted({f"{STATUS_NAMES[int(s)]}: {m}" for s, m in zip(truth.status, truth.message, strict=True)})
        )
        fid, integ = pairs[0]
        return Choice(
            None,
            fid,
            integ,
            steps[-1],
            tolerance,
            relative,
            reason=f"no pilot case could be simulated at the reference level ({why}); the cheapest "
            f"candidate is used and the cases report their status",
            pilot_cases=cases,
            per_output=texts or None,
        )
    if usable.size < batch.n_cases:
        batch = batch.take(usable)
        truth = _take_result(truth, usable)
        cases = tuple(cases[i] for i in usable)
    duration = np.asarray(batch.duration, dtype=float)
    A = (
        model.slot_state_matrix(model.params(batch))
        if states
        else modal.state_matrix(
            model.mass_matrix(batch), model.stiffness_matrix(batch), model.damping_matrix(batch)
        )
    )
    omega_max = 2.0 * np.pi * np.max(modal.modes(*_home_matrices(batch)).frequency)
    candidates = []
    for rank, (fid, integ) in enumerate(pairs):
        for dt in steps:
            n_div = stability.subdivisions(A, dt, INTEGRATORS[integ].step_matrix)
            if np.any(n_div != 1):
                continue  # the guard would refuse a case, or sub-step it (a stable step is not accurate)
            if integ == "rk4" and not per_output and relative and rk4_step_too_long(omega_max, dt, bound):
                continue  # RK4's numerical damping of the fastest mode alone would exceed the tolerance
            n_steps = np.rint(duration / (dt / n_div))
            cost = float(np.sum(n_steps) * step_cost(fid, integ, states))
            candidates.append((cost, rank, -dt, fid, integ, dt, float(dt / n_div.max())))
    candidates.sort()
    rows: list[dict[str, Any]] = []
    for cost, _, _, fid, integ, dt, used in candidates:
        r = simulate(batch, fid, integ, dt=dt, auto_step=auto_step)
        if per_output:
            err = np.max(np.stack(list(component_errors(r, truth, per_output).values())), axis=0)
        else:
            err = sizing_error(output_errors(r, truth), relative)
        worst = float(np.max(err)) if np.all(np.isfinite(err)) else None
        # the guard also looks at the stages at the ends of their travel: a case it sub-stepped there
        # rules the candidate out like one sub-stepped at home
        sub_stepped = bool(np.any(np.asarray(r.dt) < dt * (1 - 1e-9)))
        meets = worst is not None and worst <= margin * bound and not sub_stepped
        bad = [STATUS_NAMES[int(s)] for s in r.status if s != OK] or (["sub-stepped"] if sub_stepped else [])
        rows.append(
            {
                "fidelity": fid,
                "integrator": integ,
                "dt": dt,
                "step_used": used,
                "cost_s": cost,
                "error": worst,
                "status": bad[0] if bad else "ok",
                "meets": meets,
            }
        )
        if meets:
            missed = len(rows) - 1
            best_missed = min(
                (row for row in rows[:-1] if row["error"] is not None),
                key=lambda row: row["error"],
                default=None,
            )
            also = ""
            if best_missed is not None:
                also = (
                    f"; the {missed} cheaper candidates missed it (closest: {best_missed['fidelity']}/"
                    f"{best_missed['integrator']} at {best_missed['dt'] * 1e3:g} ms, "
                    f"{_fmt_error(best_missed['error'], fmt)})"
                )
            reason = (
                f"{fid}/{integ} at {dt * 1e3:g} ms is the cheapest candidate whose largest error on "
                f"pilot cases {list(cases)} ({_fmt_error(worst, fmt)} against {truth_name} "
                f"at {fine * 1e3:g} ms) stays within {margin:g} of the tolerance "
                f"{shown}" + also
            )
            return Choice(
                None, fid, integ, dt, tolerance, relative, reason, cases, tuple(rows), texts or None
            )
    closest = min(
        (row for row in rows if row["error"] is not None), key=lambda row: row["error"], default=None
    )
    near = (
        ""
        if closest is None
        else (
            f" (closest: {closest['fidelity']}/{closest['integrator']} at {closest['dt'] * 1e3:g} ms, "
            f"{_fmt_error(closest['error'], fmt)})"
        )
    )
    reason = (
        f"no candidate meets {margin:g} of {shown} on pilot cases "
        f"{list(cases)}{near}: the "
        f"reference itself ({truth_name} at {fine * 1e3:g} ms)"
    )
    return Choice(None, *truth_pair, fine, tolerance, relative, reason, cases, tuple(rows), texts or None)


def _home_matrices(batch: SceneBatch) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return model.mass_matrix(batch), model.stiffness_matrix(batch), model.damping_matrix(batch)


def rk4_step_too_long(omega: float, dt: float, tolerance: float) -> bool:
    """Whether RK4 at ``dt`` (s) damps the fastest mode (``omega``, rad/s) by more than a relative
    ``tolerance`` (1) per cycle (:func:`isolab.engine.stability.rk4_cycle_loss`): such a step is stable and
    may look accurate on pilot cases whose peaks the mode hardly drives, yet it lowers the peaks it does
    drive by about that much (0.108 % on c.g. Z of a scene with modes to 104 Hz at 1 ms)."""
    return bool(stability.rk4_cycle_loss(omega * dt) > tolerance)


def rk4_step_for(omega: float, tolerance: float, steps: Sequence[float] = CANDIDATE_STEPS) -> float | None:
    """The longest of ``steps`` (s) at which RK4 keeps its damping of a mode of ``omega`` (rad/s) within a
    relative ``tolerance`` (1) per cycle; None when even the shortest does not."""
    ok = [s for s in steps if not rk4_step_too_long(omega, s, tolerance)]
    return max(ok) if ok else None


def _take_result(result: Any, index: np.ndarray) -> SimpleNamespace:
    """The cases ``index`` of a result (the fields :func:`output_errors` reads)."""
    arrays = result_arrays(result) if not isinstance(result, Mapping) else result
    return SimpleNamespace(**{k: np.asarray(v)[index] for k, v in arrays.items()})


def pilot_cases(study: Study, limit: int = PILOT_LIMIT, seed: int = 0) -> list[int]:
    """Cases of ``study`` to measure candidates on, found by a cheap screening run (lti, exact at
    :data:`SCREEN_STEP`, rk4 under a levelling valve's dead band, which exact does not step; over at most
    :data:`SCREEN_LIMIT` cases, seeded). In order of priority: per group of categorical values (isolator
    types), the case that rotates most (the hardest for the cheaper levels); the case whose fastest mode is
    the fastest (the hardest for a fixed step); the case that moves most; the case with the least damped
    mode (the longest ringing). At most ``limit`` cases, sorted."""
    groups = case_groups(study)
    n = study.n_cases
    if n <= SCREEN_LIMIT:
        screen = np.arange(n)
    else:
        rng = np.random.default_rng(seed)
        firsts = [g[0] for g in groups.values()]
        screen = np.unique(np.concatenate([firsts, rng.choice(n, SCREEN_LIMIT, replace=False)]))
    batch = study.batch(screen)
    r = simulate(batch, "lti", "rk4" if valve_dead_band(batch) else "exact", dt=SCREEN_STEP)
    ok = r.status == OK
    if not ok.any():
        return sorted({int(g[0]) for g in groups.values()})[:limit]
    rotation = np.where(ok, np.nan_to_num(r.peak_rotation).max(axis=1), -1.0)
    where = {int(c): k for k, c in enumerate(screen)}
    worst = []
    for members in groups.values():
        ks = [where[c] for c in members if c in where]
        if ks:
            k = max(ks, key=lambda k: (rotation[k], -k))
            worst.append((rotation[k], int(screen[k])))
    worst.sort(key=lambda x: (-x[0], x[1]))
    live = np.where(r.mechanism, np.inf, r.damping_ratio)
    others = [
        np.where(ok, r.natural_frequency.max(axis=1), -np.inf),  # stiffest
        np.where(ok, np.nan_to_num(r.peak_displacement).max(axis=1), -np.inf),  # moves most
        np.where(ok, -live.min(axis=1), -np.inf),  # least damped
    ]
    picked: list[int] = []
    for c in [c for _, c in worst[: max(1, limit - 1)]] + [int(screen[int(np.argmax(x))]) for x in others]:
        if c not in picked and len(picked) < limit:
            picked.append(c)
    return sorted(picked)


def _reference_choice(sim: Simulation, request: str) -> Choice:
    dt = float(sim.dt) if sim.dt is not None else DEFAULT_DT
    return Choice(
        request,
        *REFERENCE_PAIR,
        dt,
        reason=f"accuracy reference: the nonlinear level with the reference integrator at {dt * 1e3:g} ms",
    )


def choose(study: Study) -> Choice:
    """The fidelity, integrator and step ``study`` runs with (see the module docstring).

    An explicit simulation block is returned as it is; ``accuracy: reference`` needs no measurement; any
    other request runs the pilot cases (seconds). Cached per study definition (in this process).
    """
    hit = cached_choice(study)
    if hit is None:
        hit = _choose(study)
        remember_choice(study, hit)
    return hit


CHOICE_CACHE_SIZE = 64
_CHOICES: dict[str, Choice] = {}


def _definition_key(study: Study) -> str:
    return json.dumps(study.model_dump(mode="json"), sort_keys=True)


def cached_choice(study: Study) -> Choice | None:
    """The choice made for this study definition earlier in this process, or None."""
    return _CHOICES.get(_definition_key(study))


def remember_choice(study: Study, choice: Choice) -> None:
    """Cache ``choice`` for this study definition (e.g. one a worker made)."""
    while len(_CHOICES) >= CHOICE_CACHE_SIZE:
        _CHOICES.pop(next(iter(_CHOICES)))
    _CHOICES[_definition_key(study)] = choice


def _choose(study: Study) -> Choice:
    sim = study.simulation
    request = sim.request
    if request is None:
        fidelity, integrator, dt = sim.engine_choice()  # no request: the block's validator filled all three
        return Choice(None, fidelity, integrator, dt, reason="given in the study")
    if sim.accuracy == "reference":
        return _reference_choice(sim, request)
    tolerance, relative = request_tolerance(sim)
    cases = pilot_cases(study)
    c = choose_for_batch(
        study.batch(cases),
        tolerance,
        relative,
        steps=candidate_steps(sim.dt),
        auto_step=sim.auto_step,
        case_numbers=cases,
        per_output=request_output_tolerances(sim),
    )
    return replace(c, request=request)


def choose_from_json(definition_json: str) -> Choice:
    """:func:`choose` for a study given as its JSON definition (the Dask task)."""
    return choose(study_from_json(definition_json))


def resolved_definition(study: Study, choice: Choice) -> dict[str, Any]:
    """The study's definition with the choice written into its simulation block (no accuracy request)."""
    definition = study.model_dump(mode="json")
    definition["simulation"] = {
        **definition["simulation"],
        "accuracy": None,
        "tolerance": None,
        "fidelity": choice.fidelity,
        "integrator": choice.integrator,
        "dt": float(choice.dt),
    }
    return definition


def resolved_simulation(study: Study, choice: Choice | None = None) -> Simulation:
    """The simulation block ``study`` runs with: its own when explicit, else with the choice filled in
    (``choice`` default: :func:`choose`)."""
    sim = study.simulation
    if sim.request is None:
        return sim
    choice = choice or choose(study)
    data = {
        **sim.model_dump(),
        "accuracy": None,
        "tolerance": None,
        "fidelity": choice.fidelity,
        "integrator": choice.integrator,
        "dt": float(choice.dt),
    }
    return Simulation.model_validate(data)


def resolved_study(study: Study, choice: Choice | None = None) -> Study:
    """``study`` as it runs: itself when its simulation block is explicit, else the same study with the
    choice (default: :func:`choose`) written into its simulation block."""
    if study.simulation.request is None:
        return study
    return type(study).model_validate(resolved_definition(study, choice or choose(study)))


def recorded_choice(
    study: Study, fidelity: str | None, integrator: str | None, dt: float | None
) -> Choice | None:
    """The choice a runner recorded for ``study`` (catalog columns), or None when there is none yet."""
    if study.simulation.request is None or not (fidelity and integrator and dt):
        return None
    return Choice(study.simulation.request, fidelity, integrator, float(dt), reason="recorded by the runner")
