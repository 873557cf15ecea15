"""The error a run carries: each output of a run against the reference level, and the estimate every
stored study carries.

**Errors.** :func:`output_errors` compares each output of a run with the same cases at the reference level
(:data:`REFERENCE_PAIR`: nonlinear, adaptive reference integrator; for a scene with extra linear states,
which that level does not model, the best pair that does: :func:`reference_pair`): relative to the
reference's largest peak for the :data:`SIZING_OUTPUTS`, the settling time as an absolute difference in s;
:func:`sizing_error` reduces them to what a tolerance is checked against and :func:`component_errors`
measures each component of an output against a per-output tolerance.

**Estimating.** Every stored study carries the error its outputs carry: :func:`error_sample` picks a few
cases (seeded, at least one per isolator type), :func:`sample_arrays` runs them with the study's model and
at the reference level at the step that run used (beside the study's chunks), and :func:`estimate_errors`
keeps the largest error per output (:data:`ESTIMATED_OUTPUTS`; settling time as an absolute difference in
s).
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

import numpy as np

from isolab.engine import model, simulate, stability
from isolab.engine.results import OK, OUTPUTS, STATUS_NAMES
from isolab.engine.scene import SceneBatch
from isolab.engine.simulation import SUB_STEPPED
from isolab.studies.inputs.study import Study, study_from_json
from isolab.studies.results.dataset import result_arrays
from isolab.studies.results.timings import record_timing

REFERENCE_PAIR = ("nonlinear", "reference")
"""The fidelity and integrator every error is measured against (the reference level)."""
STATES_REFERENCE_PAIR = ("ltv", "rk4")
"""The reference of a scene with extra linear states (a flexible base, mounts' internal states, levelling
valves), which the nonlinear level and the reference integrator do not model: the ltv level by RK4."""
SERVO_REFERENCE_PAIR = ("lti", "exact")
"""The reference of a scene with a stage on a servo, which only the lti level models: its exact integrator."""
SERVO_DEAD_BAND_REFERENCE_PAIR = ("lti", "rk4")
"""The reference of a scene with a stage on a servo and a levelling valve's dead band (a nonlinearity the
exact integrator's linear maps do not step): the lti level by RK4."""
ERROR_SAMPLE = 4
"""Cases of a study rerun at the reference level for its error estimate (more when it has more isolator
types, at most :data:`ERROR_SAMPLE_LIMIT`)."""
ERROR_SAMPLE_LIMIT = 6
"""Most cases of a study's error sample."""
DISPLACEMENT_FLOOR = 1e-9
"""Peak displacements (m) and rotations (rad) below this count as zero when forming relative errors."""
FORCE_FLOOR = 1e-6
"""Peak isolator forces below this fraction of the largest preload count as zero, likewise."""

SIZING_OUTPUTS = (
    "peak_displacement",
    "peak_point_displacement",
    "peak_rotation",
    "peak_isolator_force",
    "min_isolator_load",
)
"""Outputs a relative tolerance applies to."""
ESTIMATED_OUTPUTS = (*SIZING_OUTPUTS, "settling_time")
"""Outputs whose error every stored study carries (point displacement only where the scene has points)."""
OUTPUT_UNITS = {name: (OUTPUTS[name].unit if name == "settling_time" else "1") for name in ESTIMATED_OUTPUTS}
OUTPUT_MEANING = {
    "peak_displacement": "largest |error| of a peak c.g. displacement relative to the largest reference peak",
    "peak_point_displacement": "largest |error| of a peak point displacement relative to the largest "
    "reference peak",
    "peak_rotation": "largest |error| of a peak rotation relative to the largest reference peak",
    "peak_isolator_force": "largest |error| of a peak isolator force relative to the largest reference peak",
    "min_isolator_load": "largest |error| of a smallest isolator load relative to the largest preload",
    "settling_time": "largest |error| of the settling time",
}


