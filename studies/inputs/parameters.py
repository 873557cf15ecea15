"""Parameter paths: which input of a scene a study varies, and how to set it.

A path is dotted, with stage and point names and list indices as segments, following the scene's own
structure (see :mod:`studies.inputs.schema`)::

    machine.mass                    machine.block.density        machine.block.size.y
    isolators.preset                isolators.f_vertical         isolators.zeta
    isolators.layout.span_x         isolators.list.2.position.0  isolators.list.2.preset
    isolators.k.z                   isolators.c.horizontal       (explicit values on every mount)
    stages.y.mass                   stages.y.home.z              stages.y.profile.acceleration
    stages.y.profile.segments.1.velocity                         points.tool.z
    floor.sine.amplitude.z          simulation.duration          simulation.settle_tolerance

Vector components may be written 0/1/2 or x/y/z. ``isolators.k.horizontal`` sets ``k.x`` and ``k.y``,
``isolators.k.vertical`` sets ``k.z`` (same for ``c``). A path exists only where the scene has that input
(``machine.mass`` for a machine given by mass, ``isolators.layout.*`` for a layout, a profile's ``jerk``
for an S-curve or a scan).

Categorical parameters (isolator types) are applied to the scene and validated by pydantic; continuous
ones become per-case arrays that :func:`studies.inputs.scenes.build_batch` reads as overrides (``writes``).
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, cast

import numpy as np

from isolab.engine.profiles import SHAPERS
from isolab.engine.results import AXES
from isolab.studies.inputs.catalogues import scene_catalogue
from isolab.studies.inputs.isolators import PRESETS
from isolab.studies.inputs.schema import (
    MoveSegment,
    ScanProfile,
    Scene,
    SCurveProfile,
    SequenceProfile,
)
from isolab.studies.inputs.schema.scene_paths import (
    AXIS_ALIASES,
    BLOCK_CORNER,
    BLOCK_DENSITY,
    BLOCK_SIZE,
    EXPLICIT_VALUES,
    FLEXIBLE_DAMPING,
    FLEXIBLE_YOUNG_MODULUS,
    FLOOR_SINE_KEYS,
    ISOLATOR_MODEL,
    ISOLATOR_PRESET,
    ISOLATORS,
    LAYOUT_HEIGHT,
    LAYOUT_SPAN_X,
    LAYOUT_SPAN_Y,
    LEVELLING,
    LEVELLING_KEYS,
    MACHINE_CG,
    MACHINE_INERTIA_DIAGONAL,
    MACHINE_MASS,
    MOUNT_FIGURES,
    SERVO_KEYS,
    SHAPER_KEYS,
    SIMULATION_DURATION,
    SIMULATION_SETTLE_TOLERANCE,
    components,
    floor_sine,
    group_axis,
    isolator_group,
    mount,
    point,
    profile_segment,
    profile_shaper,
    stage,
    stage_profile,
    stage_servo,
)
from isolab.studies.questions.designs import Design, Factor
from isolab.studies.questions.tolerances import Spread, Tolerance, draw, resolve_spread
from isolab.studies.units import si_unit

CATEGORICAL = "categorical"

# last key -> (dimension, lower bound: "gt0" | "ge0" | None)
_LEAVES: dict[str, tuple[str, str | None]] = {
    "mass": ("mass", "gt0"),
    "density": ("density", "gt0"),
    "size": ("length", "gt0"),
    "corner": ("length", None),
    "cg": ("length", None),
    "inertia_diagonal": ("inertia", "gt0"),
    "f_vertical": ("frequency", "gt0"),
    "f_horizontal": ("frequency", "gt0"),
    "zeta": ("dimensionless", "ge0"),
    "young_modulus": ("pressure", "gt0"),
    "k": ("stiffness", "ge0"),
    "c": ("damping", "ge0"),
    "span_x": ("length", "gt0"),
    "span_y": ("length", "gt0"),
    "height": ("length", None),
    "position": ("length", None),
    "home": ("length", None),
    "travel": ("length", None),
    "move": ("length", None),
    "velocity": ("velocity", "gt0"),
    "acceleration": ("acceleration", "gt0"),
    "jerk": ("jerk", "gt0"),
    "start": ("time", "ge0"),
    "dwell": ("time", "ge0"),
    "point": ("length", None),
    "amplitude": ("length", None),
    "frequency": ("frequency", "ge0"),
    "phase": ("angle", None),
    "damping": ("dimensionless", "ge0"),
    "duration": ("time", "gt0"),
    "settle_tolerance": ("length", "gt0"),
    "servo.bandwidth": ("frequency", "gt0"),
    "servo.damping_ratio": ("dimensionless", "ge0"),
    "servo.stiffness": ("stiffness", "gt0"),
    "servo.damping": ("damping", "ge0"),
    "time_constant": ("time", "gt0"),
    "dead_band": ("length", "ge0"),
}


@dataclass(frozen=True)
class Target:
    """Where a parameter goes in the scene.

    Attributes:
        path: canonical path (vector components as 0/1/2, except the x/y/z keys of isolators.k/c).
        name: default parameter name (e.g. ``stage_y_acceleration``, ``isolator_type``).
        dimension: a :mod:`studies.units` dimension, or "categorical".
        unit: SI unit ("" for categorical and dimensionless).
        levels: allowed values of a categorical parameter.
        writes: canonical leaf paths it sets (two for ``isolators.k.horizontal``).
        bound: "gt0", "ge0" or None: what every value must satisfy besides being finite.
    """

    path: str
    name: str
    dimension: str
    unit: str
    levels: tuple[str, ...] | None
    writes: tuple[str, ...]
    bound: str | None

    @property
    def categorical(self) -> bool:
        return self.dimension == CATEGORICAL

    @property
    def choices(self) -> tuple[str, ...]:
        """The allowed values of a categorical parameter (every categorical target has them); none for a
        continuous one."""
        return self.levels if self.levels is not None else ()


def _leaf_key(path: str) -> str:
    """The key of ``_LEAVES`` a canonical continuous path falls under."""
    parts = path.split(".")
    if parts[0] == "points":
        return "point"
    if len(parts) > 2 and parts[-2] == "servo":  # a stage's servo: its damping is N s/m, not a ratio
        return f"servo.{parts[-1]}"
    if parts[-1].isdigit() or (parts[0] == ISOLATORS and parts[-2] in EXPLICIT_VALUES):
        return parts[-2]
    return parts[-1]


def leaf_rule(path: str) -> tuple[str, str | None]:
    """(dimension, bound) of a canonical continuous leaf path."""
    return _LEAVES[_leaf_key(path)]


def check_leaf_values(path: str, values: np.ndarray) -> None:
    """Raise ValueError naming ``path`` if a value is not finite or breaks the leaf's bound."""
    _, bound = leaf_rule(path)
    x = np.asarray(values, dtype=np.float64)
    bad = ~np.isfinite(x)
    reason = "must be finite"
    if bound == "gt0":
        bad |= ~(x > 0.0)
        reason = "must be positive and finite"
    elif bound == "ge0":
        bad |= ~(x >= 0.0)
        reason = "must be non-negative and finite"
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(
            f"{path}: {reason}, got {x.reshape(-1)[i]:g}" + (f" (case {i})" if x.size > 1 else "")
        )


