"""The velocity spectra a floor spectrum gives at a point of interest, per isolator type: what the plots
and the documentation of floor vibration show (:mod:`studies.questions.floor` reads the spectrum; the engine's
:mod:`~isolab.engine.frequency` computes the steady-state response)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from pydantic import BaseModel, Field

from isolab.engine import frequency
from isolab.engine.frequency import BAND_CENTRES, BAND_LOWER, BAND_UPPER, NOMINAL_CENTRES
from isolab.engine.results import AXES
from isolab.studies.answers.comparisons import comparison_study
from isolab.studies.inputs.definitions import DefinitionError, detail
from isolab.studies.inputs.parameters import scene_dict
from isolab.studies.inputs.schema import Scene
from isolab.studies.inputs.study import Study
from isolab.studies.questions.floor import ISO_LEVELS, ISO_RANGE, VC_LEVELS, VC_RANGE


def velocity_spectra(
    source: Any,
    isolator_types: Sequence[str] | None = None,
    point: str | None = None,
    case: int = 0,
    simulation: Any = None,
) -> dict[str, Any]:
    """One-third-octave RMS velocity of a point of interest under the floor spectrum, per isolator type.

    Args:
        source: a scene (:class:`~isolab.studies.inputs.schema.Scene`, or its definition as data) or a study
        and
            one of its cases (``case``): the study's scene with that case's values, simulation block and
            all.
        isolator_types: presets to compare (default: the scene's own type only).
        point: a point of interest of the scene (default: its first).
        case: the study case, when ``source`` is a study.
        simulation: overrides of the scene's simulation block (only ``gravity_stiffness`` matters here).

    Returns:
        ``{"point", "band_centres" (20,) Hz (exact), "band_edges" (21,) Hz, "nominal_centres",
        "floor" (3, 20) m/s,
        "velocity": {type: (3, 20) m/s per axis x, y, z (NaN: a tipping or mechanism case)},
        "worst": {type: (m/s, Hz of that band, axis)}}``.

    Raises:
        ValueError (a DefinitionError for bad input, naming the field): an unknown point, a scene
            without points or without a floor spectrum.
    """
    study, names, batch, types = _floor_batch(source, isolator_types, case, simulation, point)
    point = names[0] if point is None else point
    bands = frequency.batch_point_band_velocity(batch)[:, names.index(point)]  # (C, 3, 20)
    labels = [str(v) for v in study.design().values[study.design().names[0]]]
    velocity = {t: bands[labels.index(t)] for t in types}
    worst = {}
    for t, v in velocity.items():
        if np.isnan(v).any():
            worst[t] = (float("nan"), float("nan"), "")
            continue
        a, b = np.unravel_index(int(np.argmax(v)), v.shape)
        worst[t] = (float(v[a, b]), float(BAND_CENTRES[b]) if v[a, b] > 0 else 0.0, AXES[a])
    return {
        "point": point,
        "band_centres": BAND_CENTRES.copy(),
        "band_edges": np.append(BAND_LOWER, BAND_UPPER[-1]),
        "nominal_centres": np.array(NOMINAL_CENTRES, dtype=float),
        "floor": np.asarray(batch.floor_band_velocity)[0],
        "velocity": velocity,
        "worst": worst,
    }


class FloorCurve(BaseModel):
    """A line of the vibration-criteria chart: flat ``velocity`` from band ``low`` to band ``high``."""

    name: str = Field(description="VC-A .. VC-G, or an ISO 2631-2 line")
    velocity: float = Field(description="one-third-octave RMS velocity, m/s")
    low: float = Field(description="nominal centre of the first band it covers, Hz")
    high: float = Field(description="nominal centre of the last band it covers, Hz")


class PointWorst(BaseModel):
    """The largest band of a point's spectrum."""

    velocity: float | None = Field(description="one-third-octave RMS velocity, m/s (null: not computed)")
    band: float | None = Field(description="nominal centre of that band, Hz")
    axis: str = Field(description="floor axis of that band")


class FloorSpectra(BaseModel):
    """The floor-induced one-third-octave velocity at every point of interest, per isolator type, with the
    VC curves (:func:`point_spectra`); m/s and Hz."""

    unit: str = Field("m/s", description="unit of every velocity")
    band_centres: list[float] = Field(description="exact band centres 10^(n/10), Hz")
    nominal_centres: list[float] = Field(description="nominal band centres (1, 1.25 ... 80), Hz")
    band_edges: list[float] = Field(description="band edges, Hz (one more than the bands)")
    isolator_types: list[str]
    points: list[str] = Field(description="the scene's points of interest, in order")
    floor: dict[str, list[float]] = Field(description="the floor's band velocity per axis x, y, z, m/s")
    velocity: dict[str, dict[str, dict[str, list[float | None]]]] = Field(
        description="type -> point -> axis -> band velocity, m/s (null: a case with a mechanism or tipping)"
    )
    worst: dict[str, dict[str, PointWorst]] = Field(description="type -> point -> its largest band")
    curves: list[FloorCurve] = Field(description="VC-A .. VC-G, then the ISO 2631-2 lines")
    criteria: dict[str, str] = Field(description="point -> the VC curve its velocity criterion names")
    case: int | None = Field(None, description="the study case the spectra are of, for a stored study")


def vc_curves() -> list[FloorCurve]:
    """The lines of the vibration-criteria chart: VC-A .. VC-G (1 to 80 Hz) and the ISO 2631-2 workshop
    and office lines (8 to 80 Hz)."""
    return [
        FloorCurve(name=k, velocity=v, low=VC_RANGE[0], high=VC_RANGE[1]) for k, v in VC_LEVELS.items()
    ] + [FloorCurve(name=k, velocity=v, low=ISO_RANGE[0], high=ISO_RANGE[1]) for k, v in ISO_LEVELS.items()]


def _listed(values: np.ndarray) -> list[float | None]:
    return [float(v) if np.isfinite(v) else None for v in np.asarray(values, dtype=np.float64)]


def point_spectra(
    source: Any,
    isolator_types: Sequence[str] | None = None,
    case: int = 0,
    simulation: Any = None,
) -> FloorSpectra:
    """One-third-octave RMS velocity of every point of interest under the floor spectrum, per isolator type
    and floor axis, with the VC curves and the curve each point's velocity criterion names.

    Args: as :func:`velocity_spectra`; ``source`` a scene or its definition as data (on each of
    ``isolator_types``), or a study and its ``case`` (on the case's own isolators).

    Raises:
        ValueError (a DefinitionError for bad input, naming the field): a scene without points or without a
            floor spectrum.
    """
    if isinstance(source, Study):  # the case as the study ran it, on its own isolators
        scene, names, batch = _case_floor_batch(source, case)
        types = labels = [str(getattr(scene.isolators, "preset", None) or "as given")]
    else:
        study, names, batch, types = _floor_batch(source, isolator_types, case, simulation)
        scene = study.base_scene
        labels = [str(v) for v in study.design().values[study.design().names[0]]]
    bands = frequency.batch_point_band_velocity(batch)  # (C, p, 3, 20) m/s
    velocity: dict[str, dict[str, dict[str, list[float | None]]]] = {}
    worst: dict[str, dict[str, PointWorst]] = {}
    for t in types:
        per_point = bands[labels.index(t)]
        velocity[t] = {
            p: {a: _listed(per_point[j, k]) for k, a in enumerate(AXES)} for j, p in enumerate(names)
        }
        worst[t] = {}
        for j, p in enumerate(names):
            v = per_point[j]
            if np.isnan(v).any():
                worst[t][p] = PointWorst(velocity=None, band=None, axis="")
                continue
            a, b = np.unravel_index(int(np.argmax(v)), v.shape)
            worst[t][p] = PointWorst(velocity=float(v[a, b]), band=float(NOMINAL_CENTRES[b]), axis=AXES[a])
    criteria = scene.criteria
    judged = {p: str(c.velocity) for p, c in (criteria.points if criteria else {}).items() if c.velocity}
    floor = np.asarray(batch.floor_band_velocity)[0]
    return FloorSpectra(
        band_centres=BAND_CENTRES.tolist(),
        nominal_centres=[float(f) for f in NOMINAL_CENTRES],
        band_edges=np.append(BAND_LOWER, BAND_UPPER[-1]).tolist(),
        isolator_types=types,
        points=names,
        floor={a: [float(v) for v in floor[k]] for k, a in enumerate(AXES)},
        velocity=velocity,
        worst=worst,
        curves=vc_curves(),
        criteria=judged,
        case=case if isinstance(source, Study) else None,
    )


def _case_floor_batch(study: Study, case: int) -> tuple[Scene, list[str], Any]:
    """The scene of a study's case, its points and its one-case engine batch; a DefinitionError (at the
    path's ``case``) for a case without points or floor spectrum."""
    scene = study.case_scene(case)
    names = list(scene.points)
    if not names:
        raise DefinitionError([detail(["path", "case"], "the study's scene has no points of interest")])
    batch = study.batch([case])
    if not scene.has_floor_spectrum() or not batch.has_floor_spectrum:
        raise DefinitionError(
            [detail(["path", "case"], "the study's scene has no floor.spectrum: no floor-induced velocity")]
        )
    return scene, names, batch


def _floor_batch(
    source: Any, isolator_types: Sequence[str] | None, case: int, simulation: Any, point: str | None = None
) -> tuple[Study, list[str], Any, list[str]]:
    """The comparison study of ``source`` on each type, its points, its engine batch and the types; a
    DefinitionError naming the field for a scene without points or floor spectrum, or an unknown
    ``point``."""
    if isinstance(source, Study):
        scene = source.case_scene(case)
    elif isinstance(source, Scene):
        scene = source
    else:
        scene = None
    data = scene_dict(scene) if scene is not None else source
    types = list(dict.fromkeys(isolator_types)) if isolator_types else None
    if types is None:
        types = [str(scene.isolators.preset)] if scene is not None else [str(_preset_of(source))]
    study = comparison_study(data, types, simulation, prefix=["body"])
    built = study.scene
    assert built is not None  # a validated study has its scene
    names = list(built.points)
    if not names:
        raise DefinitionError([detail(["body", "scene", "points"], "the scene has no points of interest")])
    if point is not None and point not in names:
        raise DefinitionError(
            [detail(["body", "point"], f"no point of interest named {point!r} (points: {', '.join(names)})")]
        )
    if not built.has_floor_spectrum():
        raise DefinitionError(
            [
                detail(
                    ["body", "scene", "floor"],
                    "give the floor's vibration as floor.spectrum (or floor.per_mount) to draw spectra",
                )
            ]
        )
    batch = study.batch(np.arange(study.n_cases))
    if not batch.has_floor_spectrum:
        raise DefinitionError(
            [detail(["body", "scene", "floor", "spectrum"], "every band of the floor spectrum is zero")]
        )
    return study, names, batch, types


def _preset_of(data: Any) -> str:
    try:
        return str(data["isolators"].get("preset", "air"))
    except (TypeError, KeyError, AttributeError):
        return "air"
