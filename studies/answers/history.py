"""Time histories of one case, recomputed from its stored definition.

A study stores peaks, not traces: :func:`case_history` reruns one case through the engine with its
histories recorded (c.g. displacement, base rotation, dynamic isolator forces about the preload, point
displacements), with the model the study's cases ran with, and with the case's stage motion profiles on
the same time axis, its natural modes (each named by its dominant motion, :func:`mode_name`) and its
settling. :func:`history_json` and :func:`history_dataset` give them as JSON-able data and as a
CF-described xarray dataset.
"""

from __future__ import annotations

import functools
import json
import math
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

import isolab.engine
from isolab.engine import STATUS_NAMES
from isolab.engine.modal import MOTION_NAMES
from isolab.engine.profiles import Pieces, evaluate
from isolab.engine.results import AXES, DOF_NAMES, OUTPUTS, ROTATIONS, SimulationResult
from isolab.engine.scene import SceneBatch
from isolab.studies.inputs.definitions import definition_json, study_of
from isolab.studies.inputs.isolators import mount_places
from isolab.studies.inputs.study import Study, study_from_json, study_labels
from isolab.studies.results.cases import CaseQueryError
from isolab.studies.results.netcdf_locks import netcdf_writing
from isolab.studies.results.store import Store, StudyRecord
from isolab.studies.run.accuracy import recorded_choice, resolved_definition, resolved_study

if TYPE_CHECKING:  # xarray loads with the first history dataset (a mode name needs none)
    import xarray as xr

MAX_RECORDED_SAMPLES = 2_000_000
"""Longest time history (samples) a case is recomputed with: about 200 bytes a sample in memory."""
MAX_RETURNED_SAMPLES = 200_000
"""Most samples per series one answer holds (``every`` thins them)."""


COUPLED_SHARE = 0.25
"""A second degree of freedom with at least this kinetic-energy share is named too (``pitch + sway``)."""


def mode_name(energy: np.ndarray) -> str:
    """A mode named by its dominant motion from its kinetic-energy shares per degree of freedom (x, y, z,
    rx, ry, rz): ``heave``, or ``pitch + sway`` when a second motion holds at least
    :data:`COUPLED_SHARE` of the energy; ``""`` when the shares are not numbers."""
    e = np.asarray(energy, dtype=np.float64).reshape(-1)
    if e.size != len(DOF_NAMES) or not np.all(np.isfinite(e)) or e.sum() <= 0:
        return ""
    order = np.argsort(-e)
    name = MOTION_NAMES[DOF_NAMES[order[0]]]
    if e[order[1]] >= COUPLED_SHARE * e.sum():
        name += " + " + MOTION_NAMES[DOF_NAMES[order[1]]]
    return name


class CaseNotFound(LookupError):
    """A study has no case of that number."""


@dataclass
class CaseHistory:
    """Time histories of one case (SI): arrays trimmed to the samples the run produced."""

    parameters: dict[str, Any]
    status: str
    message: str
    time: np.ndarray  # (T,) s
    displacement: np.ndarray  # (T, 3) m
    rotation: np.ndarray  # (T, 3) rad
    isolator_force: np.ndarray  # (T, n, 3) N
    point_displacement: np.ndarray  # (T, p, 3) m
    isolator_names: list[str]
    point_names: list[str]
    isolator_positions: np.ndarray | None = None  # (n, 3) m, in the scene's floor frame
    stage_names: list[str] | None = None
    stage_position: np.ndarray | None = None  # (m, T) m, along each stage's axis
    stage_velocity: np.ndarray | None = None  # (m, T) m/s
    stage_acceleration: np.ndarray | None = None  # (m, T) m/s^2
    natural_frequency: np.ndarray | None = None  # (6,) Hz, ascending
    damping_ratio: np.ndarray | None = None  # (6,) 1
    mode_energy: np.ndarray | None = None  # (6, 6) share of each DOF in each mode
    settling_time: float = math.nan  # s after the last stage move
    settled: bool = False
    last_move_end: float = math.nan  # s