# ---------------------------------------------------------------------------------------------------------
# what exists


def available_paths(scene: Scene) -> list[str]:
    """Every canonical parameter path of ``scene``, in scene order."""
    out: list[str] = []
    m = scene.machine
    if m.block is not None:
        out += components(BLOCK_SIZE) + [BLOCK_DENSITY] + components(BLOCK_CORNER)
        if m.flexible is not None:
            out += [FLEXIBLE_YOUNG_MODULUS, FLEXIBLE_DAMPING]
    else:
        out += [MACHINE_MASS] + components(MACHINE_CG)
        if m.inertia_diagonal is not None:
            out += components(MACHINE_INERTIA_DIAGONAL)
    iso = scene.isolators
    out += [ISOLATOR_PRESET] + [isolator_group(key) for key in MOUNT_FIGURES]
    for kc in EXPLICIT_VALUES:
        out += [group_axis(kc, a) for a in (*AXES, *AXIS_ALIASES)]
    if iso.levelling is not None:
        out += [f"{isolator_group(LEVELLING)}.{key}" for key in LEVELLING_KEYS]
    if iso.layout is not None:
        out += [LAYOUT_SPAN_X, LAYOUT_SPAN_Y, LAYOUT_HEIGHT]
    else:
        for j, listed in enumerate(iso.listed):
            p = mount(j)
            out += components(f"{p}.position")
            out += [f"{p}.preset"] + [f"{p}.{key}" for key in MOUNT_FIGURES]
            for kc in EXPLICIT_VALUES:
                if getattr(listed, kc) is not None:
                    out += components(f"{p}.{kc}")
            if listed.levelling is not None:
                out += [f"{p}.{LEVELLING}.{key}" for key in LEVELLING_KEYS]
    for s in scene.stages:
        p = stage(s.name)
        out += [f"{p}.mass"] + components(f"{p}.home")
        prof = s.profile
        if prof.shaper is not None:  # a shaper tuned to a mode takes the mode's frequency and damping
            tuning = ("type",) if prof.shaper.mode is not None else ("type", *SHAPER_KEYS)
            out += [f"{profile_shaper(s.name)}.{key}" for key in tuning]
        if isinstance(prof, SequenceProfile):
            for k, seg in enumerate(prof.segments):
                segment_keys = (
                    ("move", "velocity", "acceleration", "jerk")
                    if isinstance(seg, MoveSegment)
                    else ("dwell",)
                )
                out += [f"{profile_segment(s.name, k)}.{key}" for key in segment_keys]
            out.append(f"{stage_profile(s.name)}.start")
            continue
        keys = ["travel", "velocity", "acceleration"]
        if isinstance(prof, SCurveProfile | ScanProfile):
            keys.append("jerk")
        if isinstance(prof, ScanProfile):
            keys.append("dwell")
        keys.append("start")
        out += [f"{stage_profile(s.name)}.{key}" for key in keys]
    for s in scene.stages:
        if s.servo is not None:
            out += [f"{stage_servo(s.name)}.{key}" for key in SERVO_KEYS if getattr(s.servo, key) is not None]
    for name in scene.material_points():
        out += components(point(name))
    if scene.floor is not None and scene.floor.sine is not None:
        for key in FLOOR_SINE_KEYS:
            out += components(floor_sine(key))
    out += [SIMULATION_DURATION, SIMULATION_SETTLE_TOLERANCE]
    return out