def output_errors(result: Any, reference: Any) -> dict[str, np.ndarray]:
    """Per-case error (C,) of each output of ``result`` against ``reference`` (same cases).

    Both are :class:`~engine.results.SimulationResult` (or anything with its fields). Keys: the
    :data:`ESTIMATED_OUTPUTS` (relative, 1; settling time absolute, s) and ``displacement_m``, the largest
    absolute error of a peak c.g. or point displacement, m. NaN where either case is not OK.
    """
    status = np.asarray(result.status)
    C = status.shape[0]
    ok = (status == OK) & (np.asarray(reference.status) == OK)
    preload = np.abs(np.asarray(reference.static_isolator_load, dtype=float)).reshape(C, -1).max(axis=1)

    def diff(name: str) -> tuple[np.ndarray, np.ndarray]:
        a = np.asarray(getattr(result, name), dtype=float).reshape(C, -1)
        b = np.asarray(getattr(reference, name), dtype=float).reshape(C, -1)
        if a.shape[1] == 0:
            return np.zeros(C), np.zeros(C)
        with np.errstate(invalid="ignore"):
            return np.abs(a - b).max(axis=1), np.abs(b).max(axis=1)

    out: dict[str, np.ndarray] = {}
    for name, floor in (
        ("peak_displacement", DISPLACEMENT_FLOOR),
        ("peak_point_displacement", DISPLACEMENT_FLOOR),
        ("peak_rotation", DISPLACEMENT_FLOOR),
        ("peak_isolator_force", FORCE_FLOOR * preload),
    ):
        num, big = diff(name)
        out[name] = num / np.maximum(big, floor)
    num, _ = diff("min_isolator_load")
    out["min_isolator_load"] = num / np.maximum(preload, np.finfo(float).tiny)
    num, _ = diff("settling_time")
    out["settling_time"] = num
    out["displacement_m"] = np.maximum(diff("peak_displacement")[0], diff("peak_point_displacement")[0])
    return {k: np.where(ok, v, np.nan) for k, v in out.items()}


def sizing_error(errors: Mapping[str, np.ndarray], relative: bool) -> np.ndarray:
    """Per-case error a tolerance is checked against: the largest relative error of the sizing outputs
    (1), or the largest absolute error of the peak displacements (m). NaN where a case is not OK."""
    if relative:
        return np.max(np.stack([np.asarray(errors[k]) for k in SIZING_OUTPUTS]), axis=0)
    return np.asarray(errors["displacement_m"])


COMPONENT_FLOOR = 1e-3
"""Per-output relative tolerances: a component whose reference value is below this fraction of the largest
reference value of its output is measured against that fraction (a peak that is almost zero has no
meaningful relative error)."""
SETTLING_FLOOR = 1e-3
"""Per-output relative tolerance on the settling time: reference settling times below this (s) count as
this."""


def component_errors(
    result: Any, reference: Any, tolerances: Mapping[str, tuple[float, bool]]
) -> dict[str, np.ndarray]:
    """Per case (C,), for each output named in ``tolerances`` (output -> (value, relative), as
    :func:`studies.inputs.schema.parse_output_tolerance` gives them), the error of its worst component as a
    fraction of its tolerance (1 = at the tolerance). NaN where either case is not OK.

    A component is one axis of one point, isolator or the c.g. A relative error is ``|a - b| / |b|`` with
    ``b`` the reference value of that component (at least :data:`COMPONENT_FLOOR` of the output's largest
    component); the smallest and largest isolator loads are relative to that isolator's preload; the
    settling time to the reference's (at least :data:`SETTLING_FLOOR` s). An absolute one is ``|a - b|``
    in SI.
    """
    status = np.asarray(result.status)
    C = status.shape[0]
    ok = (status == OK) & (np.asarray(reference.status) == OK)
    out: dict[str, np.ndarray] = {}
    for name, (tol, relative) in tolerances.items():
        a = np.asarray(getattr(result, name), dtype=float).reshape(C, -1)
        b = np.asarray(getattr(reference, name), dtype=float).reshape(C, -1)
        if a.shape[1] == 0:
            out[name] = np.where(ok, 0.0, np.nan)
            continue
        with np.errstate(invalid="ignore", divide="ignore"):
            err = np.abs(a - b)
            if relative:
                if name in ("min_isolator_load", "max_isolator_load"):
                    scale = np.abs(np.asarray(reference.static_isolator_load, dtype=float)).reshape(C, -1)
                elif name == "settling_time":
                    scale = np.maximum(np.abs(b), SETTLING_FLOOR)
                else:
                    big = np.abs(b).max(axis=1, keepdims=True)
                    scale = np.maximum(np.abs(b), np.maximum(COMPONENT_FLOOR * big, DISPLACEMENT_FLOOR))
                err = err / np.maximum(scale, np.finfo(float).tiny)
            out[name] = np.where(ok, err.max(axis=1) / tol, np.nan)
    return out


def valve_dead_band(batch: SceneBatch) -> bool:
    """Whether some case of ``batch`` has a levelling valve with a dead band: a nonlinearity only the
    stepping integrators (rk4) take, not exact's linear maps."""
    return bool(np.any((np.asarray(batch.iso_valve) >= 0) & (np.asarray(batch.iso_level_band) > 0)))


def reference_pair(batch: SceneBatch) -> tuple[str, str]:
    """The fidelity and integrator ``batch``'s errors are measured against: :data:`REFERENCE_PAIR`, or the
    best pair that models the scene's extra linear states where it has some (:data:`SERVO_REFERENCE_PAIR`
    with a stage on a servo, :data:`SERVO_DEAD_BAND_REFERENCE_PAIR` when a levelling valve also has a dead
    band, else :data:`STATES_REFERENCE_PAIR`)."""
    if len(batch.servo_stages):
        return SERVO_DEAD_BAND_REFERENCE_PAIR if valve_dead_band(batch) else SERVO_REFERENCE_PAIR
    if model.linear_slot(batch).A.shape[1]:
        return STATES_REFERENCE_PAIR
    return REFERENCE_PAIR