def case_history(study: Study, case: int, every: int = 1) -> CaseHistory:
    """Recompute one case with its time histories recorded (runs the engine: call it off the event loop).

    Refused (:class:`~isolab.studies.results.cases.CaseQueryError`) when the case would record more than
    :data:`MAX_RECORDED_SAMPLES` samples, or return more than :data:`MAX_RETURNED_SAMPLES` with every
    ``every``-th kept."""
    sim = study.simulation
    try:
        batch = study.batch([case])
    except ValueError as err:  # a combination of values no scene can have
        raise CaseQueryError("case", f"case {case} cannot be simulated: {err}", where="path") from None
    if sim.dt is not None:
        samples = int(math.ceil(float(np.asarray(batch.duration)[0]) / float(sim.dt))) + 1
        if samples > MAX_RECORDED_SAMPLES:
            raise CaseQueryError(
                "case",
                f"case {case} runs {samples} time steps; time histories are recomputed only for cases of "
                f"at most {MAX_RECORDED_SAMPLES} (a shorter duration or a longer step)",
                where="path",
            )
        if math.ceil(samples / every) > MAX_RETURNED_SAMPLES:
            raise CaseQueryError(
                "every",
                f"case {case} has {samples} samples; keep at most {MAX_RETURNED_SAMPLES} "
                f"(every >= {math.ceil(samples / MAX_RETURNED_SAMPLES)})",
            )
    fidelity, integrator, dt = sim.engine_choice()  # the study's own, or what its runner chose
    result = isolab.engine.simulate(  # the kernels load with the first case asked for
        batch, fidelity=fidelity, integrator=integrator, dt=dt, auto_step=sim.auto_step, record=[0]
    )
    return recorded_history(study, case, batch, result)


def recorded_history(study: Study, case: int, batch: SceneBatch, result: SimulationResult) -> CaseHistory:
    """The :class:`CaseHistory` of case ``case`` of ``study``, from the engine's ``result`` of a one-case
    ``batch`` of it that recorded its histories (``record=[0]``)."""
    scene = study.scene
    assert scene is not None  # a validated study has its scene
    h = result.history
    assert h is not None  # asked for with record=[0]
    n = int(h["n_samples"][0])
    iso, pts = study_labels(study)
    time = np.asarray(h["time"][0, :n])
    pieces = Pieces(batch.prof_t[0], batch.prof_s[0], batch.prof_v[0], batch.prof_a[0], batch.prof_j[0])
    stage_s, stage_v, stage_a = evaluate(pieces, time) if time.size else (np.zeros((0, 0)),) * 3
    return CaseHistory(
        parameters=study.case_values(case),
        status=STATUS_NAMES[int(result.status[0])],
        message=str(result.message[0]),
        time=time,
        displacement=np.asarray(h["displacement"][0, :n]),
        rotation=np.asarray(h["rotation"][0, :n]),
        isolator_force=np.asarray(h["isolator_force"][0, :n]),
        point_displacement=np.asarray(h["point_displacement"][0, :n]),
        isolator_names=iso,
        point_names=pts,
        isolator_positions=np.asarray(batch.iso_pos)[0],
        stage_names=[str(st.name) for st in scene.stages],
        stage_position=stage_s,
        stage_velocity=stage_v,
        stage_acceleration=stage_a,
        natural_frequency=np.asarray(result.natural_frequency[0]),
        damping_ratio=np.asarray(result.damping_ratio[0]),
        mode_energy=np.asarray(result.mode_energy[0]),
        settling_time=float(result.settling_time[0]),
        settled=bool(result.settled[0]),
        last_move_end=float(batch.last_move_end()[0]),
    )