def _canonical(path: str, known: set[str]) -> str:
    """``path`` with x/y/z vector components written as 0/1/2 where the scene's path uses indices."""
    if path in known:
        return path
    parts = path.strip().split(".")
    for i, part in enumerate(parts):
        if part in AXES:
            trial = ".".join([*parts[:i], str(AXES.index(part)), *parts[i + 1 :]])
            if trial in known:
                return trial
    return path.strip()


def _summary(paths: list[str]) -> str:
    """Compact listing: vector components folded into ``.{0,1,2}``."""
    out: list[str] = []
    for p in paths:
        head, _, last = p.rpartition(".")
        if last in ("1", "2") and out and out[-1] == f"{head}.0":
            continue
        out.append(p)
    return ", ".join(p[:-2] + ".{0,1,2}" if p.endswith(".0") else p for p in out)


def _default_name(path: str) -> str:
    parts = path.split(".")

    def comp(s: str) -> str:
        return AXES[int(s)] if s.isdigit() and int(s) < 3 else s

    head = parts[0]
    if head == "machine":
        rest = [p for p in parts[1:] if p != "block"]
        if rest[0] == "inertia_diagonal":
            return f"machine_i{comp(rest[1]) * 2}"
        return "_".join(["machine", *map(comp, rest)])
    if head == "isolators":
        if parts[1] == "preset":
            return "isolator_type"
        if parts[1] == "layout":
            return "isolator_" + parts[2]
        if parts[1] == "list":
            j, key = parts[2], parts[3]
            if key == "preset":
                return f"isolator_{j}_type"
            if key == "position":
                return f"isolator_{j}_{comp(parts[4])}"
            return "_".join(["isolator", j, key, *map(comp, parts[4:])])
        return "_".join(["isolator", *parts[1:]])
    if head == "stages":
        name, rest = parts[1], parts[2:]
        if rest[0] == "profile":
            rest = rest[1:]
            if rest[0] == "segments":
                rest = ["segment", *rest[1:]]
        return "_".join(["stage", name, *map(comp, rest)])
    if head == "points":
        return f"point_{parts[1]}_{comp(parts[2])}"
    if head == "floor":
        return "_".join(["floor", parts[2], comp(parts[3])])
    return parts[-1]