def reference_method(pair: tuple[str, str]) -> str:
    """How the reference reruns of an error estimate ran (``pair``, from :func:`reference_pair`), in words."""
    if tuple(pair) == REFERENCE_PAIR:
        return (
            "nonlinear level, reference integrator (DOP853, rtol 1e-10), sampled at the step each case used"
        )
    return (
        f"{pair[0]} level, {pair[1]} integrator at the step each case used: the scene has extra linear "
        "states (a flexible base, mounts' internal states, levelling valves or a stage on a servo) that the "
        f"nonlinear level and the reference integrator do not model, so {pair[0]}/{pair[1]} is the reference "
        "(its own step error is not in the estimate)"
    )


def case_groups(study: Study) -> dict[tuple, list[int]]:
    """Cases of a study by their categorical values (isolator types ...), in case order."""
    design = study.design()
    names = [n for n, t in zip(design.names, study.targets, strict=True) if t.categorical]
    groups: dict[tuple, list[int]] = {}
    keys = zip(*(design.values[n].tolist() for n in names), strict=True) if names else [()] * study.n_cases
    for i, key in enumerate(keys):
        groups.setdefault(tuple(key), []).append(i)
    return groups


def error_sample(
    study: Study, n: int = ERROR_SAMPLE, seed: int = 0, limit: int = ERROR_SAMPLE_LIMIT
) -> list[int]:
    """A seeded sample of cases to rerun at the reference level: one per group of categorical values
    (isolator types) first, then others up to ``n`` cases; at most ``limit``. Sorted."""
    rng = np.random.default_rng(seed)
    groups = list(case_groups(study).values())
    picked = [int(rng.choice(members)) for members in groups][:limit]
    rest = np.setdiff1d(np.arange(study.n_cases), picked)
    extra = max(0, min(n, limit) - len(picked))
    if extra and rest.size:
        picked += [int(c) for c in rng.choice(rest, min(extra, rest.size), replace=False)]
    return sorted(picked)


def sample_arrays(
    definition_json: str, cases: int | Sequence[int], pair: tuple[str, str] | None = None
) -> dict[str, dict[str, np.ndarray]]:
    """Sampled cases of a study (JSON definition) run twice (a Dask task): with the study's own model
    (``"ours"``, the numbers its chunks give: a case's result does not depend on the batch it runs in)
    and at the reference level sampled at the step that run used (``"reference"``): ``pair``, or the
    cases' own :func:`reference_pair` when None. Each array has one row per case of ``cases`` (one case
    or several, in that order), bit for bit what each case run alone gives; the cases run as one batch
    at each level (one case at a time at the reference level where the run's steps differ), which saves
    each engine call's fixed work: four cases of the article scene 0.124 -> 0.105 s of CPU."""
    t0 = time.perf_counter()
    study = study_from_json(definition_json)
    sim = study.simulation
    picked = np.atleast_1d(np.asarray(cases, dtype=np.int64))
    batch = study.batch(picked)
    fidelity, integrator, step = sim.engine_choice()  # resolved, as for the chunks that run this definition
    ours = result_arrays(simulate(batch, fidelity, integrator, dt=step, auto_step=sim.auto_step))
    steps = np.where(np.isfinite(ours["dt"]), ours["dt"], step)
    pair = reference_pair(batch) if pair is None else pair
    if np.all(steps == steps[0]):
        reference = result_arrays(simulate(batch, *pair, dt=float(steps[0]), auto_step=sim.auto_step))
    else:
        alone = [
            result_arrays(simulate(batch.take([k]), *pair, dt=float(h), auto_step=sim.auto_step))
            for k, h in enumerate(steps.tolist())
        ]
        reference = {name: np.concatenate([a[name] for a in alone]) for name in alone[0]}
    record_timing("rerun", cases=picked.tolist(), seconds=time.perf_counter() - t0)
    return {"ours": ours, "reference": reference}


@dataclass(frozen=True)
class ErrorEstimate:
    """The largest error found per output on the sampled cases.

    Attributes:
        values: output -> largest error (1, or s for the settling time); NaN when no sampled case could be
            compared.
        worst_case: output -> the study case where it was found (None when none).
        cases: the sampled study cases.
        excluded: case -> why it could not be compared (the case or its reference rerun is not OK).
        method: how the reference was run (and which sampled cases the stability guard sub-stepped).
        sub_stepped: case -> the message of a sampled case the stability guard sub-stepped; such a case
            is ``ok`` and compared like any other, so its (often larger) error is in ``values``.
    """

    values: dict[str, float]
    worst_case: dict[str, int | None]
    cases: tuple[int, ...]
    excluded: dict[int, str]
    method: str
    sub_stepped: dict[int, str] = field(default_factory=dict)