def case_study(record: StudyRecord, case: int, store: Store | None = None) -> Study:
    """The study of a catalog ``record`` as its case ``case`` runs: an accuracy request resolved to the
    model the runner chose and recorded. An optimisation's cases are the candidates it evaluated (their
    parameter values read from its dataset in ``store``): the study returned lists them, case for case (a
    robust optimisation's candidate as its nominal case, the tolerances at their nominal values).

    Raises:
        CaseNotFound: the study has no such case (an optimisation: none before its dataset is written).
    """
    study = study_of(record)
    if study.goals is not None:
        return _candidate_study(record, study, case, store)
    if not 0 <= case < record.n_cases:
        raise CaseNotFound(f"study {record.id} has no case {case} (cases 0..{record.n_cases - 1})")
    if study.simulation.request is None:
        return study
    choice = recorded_choice(study, record.fidelity, record.integrator, record.dt)
    return _resolved(definition_json(record), choice)


def _candidate_study(record: StudyRecord, study: Study, case: int, store: Store | None) -> Study:
    """An optimisation's study with a list design of the candidates its dataset holds (case ``case`` among
    them), run at the model its runner recorded."""
    goals = study.goals
    assert goals is not None  # an optimisation's study
    names = [f.name for f in goals.factors]
    try:
        if store is None:
            raise FileNotFoundError
        with store.open_dataset(record.id) as ds:
            values = {n: np.asarray(ds[n].values, dtype=np.float64).reshape(-1) for n in names}
    except (FileNotFoundError, OSError, KeyError):
        raise CaseNotFound(
            f"study {record.id} has no stored candidates yet (its dataset is not written)"
        ) from None
    n = len(values[names[0]]) if names else 0
    if not 0 <= case < n:
        raise CaseNotFound(f"study {record.id} has no case {case} (cases 0..{n - 1})")
    choice = recorded_choice(study, record.fidelity, record.integrator, record.dt)
    definition = dict(record.definition) if choice is None else resolved_definition(study, choice)
    base = {k: v for k, v in definition.items() if k not in ("design", "design_spec")}
    cases = [{k: float(values[k][i]) for k in names} for i in range(n)]
    return study_from_json(json.dumps({**base, "design": {"type": "list", "cases": cases}}, sort_keys=True))


@functools.lru_cache(maxsize=16)
def _resolved(definition: str, choice: Any) -> Study:
    return resolved_study(study_from_json(definition), choice)


def _series(a: np.ndarray) -> list[float | None]:
    return [v if math.isfinite(v) else None for v in np.asarray(a, dtype=np.float64).tolist()]


def history_json(study_id: str, case: int, h: CaseHistory, every: int) -> dict[str, Any]:
    """The histories as JSON-able data, every ``every``-th sample, SI units named under ``units``."""
    s = slice(None, None, every)
    axes, rots = AXES, ROTATIONS
    return {
        "study_id": study_id,
        "case": case,
        "parameters": h.parameters,
        "status": h.status,
        "message": h.message,
        "units": {
            "time": "s",
            "displacement": "m",
            "rotation": "rad",
            "isolator_force": "N",
            "point_displacement": "m",
            "stage_position": "m",
            "stage_velocity": "m/s",
            "stage_acceleration": "m/s^2",
            "natural_frequency": OUTPUTS["natural_frequency"].unit,
            "settling_time": OUTPUTS["settling_time"].unit,
        },
        "time": _series(h.time[s]),
        "displacement": {a: _series(h.displacement[s, k]) for k, a in enumerate(axes)},
        "rotation": {r: _series(h.rotation[s, k]) for k, r in enumerate(rots)},
        "isolator_force": {
            iso: {a: _series(h.isolator_force[s, j, k]) for k, a in enumerate(axes)}
            for j, iso in enumerate(h.isolator_names)
        },
        "point_displacement": {
            p: {a: _series(h.point_displacement[s, j, k]) for k, a in enumerate(axes)}
            for j, p in enumerate(h.point_names)
        },
        "isolators": isolator_places(h.isolator_names, h.isolator_positions),
        "stages": {
            name: {
                "position": _series(h.stage_position[j, s]),
                "velocity": _series(h.stage_velocity[j, s]),
                "acceleration": _series(h.stage_acceleration[j, s]),
            }
            for j, name in enumerate(h.stage_names or [])
            if h.stage_position is not None
            and h.stage_velocity is not None
            and h.stage_acceleration is not None
        },
        "modes": _modes(h),
        "settling_time": _number(h.settling_time),
        "settled": h.settled,
        "last_move_end": _number(h.last_move_end),
    }