def resolve(path: str, scene: Scene) -> Target:
    """The :class:`Target` of ``path`` in ``scene``.

    Raises:
        ValueError: the path does not exist in this scene; the message lists what exists.
    """
    if path.strip() == ISOLATOR_MODEL:  # a product of the scene's catalogue (its ids are the levels)
        ids = tuple(scene_catalogue(scene.isolators.catalogue).ids)
        return Target(ISOLATOR_MODEL, "product", CATEGORICAL, "", ids, (ISOLATOR_MODEL,), None)
    paths = available_paths(scene)
    known = set(paths)
    canon = _canonical(path, known)
    if canon not in known:
        raise ValueError(f"{path!r} does not exist in this scene; paths that exist: {_summary(paths)}")
    parts = canon.split(".")
    name = _default_name(canon)
    if parts[-1] == "preset":
        return Target(canon, name, CATEGORICAL, "", tuple(PRESETS), (canon,), None)
    if parts[-2:] == ["shaper", "type"]:
        return Target(canon, name, CATEGORICAL, "", SHAPERS, (canon,), None)
    writes: tuple[str, ...] = (canon,)
    if parts[0] == ISOLATORS and parts[1] in EXPLICIT_VALUES and parts[2] in AXIS_ALIASES:
        writes = tuple(group_axis(parts[1], axis) for axis in AXIS_ALIASES[parts[2]])
    dimension, bound = leaf_rule(writes[0])
    return Target(canon, name, dimension, si_unit(dimension), None, writes, bound)


# ---------------------------------------------------------------------------------------------------------
# setting values in a scene dict


def scene_dict(scene: Scene) -> dict[str, Any]:
    """A fresh, mutable plain-dict copy of a validated scene (SI numbers, lists, aliases as in YAML)."""
    return scene.model_dump(mode="json", by_alias=True, exclude_none=True)


def _set(d: dict[str, Any], leaf: str, value: Any) -> None:
    parts = leaf.split(".")
    node: Any = d
    for i, part in enumerate(parts[:-1]):
        nxt = parts[i + 1]
        if isinstance(node, list):
            if parts[i - 1] == "stages":
                node = next(s for s in node if s["name"] == part)
            else:
                node = node[int(part)]
            continue
        if node.get(part) is None:
            node[part] = [0.0, 0.0, 0.0] if nxt.isdigit() else {}
        node = node[part]
    last = parts[-1]
    if isinstance(node, list):
        node[int(last)] = value
    else:
        node[last] = value


def _get(d: dict[str, Any], leaf: str) -> Any:
    """The value at ``leaf`` of a scene dict, or None where the scene leaves it unset."""
    parts = leaf.split(".")
    node: Any = d
    for i, part in enumerate(parts):
        if isinstance(node, list):
            if i > 0 and parts[i - 1] == "stages":
                node = next((s for s in node if s.get("name") == part), None)
            else:
                node = node[int(part)] if part.isdigit() and int(part) < len(node) else None
        elif isinstance(node, dict):
            node = node.get(part)
        else:
            return None
        if node is None:
            return None
    return node


