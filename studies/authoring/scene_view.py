"""A scene as an engineer builds it: what the service computes from it before anything runs, for a
picture of the machine and the forms that edit it.

- :func:`scene_view`: check a scene as ``POST /simulations`` checks it (the same 422 details) and answer
  the base's mass, inertia about its c.g. and c.g. (from its size and density when it is a block,
  :func:`isolab.studies.inputs.block.block_properties`), the box it is drawn as, each mount's place,
  static load, stiffness, damping and frequencies on that load, each stage at home with the line its
  profile travels along and its motion sampled over the run (position, velocity, acceleration from
  :mod:`isolab.engine.profiles`, for the profile plot), the points of interest, the natural modes with
  their shapes (:func:`isolab.studies.answers.single_case.mode_shapes`), and the scene as YAML text;
- :func:`example_scene_names`, :func:`example_scene`: the shipped examples that hold a scene (a scene
  file, or a study's scene) and each one's scene as written.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field

from isolab.engine import model as engine_model
from isolab.engine.profiles import Pieces, end_time, evaluate
from isolab.engine.results import DOF_NAMES
from isolab.studies.answers.history import isolator_places, mode_name
from isolab.studies.answers.single_case import mode_shapes
from isolab.studies.authoring.authoring import EXAMPLES_DIR, ExampleNotFound
from isolab.studies.inputs.definitions import DefinitionError, Loc, check_definition, detail
from isolab.studies.inputs.study import study_labels

TRAVEL_SAMPLES = 4001
"""Times a stage's profile is evaluated at (with its breakpoints) to find the ends of its travel."""
BOX_MARGIN = 0.1
"""A base given by mass and inertia is drawn as the box around its mounts, widened by this share."""
PROFILE_SAMPLES = 600
"""Evenly spaced times (with the profile's breakpoints) each stage's motion is sampled at for its plot."""
STUDY_NAME = "scene-study"
"""The name of the study the scene is handed to (``study_yaml``)."""


class SceneRequest(BaseModel):
    """A scene to check and describe."""

    model_config = ConfigDict(extra="forbid")

    scene: dict[str, Any] = Field(description="inline scene (as in a study's scene block)")


class SceneBase(BaseModel):
    """The machine base as the service computes it."""

    source: str = Field(description="block (from size and density) or given (mass, inertia and c.g.)")
    mass: float = Field(description="kg")
    inertia: list[list[float]] = Field(description="3x3 tensor about the c.g., kg m^2")
    cg: list[float] = Field(description="c.g. position, m")
    density: float | None = Field(None, description="kg/m^3, a block only")
    box_corner: list[float] = Field(description="the drawn box's minimum corner, m")
    box_size: list[float] = Field(description="the drawn box's sides lx, ly, lz, m (a block: its size)")
    total_mass: float = Field(description="base and stages, kg")


class SceneMount(BaseModel):
    """One isolator where it stands, with what it carries."""

    name: str
    place: str = Field(description="front-left...: -X left, -Y front")
    position: list[float] = Field(description="m")
    static_load: float = Field(description="vertical load at rest, N")
    stiffness: list[float] = Field(description="kx, ky, kz, N/m")
    damping: list[float] = Field(description="cx, cy, cz, N s/m")
    f_vertical: float | None = Field(description="vertical frequency on its static load, Hz")
    f_horizontal: float | None = Field(description="frequency along X on its static load, Hz")


class SceneProfile(BaseModel):
    """A stage's motion along its axis (relative to its parent) sampled over the run, from the engine's
    profile: at each breakpoint the value of the piece that starts there."""

    time: list[float] = Field(description="s")
    position: list[float] = Field(description="from home along the axis, m")
    velocity: list[float] = Field(description="m/s")
    acceleration: list[float] = Field(description="m/s^2")
    end: float = Field(description="time the last move ends, s")


class SceneStage(BaseModel):
    """One stage at home and the line its profile travels along."""

    name: str
    mass: float = Field(description="kg")
    home: list[float] = Field(description="m")
    axis: list[float] = Field(description="unit vector")
    parent: str | None = None
    travel: list[float] = Field(description="nearest and farthest position along its axis from home, m")
    travel_ends: list[list[float]] = Field(description="the two ends of its own travel, m (parents at home)")
    profile: SceneProfile = Field(description="its motion sampled over the run (what the plot draws)")


class SceneMode(BaseModel):
    """One natural mode of the base with its stages at home."""

    mode: int
    frequency: float | None = Field(description="undamped natural frequency, Hz")
    damping_ratio: float | None
    energy: dict[str, float | None] = Field(description="DOF (x, y, z, rx, ry, rz) -> kinetic-energy share")
    name: str = Field(description="dominant motion: heave, pitch, roll, yaw, surge, sway (+ a coupled one)")
    shape: dict[str, float | None] = Field(description="x, y, z (m), rx, ry, rz (rad): 1 m at the far mount")