def isolator_places(names: list[str], positions: np.ndarray | None) -> dict[str, dict[str, Any]]:
    """Each isolator's ``place`` on the base in words (:func:`~isolab.studies.inputs.isolators.mount_places`),
    its ``position`` (m, the scene's floor frame) and a ``label`` for people: ``front-left (x 0.20 m,
    y 0.30 m)``. Empty without positions."""
    if positions is None:
        return {}
    xyz = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    places = mount_places(xyz)
    return {
        name: {
            "place": place,
            "position": [float(v) for v in xyz[j]],
            "label": f"{place} (x {xyz[j, 0]:.2f} m, y {xyz[j, 1]:.2f} m)",
        }
        for j, (name, place) in enumerate(zip(names, places, strict=True))
    }


def _number(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _modes(h: CaseHistory) -> list[dict[str, Any]]:
    """Each natural mode: frequency (Hz), damping ratio, energy shares per DOF and its name."""
    if h.natural_frequency is None or h.mode_energy is None or h.damping_ratio is None:
        return []
    out = []
    for k in range(h.natural_frequency.shape[0]):
        energy = h.mode_energy[k]
        out.append(
            {
                "mode": k + 1,
                "frequency": _number(float(h.natural_frequency[k])),
                "damping_ratio": _number(float(h.damping_ratio[k])),
                "energy": dict(zip(DOF_NAMES, _series(energy), strict=True)),
                "name": mode_name(energy),
            }
        )
    return out


def history_dataset(study_id: str, case: int, h: CaseHistory, every: int) -> xr.Dataset:
    """The histories as a CF-described dataset: ``displacement`` (time, axis), ``base_rotation``
    (time, rotation), ``isolator_force`` (time, isolator, axis), ``point_displacement``
    (time, point, axis)."""
    import xarray as xr

    s = slice(None, None, every)
    ds = xr.Dataset(
        {
            "displacement": (
                ("time", "axis"),
                h.displacement[s],
                {"units": "m", "long_name": "displacement of the machine c.g."},
            ),
            "base_rotation": (
                ("time", "rotation"),
                h.rotation[s],
                {"units": "rad", "long_name": "rotation of the machine base"},
            ),
            "isolator_force": (
                ("time", "isolator", "axis"),
                h.isolator_force[s],
                {"units": "N", "long_name": "dynamic isolator force"},
            ),
            "point_displacement": (
                ("time", "point", "axis"),
                h.point_displacement[s],
                {"units": "m", "long_name": "displacement of a point of interest"},
            ),
        },
        coords={
            "time": ("time", h.time[s], {"units": "s", "long_name": "time"}),
            "axis": ("axis", np.array(AXES), {"units": "1", "long_name": "floor axis (Z up)"}),
            "rotation": (
                "rotation",
                np.array(ROTATIONS),
                {"units": "1", "long_name": "rotation axis"},
            ),
            "isolator": (
                "isolator",
                np.array(h.isolator_names, dtype=str).reshape(-1),
                {"units": "1", "long_name": "isolator"},
            ),
            "point": (
                "point",
                np.array(h.point_names, dtype=str).reshape(-1),
                {"units": "1", "long_name": "point of interest"},
            ),
        },
    )
    ds.attrs = {
        "Conventions": "CF-1.10",
        "title": f"isolab study {study_id} case {case}",
        "study_id": study_id,
        "case": case,
        "status": h.status,
        "message": h.message,
        "parameters": json.dumps(h.parameters, sort_keys=True),
    }
    return ds


def netcdf_bytes(ds: xr.Dataset) -> bytes:
    """``ds`` as the bytes of a netCDF4 file."""
    with tempfile.TemporaryDirectory(prefix="isolab-") as tmp:
        path = Path(tmp) / "case.nc"
        with netcdf_writing():
            ds.to_netcdf(path, format="NETCDF4", engine="netcdf4")
        return path.read_bytes()