def nominal_value(scene: Scene, target: Target) -> float:
    """The value ``scene`` gives the continuous ``target`` (SI): its own, or for the isolator group's
    figures (``isolators.f_vertical``...) its preset's, with the machine's tuning of it.

    Raises:
        ValueError: the scene gives no single value there (unset, or several that differ).
    """
    data = scene_dict(scene)
    values = [_get(data, leaf) for leaf in target.writes]
    parts = target.path.split(".")
    if values[0] is None and parts[0] == ISOLATORS and len(parts) == 2 and parts[1] in MOUNT_FIGURES:
        iso = scene.isolators
        values = [getattr(iso.preset_of(iso.preset), parts[1])]
    if any(v is None for v in values):
        raise ValueError(f"{target.path!r}: the scene sets no value there to spread about")
    numbers = {float(v) for v in values}
    if len(numbers) != 1:
        raise ValueError(f"{target.path!r}: the scene sets several values there ({sorted(numbers)})")
    return numbers.pop()


def apply(scene_data: dict[str, Any], targets: list[Target], values: list[Any]) -> dict[str, Any]:
    """A deep copy of ``scene_data`` with each target set to its value (SI floats or level names)."""
    d = copy.deepcopy(scene_data)
    for target, value in zip(targets, values, strict=True):
        v = value.item() if isinstance(value, np.generic) else value
        for leaf in target.writes:
            _set(d, leaf, v)
        if target.path == ISOLATOR_MODEL:  # the product decides the type
            d[ISOLATORS].pop("preset", None)
    return d


# ---------------------------------------------------------------------------------------------------------
# cases drawn from tolerances

_NOT_DRAWN = (
    "objective",
    "constraints",
    "algorithm",
    "budget",
    "population",
    "plateau",
    "stall",
    "robust",
    "cases",
    "second_order",
)
"""Fields of the design block a monte_carlo design does not take."""


def drawn_design(
    scene: Scene, spec: Any, where: str, targets: list[Target], factors: list[Factor]
) -> tuple[list[Target], Design, list[Spread]]:
    """The targets, cases and spreads of a monte_carlo design: ``design.samples`` cases drawn from the
    tolerances about their nominal values (a parameter's one value, else the scene's), the study's
    parameters held at their one value each."""
    block = scene.tolerances or {}
    if not block:
        raise ValueError(
            "tolerances: a monte_carlo design draws its cases from a tolerances block; give one in the study "
            "or its scene"
        )
    given = [k for k in _NOT_DRAWN if getattr(spec, k) is not None]
    if given:
        raise ValueError(f"design.{given[0]}: a monte_carlo design does not take it")
    if spec.samples is None:
        raise ValueError("design.samples: a monte_carlo design needs the number of cases to draw")
    n = int(spec.samples)
    for i, f in enumerate(factors):
        if f.levels is None or len(f.levels) != 1:
            raise ValueError(
                f"parameters[{i}]: a monte_carlo design draws its cases from the tolerances; a parameter "
                "sets a nominal value, with one value (values: [...])"
            )
    all_targets, names = list(targets), [f.name for f in factors]
    # each factor has one level (checked above)
    values: dict[str, np.ndarray] = {f.name: np.repeat(cast(np.ndarray, f.levels), n) for f in factors}
    shown = {f.name: f.display_unit or f.unit for f in factors if not f.categorical}
    nominals = {
        t.path: (f.name, float(cast(np.ndarray, f.levels)[0])) for t, f in zip(targets, factors, strict=True)
    }
    extra, spreads = tolerance_spreads(scene, block, where, targets, nominals)
    all_targets += extra
    names += [t.name for t in extra]
    shown.update({t.name: t.unit for t in extra})
    x = draw(spreads, n, spec.seed, spec.sampling or "sobol")
    for j, sp in enumerate(spreads):
        values[sp.name] = x[:, j]
    design = Design(
        "sampled",
        names,
        values,
        {},
        {name: t.path for name, t in zip(names, all_targets, strict=True)},
        {name: t.unit for name, t in zip(names, all_targets, strict=True)},
        display_units=shown,
        scales={name: "linear" for name in shown},
    )
    return all_targets, design, spreads


