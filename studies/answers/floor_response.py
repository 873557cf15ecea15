"""The velocity spectra a floor spectrum gives at a point of interest, per isolator type: what the plots
and the documentation of floor vibration show (:mod:`studies.questions.floor` reads the spectrum; the engine's
:mod:`~isolab.engine.frequency` computes the steady-state response)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from isolab.engine import frequency
from isolab.engine.frequency import BAND_CENTRES, BAND_LOWER, BAND_UPPER, NOMINAL_CENTRES
from isolab.engine.results import AXES
from isolab.studies.answers.comparisons import comparison_study
from isolab.studies.inputs.definitions import DefinitionError, detail
from isolab.studies.inputs.parameters import scene_dict
from isolab.studies.inputs.schema import Scene
from isolab.studies.inputs.study import Study


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
    if point is None:
        point = names[0]
    if point not in names:
        raise DefinitionError(
            [detail(["body", "point"], f"no point of interest named {point!r} (points: {', '.join(names)})")]
        )
    if built.floor is None or built.floor.spectrum is None:
        raise DefinitionError(
            [
                detail(
                    ["body", "scene", "floor"], "give the floor's vibration as floor.spectrum to draw spectra"
                )
            ]
        )
    batch = study.batch(np.arange(study.n_cases))
    if not batch.has_floor_spectrum:
        raise DefinitionError(
            [detail(["body", "scene", "floor", "spectrum"], "every band of the floor spectrum is zero")]
        )
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


def _preset_of(data: Any) -> str:
    try:
        return str(data["isolators"].get("preset", "air"))
    except (TypeError, KeyError, AttributeError):
        return "air"