def estimate_errors(
    study_arrays: Mapping[str, np.ndarray],
    reference: Mapping[str, np.ndarray],
    cases: Sequence[int],
    outputs: Sequence[str] = ESTIMATED_OUTPUTS,
    method: str = "",
    integrator: str | None = None,
) -> ErrorEstimate:
    """Largest error per output of the study's results (``study_arrays``: result arrays of the sampled
    ``cases``, in that order) against their reference reruns (``reference``, same cases). With the study's
    ``integrator`` rk4, ``method`` also says when RK4's damping of the sampled cases' fastest mode exceeds
    :data:`RK4_NOTE_LOSS` per cycle: the reference on the same grid does not show that error."""
    cases = tuple(int(c) for c in cases)
    ours = SimpleNamespace(**{k: np.asarray(v) for k, v in study_arrays.items()})
    ref = SimpleNamespace(**{k: np.asarray(v) for k, v in reference.items()})
    errors = output_errors(ours, ref)
    excluded = {}
    for k, c in enumerate(cases):
        if ours.status[k] != OK:
            excluded[c] = f"the case is {STATUS_NAMES[int(ours.status[k])]}"
        elif ref.status[k] != OK:
            excluded[c] = f"its reference rerun is {STATUS_NAMES[int(ref.status[k])]}"
    messages = [str(m) for m in np.asarray(study_arrays.get("message", [""] * len(cases))).reshape(-1)]
    sub_stepped = {
        c: m
        for c, m, s in zip(cases, messages, ours.status, strict=True)
        if s == OK and m.startswith(SUB_STEPPED)
    }
    if sub_stepped:
        method = (
            f"{method}; sampled cases {sorted(sub_stepped)} were sub-stepped by the stability guard and are "
            "compared like the others"
        ).lstrip("; ")
    if integrator == "rk4" and "natural_frequency" in study_arrays and "dt" in study_arrays:
        note = rk4_damping_note(np.asarray(study_arrays["natural_frequency"]), np.asarray(study_arrays["dt"]))
        if note:
            method = f"{method}; {note}".lstrip("; ")
    values: dict[str, float] = {}
    worst: dict[str, int | None] = {}
    for name in outputs:
        e = np.asarray(errors[name])
        if np.all(np.isnan(e)):
            values[name], worst[name] = float("nan"), None
        else:
            k = int(np.nanargmax(e))
            values[name], worst[name] = float(e[k]), cases[k]
    return ErrorEstimate(values, worst, cases, excluded, method, sub_stepped)


RK4_NOTE_LOSS = 1e-3
"""RK4's damping of the fastest mode per cycle (1) above which an error estimate says so."""


def rk4_damping_note(frequency: np.ndarray, dt: np.ndarray) -> str:
    """What an error estimate says when RK4 at the steps ``dt`` (cases,), s, damps the fastest of the
    ``frequency`` (cases, 6), Hz, by more than :data:`RK4_NOTE_LOSS` per cycle; empty otherwise."""
    f = np.nanmax(np.asarray(frequency, dtype=float), axis=-1)
    h = np.asarray(dt, dtype=float).reshape(f.shape)
    loss = stability.rk4_cycle_loss(2 * np.pi * f * h)
    if not np.any(loss > RK4_NOTE_LOSS):
        return ""
    k = int(np.argmax(loss))
    # the longest step that keeps the loss within RK4_NOTE_LOSS: the loss grows as (w h)^5
    limit = h[k] * (RK4_NOTE_LOSS / loss[k]) ** 0.2
    return (
        f"rk4 at {h[k] * 1e3:.3g} ms damps the fastest mode of the sample ({f[k]:.4g} Hz) by "
        f"{loss[k] * 100:.2g} % per cycle; peaks that mode drives may be low by a share of that, which the "
        f"reference on the same grid does not show; dt <= {limit * 1e3:.2g} ms keeps it under "
        f"{RK4_NOTE_LOSS * 100:g} %"
    )


def exact_estimate(
    cases: Sequence[int], outputs: Sequence[str] = ESTIMATED_OUTPUTS, pair: tuple[str, str] = REFERENCE_PAIR
) -> ErrorEstimate:
    """The estimate of a study that ran at its reference level (``pair``) itself: zero by definition."""
    method = "the study ran at the reference level (nonlinear, reference integrator)"
    if tuple(pair) != REFERENCE_PAIR:
        method = f"the study ran at the reference level of its extra linear states ({pair[0]}, {pair[1]})"
    return ErrorEstimate({k: 0.0 for k in outputs}, {k: None for k in outputs}, tuple(cases), {}, method)