def tolerance_spreads(
    scene: Scene,
    block: Mapping[str, Tolerance],
    where: str,
    targets: list[Target],
    nominals: Mapping[str, tuple[str, float]],
) -> tuple[list[Target], list[Spread]]:
    """The spreads of a ``tolerances`` block about their nominal values, and the targets of the paths the
    study's parameters (``targets``) do not already set.

    Args:
        scene: the study's scene (the nominal value of a path no parameter sets).
        block: the tolerances, path -> :class:`~studies.questions.tolerances.Tolerance`.
        where: the block's place in the file (``tolerances`` or ``scene.tolerances``), for messages.
        targets: the study's parameters.
        nominals: a parameter's path -> (its name, the nominal value of its spread, SI).

    Raises:
        ValueError: ``<where>.<path>: reason``.
    """
    all_targets = list(targets)
    names = [name for name, _ in nominals.values()]
    spreads = []
    for path, tolerance in block.items():
        loc = f"{where}.{path}"
        try:
            t = resolve(path, scene)
        except ValueError as err:
            raise ValueError(f"{loc}: {err}") from None
        if t.categorical or t.path.split(".")[0] == "simulation":
            raise ValueError(
                f"{loc}: {t.path} is a choice or a setting, not a built dimension; it has no spread"
            )
        if t.path in nominals:
            name, nominal = nominals[t.path]
        else:
            for other in all_targets:
                if set(t.writes) & set(other.writes):
                    raise ValueError(f"{loc}: {t.path} sets what {other.path} already sets")
            try:
                nominal = nominal_value(scene, t)
            except ValueError as err:
                raise ValueError(f"{loc}: {err}") from None
            name = t.name
            if name in names:
                raise ValueError(f"{loc}: its name {name!r} is already a parameter's")
            all_targets.append(t)
            names.append(name)
        spreads.append(
            resolve_spread(
                tolerance,
                name=name,
                path=t.path,
                unit=t.unit,
                dimension=t.dimension,
                nominal=nominal,
                where=loc,
            )
        )
    return all_targets[len(targets) :], spreads


def robust_spreads(scene: Scene, where: str, targets: list[Target], factors: list[Factor]) -> list[Spread]:
    """The spreads a robust optimize design draws each candidate's cloud from: the tolerances block's,
    an optimised parameter's about the middle of its range (each candidate re-centres it on its own value,
    :meth:`studies.questions.tolerances.Spread.about`), any other path's about the scene's value.

    Raises:
        ValueError: ``design.robust: ...`` without a tolerances block, else ``<where>.<path>: reason``
            (a path that is not a built dimension, a spread that is not valid at an end of its range).
    """
    block = scene.tolerances or {}
    if not block:
        raise ValueError(
            "design.robust: a robust design judges each candidate on draws of its tolerances; give a "
            "tolerances block in the study or its scene"
        )
    ranges = {f.name: (float(cast(float, f.low)), float(cast(float, f.high))) for f in factors}
    nominals = {t.path: (f.name, 0.5 * sum(ranges[f.name])) for t, f in zip(targets, factors, strict=True)}
    _, spreads = tolerance_spreads(scene, block, where, targets, nominals)
    for sp in spreads:
        for end in ranges.get(sp.name, ()):  # an optimised parameter's spread at each end of its range
            try:
                sp.about(end)
            except ValueError as err:
                raise ValueError(f"{where}.{sp.path}: at {end:g} {sp.unit}, {err}") from None
    return spreads
