"""One scene run at once: the summary and the time traces of a single case, for a person waiting on it.

A single case is a one-case study (a scene, no varied parameter) run directly through the engine with its
histories recorded, in the calling process: the engine's kernels are warm there, and a case of a few
thousand steps takes a fraction of a second, far less than queueing it behind the studies. Its summary is
the case table of that one case (:func:`isolab.studies.results.cases.case_table`), the same columns a
study's case 0 of the same scene has, each with its SI unit and long name; its traces are those of
:func:`isolab.studies.answers.history.history_json`, thinned to at most ``max_points`` samples a trace.

A case is sized before it runs: at most :data:`MAX_CASE_VALUES` recorded values (time steps x recorded
series) and :data:`MAX_CASE_SECONDS` of estimated engine time; a larger one is refused, naming the limit
and the field that sets the length of the run.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from isolab.engine import modal, simulate
from isolab.engine import model as engine_model
from isolab.engine.results import DOF_NAMES
from isolab.engine.scene import SceneBatch
from isolab.studies.answers.history import history_json, isolator_places, recorded_history
from isolab.studies.inputs.definitions import DefinitionError, Loc, check_definition, detail
from isolab.studies.inputs.study import Study, study_labels
from isolab.studies.questions.criteria import add_criteria
from isolab.studies.results.cases import case_table, json_values
from isolab.studies.results.dataset import to_dataset
from isolab.studies.run.accuracy import resolved_study
from isolab.studies.run.costs import estimate_seconds_per_case

MAX_CASE_VALUES = 5_000_000
"""Most values a single case may record: time steps x recorded series (time, c.g. displacement and
rotation, 3 per isolator, 3 per point). 5 million is 40 MB of histories, about 10 s of engine time."""
MAX_CASE_SECONDS = 10.0
"""Longest estimated engine time of a single case, s (:func:`estimate_seconds_per_case`)."""
DEFAULT_TRACE_POINTS = 2000
"""Samples per trace returned unless asked otherwise."""
MAX_TRACE_POINTS = 20_000
"""Most samples per trace one answer holds."""
TRACE_KEYS = ("units", "time", "displacement", "rotation", "isolator_force", "point_displacement", "stages")
"""The traces of :func:`history_json` an answer carries."""


def single_case_study(scene: Any, simulation: Any = None, prefix: Loc | None = None) -> Study:
    """The one-case study of ``scene`` (a scene definition as data) with ``simulation`` overriding the
    scene's simulation block, its accuracy request (if any) resolved to a model, and sized.

    Raises:
        DefinitionError: naming the request's field under ``prefix`` (default ``["body"]``): a bad scene
            or simulation block, or a case past :data:`MAX_CASE_VALUES` or :data:`MAX_CASE_SECONDS`.
    """
    pre: Loc = ["body"] if prefix is None else list(prefix)
    body: dict[str, Any] = {"name": "simulation", "scene": scene}
    if simulation is not None:
        body["simulation"] = simulation
    study = check_definition(body, prefix=pre)
    try:
        study = resolved_study(study)
    except ValueError as err:
        raise DefinitionError([detail([*pre, "scene"], str(err))]) from None
    check_case_size(study, pre, given=dict(simulation or {}))
    return study


def recorded_series(study: Study) -> int:
    """Series a case of ``study`` records per time step: time, 3 c.g. displacements, 3 rotations, 3 forces
    per isolator, 3 displacements per point."""
    isolators, points = study_labels(study)
    return 7 + 3 * len(isolators) + 3 * len(points)


def check_case_size(study: Study, prefix: Loc, given: dict[str, Any]) -> None:
    """Refuse a case of ``study`` that records more than :data:`MAX_CASE_VALUES` values or would run
    longer than :data:`MAX_CASE_SECONDS`: a :class:`DefinitionError` at the field that sets its length
    (the request's ``simulation.duration`` or ``.dt`` when ``given`` there, else the scene's)."""
    fidelity, integrator, dt = study.simulation.engine_choice()
    try:
        duration = float(np.asarray(study.batch(np.array([0])).duration)[0])
    except ValueError as err:
        raise DefinitionError([detail([*prefix, "scene"], f"cannot be simulated: {err}")]) from None
    steps = int(math.ceil(duration / dt)) + 1
    series = recorded_series(study)
    field = "dt" if "dt" in given and "duration" not in given else "duration"
    where = [*prefix, "simulation", field] if field in given else [*prefix, "scene", "simulation", "duration"]
    advice = "shorten simulation.duration, lengthen simulation.dt, or submit it as a study"
    if steps * series > MAX_CASE_VALUES:
        raise DefinitionError(
            [
                detail(
                    where,
                    f"this case records {steps:,} time steps x {series} series = {steps * series:,} values, "
                    f"more than the {MAX_CASE_VALUES:,} of a single case run at once ({advice})",
                    "case_too_large",
                )
            ]
        )
    seconds = estimate_seconds_per_case(study)
    if seconds > MAX_CASE_SECONDS:
        raise DefinitionError(
            [
                detail(
                    where,
                    f"this case would take about {seconds:.0f} s "
                    f"({steps:,} steps of {fidelity}/{integrator}), "
                    f"more than the {MAX_CASE_SECONDS:g} s of a single case run at once ({advice})",
                    "case_too_long",
                )
            ]
        )


def mode_shapes(batch: SceneBatch) -> tuple[modal.Modes, np.ndarray]:
    """The natural modes of case 0 of ``batch`` with its stages at home (the matrices and the eigen
    problem :func:`isolab.engine.simulate` solves, so the order and frequencies are the result's), and
    each mode's shape as the rigid-body motion of the base about its c.g.: (mode, 6) rows of x, y, z (m)
    and rx, ry, rz (rad), scaled so that the isolator point that moves most moves by 1 m, signed so that
    the degree of freedom holding the most kinetic energy moves positively."""
    M = engine_model.mass_matrix(batch)
    found = modal.modes(M, engine_model.stiffness_matrix(batch), engine_model.damping_matrix(batch))
    phi = np.asarray(found.shapes[0]).T  # (mode, dof)
    arms = np.asarray(batch.iso_pos[0]) - np.asarray(batch.cg[0])  # (n, 3) m
    moved = phi[:, None, :3] + np.cross(phi[:, None, 3:], arms[None])  # (mode, n, 3)
    reach = np.linalg.norm(moved, axis=-1).max(axis=-1)
    dominant = np.argmax(np.asarray(found.energy[0]), axis=-1)
    sign = np.where(phi[np.arange(phi.shape[0]), dominant] < 0, -1.0, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return found, phi * (sign / np.where(reach > 0, reach, 1.0))[:, None]


def _finite(values: np.ndarray) -> list[float | None]:
    return [float(v) if math.isfinite(v) else None for v in np.asarray(values, dtype=np.float64).tolist()]


def run_single_case(study: Study, max_points: int = DEFAULT_TRACE_POINTS) -> dict[str, Any]:
    """Run the one case of ``study`` (from :func:`single_case_study`) with its histories recorded.

    Returns the answer of ``POST /simulations``: ``status`` and ``message``; ``model`` (fidelity,
    integrator, dt in s, duration in s, engine seconds); ``summary``: the case-table columns of the case,
    each ``{"value", "unit", "long_name"}`` (SI; margins of the scene's criteria as fractions of their
    limits, when it has criteria); ``isolators`` (each one's place on the base and position); ``modes``,
    each with its ``shape`` (:func:`mode_shapes`); ``settling_time``, ``settled``, ``last_move_end``;
    ``traces`` (time, c.g. displacement, rotation, isolator forces, point displacements and stage
    profiles, SI, units under ``units``), every ``every``-th of ``n_samples`` samples, at most
    ``max_points`` a trace.

    Raises:
        DefinitionError: ``max_points`` outside 2..:data:`MAX_TRACE_POINTS`, or a scene the engine refuses.
    """
    if not 2 <= max_points <= MAX_TRACE_POINTS:
        raise DefinitionError(
            [detail(["body", "max_points"], f"must be between 2 and {MAX_TRACE_POINTS}, got {max_points}")]
        )
    sim = study.simulation
    fidelity, integrator, dt = sim.engine_choice()
    batch = study.batch(np.array([0]))
    started = time.perf_counter()
    try:
        result = simulate(
            batch, fidelity=fidelity, integrator=integrator, dt=dt, auto_step=sim.auto_step, record=[0]
        )
    except ValueError as err:
        raise DefinitionError([detail(["body", "scene"], str(err))]) from None
    seconds = time.perf_counter() - started
    isolators, points = study_labels(study)
    table = case_table(
        add_criteria(
            to_dataset(result, study.design(), isolator_names=isolators, point_names=points), study.criteria
        )
    )
    summary = {}
    for column in table.names:
        if column == "case":
            continue
        value = json_values(table.data[column][:1], table.kinds[column])[0]
        summary[column] = {
            "value": value,
            "unit": table.units[column],
            "long_name": table.long_names.get(column, column),
        }
    history = recorded_history(study, 0, batch, result)
    n = int(history.time.size)
    every = max(1, math.ceil(n / max_points))
    full = history_json("", 0, history, every)
    traces = {key: full[key] for key in TRACE_KEYS}
    shapes = mode_shapes(batch)[1]
    for mode in full["modes"]:
        mode["shape"] = dict(zip(DOF_NAMES, _finite(shapes[mode["mode"] - 1]), strict=True))
    return {
        "status": history.status,
        "message": history.message,
        "model": {
            "fidelity": fidelity,
            "integrator": integrator,
            "dt": float(result.dt[0]),
            "duration": float(np.asarray(batch.duration)[0]),
            "engine_seconds": seconds,
        },
        "summary": summary,
        "isolators": isolator_places(history.isolator_names, history.isolator_positions),
        "modes": full["modes"],
        "settling_time": full["settling_time"],
        "settled": full["settled"],
        "last_move_end": full["last_move_end"],
        "n_samples": n,
        "every": every,
        "max_points": max_points,
        "traces": traces,
    }