class SceneView(BaseModel):
    """What the service computes from a scene before it runs."""

    base: SceneBase
    mounts: list[SceneMount]
    stages: list[SceneStage]
    points: dict[str, list[float]] = Field(description="point of interest -> position, m")
    modes: list[SceneMode]
    yaml: str = Field(description="the scene as a scene file (YAML)")
    study_yaml: str = Field(description="a study of the scene alone, ready for POST /studies/validate")


class SceneExample(BaseModel):
    """The scene of a shipped example."""

    name: str
    scene: dict[str, Any] = Field(description="the scene as written, units as text")


def _floats(values: Any) -> list[float]:
    return [float(v) for v in np.asarray(values, dtype=np.float64).reshape(-1)]


def _number(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def scene_view(scene: Any, prefix: Loc | None = None) -> dict[str, Any]:
    """Check ``scene`` (a scene as data, units as text allowed) and describe it (see the module).

    Raises:
        DefinitionError: one detail per problem, at ``prefix + ["scene", ...]`` (default ``["body"]``).
    """
    pre: Loc = ["body"] if prefix is None else list(prefix)
    study = check_definition({"name": STUDY_NAME, "scene": scene}, prefix=pre)
    parsed = study.scene
    assert parsed is not None  # a checked study has its scene
    try:
        batch = study.batch(np.array([0]))
    except ValueError as err:
        raise DefinitionError([detail([*pre, "scene"], f"cannot be simulated: {err}")]) from None
    isolators, points = study_labels(study)
    cg = np.asarray(batch.cg[0], dtype=np.float64)
    mass = float(np.asarray(batch.mass)[0])
    iso_pos = np.asarray(batch.iso_pos[0], dtype=np.float64)
    block = parsed.machine.block
    if block is not None:
        corner, size = np.asarray(block.corner, dtype=np.float64), np.asarray(block.size, dtype=np.float64)
    else:  # the box around the mounts, as high above them as the c.g. is, twice
        low, high = iso_pos.min(axis=0), iso_pos.max(axis=0)
        span = np.maximum(high - low, 1e-3)
        top = max(2.0 * cg[2] - float(low[2]), float(high[2]) + 1e-3)
        corner = np.array([low[0] - BOX_MARGIN * span[0], low[1] - BOX_MARGIN * span[1], high[2]])
        size = np.array([(1 + 2 * BOX_MARGIN) * span[0], (1 + 2 * BOX_MARGIN) * span[1], top - high[2]])
    base = {
        "source": "block" if block is not None else "given",
        "mass": mass,
        "inertia": [_floats(row) for row in np.asarray(batch.inertia[0])],
        "cg": _floats(cg),
        "density": float(block.density) if block is not None else None,
        "box_corner": _floats(corner),
        "box_size": _floats(size),
        "total_mass": mass + float(np.asarray(batch.stage_mass[0]).sum()),
    }
    load = np.asarray(engine_model.preload(batch)[0], dtype=np.float64)
    k, c = np.asarray(batch.iso_k[0]), np.asarray(batch.iso_c[0])
    places = isolator_places(isolators, iso_pos)
    mounts = []
    for j, name in enumerate(isolators):
        carried = load[j] / batch.g  # kg
        freq = [math.sqrt(k[j, a] / carried) / (2 * math.pi) if carried > 0 else math.nan for a in (2, 0)]
        mounts.append(
            {
                "name": name,
                "place": places[name]["place"],
                "position": _floats(iso_pos[j]),
                "static_load": float(load[j]),
                "stiffness": _floats(k[j]),
                "damping": _floats(c[j]),
                "f_vertical": _number(freq[0]),
                "f_horizontal": _number(freq[1]),
            }
        )
    duration = float(np.asarray(batch.duration)[0])
    breaks = np.asarray(batch.prof_t[0], dtype=np.float64).reshape(-1)
    times = np.unique(
        np.concatenate(
            [np.linspace(0.0, duration, TRAVEL_SAMPLES), breaks[np.isfinite(breaks) & (breaks >= 0)]]
        )
    )
    pieces = Pieces(batch.prof_t, batch.prof_s, batch.prof_v, batch.prof_a, batch.prof_j)
    position = np.asarray(evaluate(pieces, times)[0])[0] if parsed.stages else np.zeros((0, 1))
    profiles = stage_profiles(pieces, duration) if parsed.stages else []
    stages = []
    for j, stage in enumerate(parsed.stages):
        home = np.asarray(batch.stage_home[0, j], dtype=np.float64)
        axis = np.asarray(batch.stage_axis[0, j], dtype=np.float64)
        near, far = float(position[j].min()), float(position[j].max())
        stages.append(
            {
                "name": str(stage.name),
                "mass": float(batch.stage_mass[0, j]),
                "home": _floats(home),
                "axis": _floats(axis),
                "parent": stage.parent,
                "travel": [near, far],
                "travel_ends": [_floats(home + near * axis), _floats(home + far * axis)],
                "profile": profiles[j],
            }
        )
    found, shapes = mode_shapes(batch)
    modes = [
        {
            "mode": m + 1,
            "frequency": _number(float(found.frequency[0, m])),
            "damping_ratio": _number(float(found.damping_ratio[0, m])),
            "energy": dict(zip(DOF_NAMES, [_number(float(e)) for e in found.energy[0, m]], strict=True)),
            "name": mode_name(found.energy[0, m]),
            "shape": dict(zip(DOF_NAMES, [_number(float(v)) for v in shapes[m]], strict=True)),
        }
        for m in range(shapes.shape[0])
    ]
    return {
        "base": base,
        "mounts": mounts,
        "stages": stages,
        "points": {name: _floats(batch.points[0, j]) for j, name in enumerate(points)},
        "modes": modes,
        "yaml": yaml.safe_dump(scene, sort_keys=False, default_flow_style=None, allow_unicode=True),
        "study_yaml": yaml.safe_dump(
            {"name": STUDY_NAME, "scene": scene}, sort_keys=False, default_flow_style=None, allow_unicode=True
        ),
    }


def stage_profiles(pieces: Pieces, duration: float, samples: int = PROFILE_SAMPLES) -> list[dict[str, Any]]:
    """Each stage's position (m), velocity (m/s) and acceleration (m/s^2) along its axis at ``samples``
    evenly spaced times over ``[0, duration]`` (s) and at every breakpoint inside it (and just before it,
    so a step of acceleration is drawn as a step), for the first case of ``pieces`` (shape (C, m, K));
    with the time its last move ends (s)."""
    breaks = np.asarray(pieces.t[0], dtype=np.float64).reshape(-1)
    inside = breaks[np.isfinite(breaks) & (breaks >= 0) & (breaks <= duration)]
    just_before = np.maximum(inside - 1e-9 * max(duration, 1.0), 0.0)
    times = np.unique(np.concatenate([np.linspace(0.0, duration, samples), inside, just_before]))
    s, v, a = (np.asarray(x)[0] for x in evaluate(pieces, times))
    ends = np.asarray(end_time(pieces))[0]
    return [
        {
            "time": _floats(times),
            "position": _floats(s[j]),
            "velocity": _floats(v[j]),
            "acceleration": _floats(a[j]),
            "end": float(ends[j]),
        }
        for j in range(s.shape[0])
    ]


def example_scene_names() -> list[str]:
    """Names (file stems) of the shipped examples that hold a scene, sorted."""
    names = []
    for path in sorted(EXAMPLES_DIR.glob("*.yaml")):
        try:
            example_scene(path.stem)
        except ExampleNotFound:
            continue
        names.append(path.stem)
    return names


def example_scene(name: str) -> dict[str, Any]:
    """The scene of the shipped example ``name`` (a scene file such as ``article-scriber``, or the scene of
    an example study, its ``scene_file`` read, with the study's own ``floor`` and ``criteria`` in place of
    the scene's, as when the study runs), as written: ``{"name", "scene"}``.

    Raises:
        ExampleNotFound: no example file of that name holds a scene.
    """
    known = {p.stem: p for p in EXAMPLES_DIR.glob("*.yaml")}
    path = known.get(name)
    data = yaml.safe_load(path.read_text(encoding="utf-8")) if path is not None else None
    study_parts = (
        {k: data[k] for k in ("floor", "criteria") if k in data}
        if isinstance(data, dict) and ("scene" in data or "scene_file" in data)
        else {}
    )
    if isinstance(data, dict) and isinstance(data.get("scene_file"), str):
        scene_path = EXAMPLES_DIR / data["scene_file"]
        data = (
            {"scene": yaml.safe_load(scene_path.read_text(encoding="utf-8"))}
            if scene_path.is_file()
            else None
        )
    scene = data.get("scene", data) if isinstance(data, dict) else None
    if not isinstance(scene, dict) or "machine" not in scene:
        raise ExampleNotFound(f"no example scene {name!r}; examples: {', '.join(sorted(known))}")
    return {"name": name, "scene": {**scene, **study_parts}}
