"""From validated scenes to the engine's input: :class:`engine.scene.SceneBatch`.

:func:`build_batch` turns ``C`` scenes of one shape (same isolator count and placement, same stages and
profile kinds, same points and floor kind) into one batch, vectorised over the cases. A study passes a
single scene plus per-case ``overrides``: arrays of the continuous values its parameters set, keyed by
canonical leaf path (see :mod:`studies.inputs.parameters`), so thousands of cases need no per-case validation.

What the builder works out:
- machine mass, inertia and c.g. (from a block: :func:`studies.inputs.block.block_properties`);
- mount positions (a layout puts four mounts at ``cg_x +- span_x/2, cg_y +- span_y/2, cg_z - height``
  around the machine's c.g., order :data:`studies.inputs.schema.LAYOUT_ORDER`);
- the static load of each mount under the total weight of machine and stages at home
  (:func:`studies.inputs.isolators.load_share`, about the composite c.g.), and from it preset stiffness per
  floor axis (X, Y from ``f_horizontal``, Z from ``f_vertical``) and damping from ``zeta``; explicit values
  win; stage motion profiles (:mod:`engine.profiles`), points, floor motion, duration and settling tolerance.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from typing import cast

import numpy as np

from isolab.engine import profiles
from isolab.engine.modal import Modes
from isolab.engine.results import AXES
from isolab.engine.scene import GRAVITY, SceneBatch, SceneError
from isolab.studies.inputs.block import MAX_TRAVEL, beyond_travel, block_properties, travel_bound
from isolab.studies.inputs.isolators import (
    CollinearIsolatorsError,
    IsolatorPreset,
    damping_from_ratio,
    load_share,
    stiffness_from_frequency,
)
from isolab.studies.inputs.mount_physics import (
    apply_mount_physics,
    axis_damping_ratios,
    first_set,
    levelling_valves,
    mount_feedforward,
    mount_figures,
    mount_states,
    valve_signature,
    valve_time,
)
from isolab.studies.inputs.parameters import check_leaf_values
from isolab.studies.inputs.precision import flexible_base, point_signature, precision_inputs, servo_kind
from isolab.studies.inputs.schema import (
    AUTO_DURATION_CAP,
    AUTO_DURATION_DECAYS,
    AUTO_DURATION_MARGIN,
    Block,
    Floor,
    Isolators,
    Layout,
    MoveSegment,
    PresetName,
    RecordedFloor,
    ScanProfile,
    Scene,
    SCurveProfile,
    SequenceProfile,
    Simulation,
    SineFloor,
    TrapezoidProfile,
)
from isolab.studies.inputs.schema.scene_paths import (
    BLOCK_CORNER,
    BLOCK_DENSITY,
    BLOCK_SIZE,
    ISOLATORS,
    LAYOUT_HEIGHT,
    LAYOUT_SPAN_X,
    LAYOUT_SPAN_Y,
    MACHINE_CG,
    MACHINE_INERTIA_DIAGONAL,
    MACHINE_MASS,
    SIMULATION_DURATION,
    SIMULATION_SETTLE_TOLERANCE,
    floor_sine,
    group_axis,
    isolator_group,
    mount,
    point,
    profile_segment,
    stage,
    stage_entry,
    stage_profile,
)
from isolab.studies.inputs.shaping import scene_modes, shaped_profile, tuned_to_modes
from isolab.studies.questions.floor import spectrum_fields

_LAYOUT_SX = np.array([-1.0, 1.0, 1.0, -1.0])
_LAYOUT_SY = np.array([-1.0, -1.0, 1.0, 1.0])


def shape_signature(scene: Scene) -> tuple:
    """What all scenes of one batch must share (array shapes and which inputs exist)."""
    iso = scene.isolators
    m = scene.machine
    machine = ("block", m.flexible and m.flexible.modes) if m.block else ("direct", m.inertia is not None)
    mounts = (
        ("layout",)
        if iso.layout is not None
        else ("list", len(iso.listed), tuple((mt.k is not None, mt.c is not None) for mt in iso.listed))
    )
    stages = []
    for s in scene.stages:
        p = s.profile
        kind: tuple[object, ...]
        if isinstance(p, SequenceProfile):
            kind = (
                "sequence",
                tuple(
                    ("move", g.jerk is not None) if isinstance(g, MoveSegment) else ("dwell",)
                    for g in p.segments
                ),
            )
        elif isinstance(p, ScanProfile):
            kind = ("scan", p.jerk is not None, p.repeats)
        else:
            kind = (p.type,)
        if p.shaper is not None:  # a shaped profile has SHAPER_IMPULSES times the pieces
            kind = (*kind, "shaped")
        stages.append((s.name, s.parent, kind, servo_kind(s)))
    floor: tuple[object, ...] | None = None  # the time-domain floor motion (a spectrum shapes nothing)
    if scene.floor is not None and scene.floor.sine is not None:
        floor = ("sine",)
    elif scene.floor is not None and scene.floor.recorded is not None:
        rec = scene.floor.recorded
        floor = ("recorded", rec.dt, len(rec.displacement.samples()[0]))
    return machine, mounts + valve_signature(iso), tuple(stages), point_signature(scene), floor


class _Cases:
    """Reads a leaf of ``C`` cases: the override array if there is one, else the scenes' own values.

    The scenes are one scene shared by every case (a study's group) or one scene per case: a scene's own
    value is read once per scene and broadcast over the cases, not once per case."""

    def __init__(self, scenes: Sequence[Scene], overrides: Mapping[str, np.ndarray], n_cases: int):
        self.scenes = scenes
        self.overrides = overrides
        self.c = n_cases
        self.presets: dict[tuple[int, str], IsolatorPreset] = {}

    def get(self, path: str, read: Callable[[Scene], float | None]) -> np.ndarray:
        """(C,) values; NaN where a scene leaves an optional input unset."""
        if path in self.overrides:
            return self.overrides[path]
        vals = [read(s) for s in self.scenes]
        arr = np.array([np.nan if v is None else float(v) for v in vals])
        return np.broadcast_to(arr, (self.c,)) if arr.size == 1 else arr

    def vec(self, path: str, read: Callable[[Scene], Sequence[float] | None]) -> np.ndarray:
        """(C, 3) vector leaf, components ``path.0 .. path.2`` (a fresh array)."""
        if not any(f"{path}.{i}" in self.overrides for i in range(3)):  # the scenes' own: one read each
            rows = [read(s) for s in self.scenes]
            values = np.array([[np.nan] * 3 if v is None else [float(v[i]) for i in range(3)] for v in rows])
            return np.repeat(values, self.c, axis=0) if len(rows) == 1 else values
        columns = []
        for i in range(3):

            def component(s: Scene, i: int = i) -> float | None:
                vector = read(s)
                return None if vector is None else vector[i]

            columns.append(self.get(f"{path}.{i}", component))
        return np.stack(columns, axis=-1)

    def preset(self, iso: Isolators, name: PresetName) -> IsolatorPreset:
        """``iso.preset_of(name)``, worked out once per batch and group."""
        key = (id(iso), name)
        if key not in self.presets:
            self.presets[key] = iso.preset_of(name)
        return self.presets[key]

    def per_scene(self, read: Callable[[Scene], object]) -> list:
        """An input of each scene (no overrides): one value shared by every case, or one per case."""
        return [read(s) for s in self.scenes]

    def array(self, read: Callable[[Scene], object]) -> np.ndarray:
        """(C, ...) a fresh float array of an input of each case (no overrides), read once per scene."""
        values = np.array(self.per_scene(read), dtype=np.float64)
        return np.repeat(values, self.c, axis=0) if len(self.scenes) == 1 else values


def _fail(field: str, reason: str, bad: np.ndarray, c: int) -> None:
    if np.any(bad):
        where = f" (case {int(np.flatnonzero(np.reshape(bad, (c, -1)).any(axis=1))[0])})" if c > 1 else ""
        raise SceneError(field, reason + where)


def _machine(cases: _Cases) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """Mass (C,), inertia (C, 3, 3), c.g. (C, 3) and the block size (C, 3) or None."""
    m0 = cases.scenes[0].machine
    c = cases.c
    if m0.block is not None:

        def block(s: Scene) -> Block:  # the batch's scenes share one shape: each base is a block
            return cast(Block, s.machine.block)

        size = cases.vec(BLOCK_SIZE, lambda s: block(s).size)
        rho = cases.get(BLOCK_DENSITY, lambda s: block(s).density)
        corner = cases.vec(BLOCK_CORNER, lambda s: block(s).corner)
        mass, inertia, cg = block_properties(size, rho, corner)
        return mass, inertia, cg, size
    mass = cases.get(MACHINE_MASS, lambda s: s.machine.mass)
    cg = cases.vec(MACHINE_CG, lambda s: s.machine.cg)
    if m0.inertia is not None:
        inertia = cases.array(lambda s: s.machine.inertia).reshape(c, 3, 3)
    else:
        diag = cases.vec(MACHINE_INERTIA_DIAGONAL, lambda s: s.machine.inertia_diagonal)
        srt = np.sort(diag, axis=-1)
        _fail(
            MACHINE_INERTIA_DIAGONAL,
            "principal moments break the triangle inequality (no rigid body has them)",
            srt[:, 2] > (srt[:, 0] + srt[:, 1]) * (1.0 + 1e-9),
            c,
        )
        inertia = np.zeros((c, 3, 3))
        inertia[:, [0, 1, 2], [0, 1, 2]] = diag
    return np.asarray(mass, dtype=np.float64), inertia, cg, None


def _profiles(cases: _Cases, modes: Modes | None = None) -> profiles.Pieces:
    """Every stage's profile (C, m, K); a shaper tuned to a mode waits for ``modes`` (scene_modes).

    A profile that no case varies (one scene, no override of it, no shaper tuned to the cases' modes) is
    worked out for one case (:func:`_shared_pieces`) and broadcast over the cases; when no case varies
    any, they come as (1, m, K), to be broadcast by the caller."""
    c = cases.c
    one_case = _Cases(cases.scenes, {}, 1)
    pieces = []
    for i, st in enumerate(cases.scenes[0].stages):
        prefix = f"{stage_profile(st.name)}."
        shared = (
            len(cases.scenes) == 1
            and not any(path.startswith(prefix) for path in cases.overrides)
            and (st.profile.shaper is None or st.profile.shaper.mode is None)
        )
        pieces.append(_shared_pieces(cases, one_case, i) if shared else _stage_pieces(cases, i, modes))
    if not pieces:
        z = np.zeros((c, 0, 1))
        return profiles.Pieces(z, z, z, z, z)
    if all(pc.t.shape[0] == 1 for pc in pieces):
        return profiles.stack(pieces)
    return profiles.stack(
        [profiles.Pieces(*(np.broadcast_to(x, (c, x.shape[1])) for x in pc)) for pc in pieces]
    )


SHARED_PROFILES_KEPT = 256
"""How many profiles no case varies a process keeps, by their figures (:func:`_shared_pieces`)."""
_shared_profiles: dict[str, profiles.Pieces] = {}


def _shared_pieces(cases: _Cases, one_case: _Cases, i: int) -> profiles.Pieces:
    """Stage ``i``'s profile that no case varies (1, K), worked out once per process for its figures: the
    batches of a study's group share it. Read-only; an error is reported as the cases give it."""
    key = cases.scenes[0].stages[i].profile.model_dump_json()
    pc = _shared_profiles.get(key)  # one look: another thread may clear the store meanwhile
    if pc is None:
        try:
            pc = _stage_pieces(one_case, i, None)
        except SceneError:
            return _stage_pieces(cases, i, None)  # raises the error with the cases' own wording
        for x in pc:
            x.setflags(write=False)
        if len(_shared_profiles) >= SHARED_PROFILES_KEPT:
            _shared_profiles.clear()
        _shared_profiles[key] = pc
    return pc


def _stage_pieces(cases: _Cases, i: int, modes: Modes | None) -> profiles.Pieces:
    """Stage ``i``'s profile over ``cases`` (C, K)."""
    c = cases.c
    st = cases.scenes[0].stages[i]
    p = stage_profile(st.name)
    prof = st.profile

    def get(key: str) -> np.ndarray:
        return cases.get(f"{p}.{key}", lambda s: getattr(s.stages[i].profile, key))

    try:
        if isinstance(prof, TrapezoidProfile):
            pc = profiles.trapezoid(get("travel"), get("velocity"), get("acceleration"), start=get("start"))
        elif isinstance(prof, SCurveProfile):
            pc = profiles.scurve(
                get("travel"), get("velocity"), get("acceleration"), get("jerk"), start=get("start")
            )
        elif isinstance(prof, ScanProfile):
            jerk = get("jerk") if prof.jerk is not None or f"{p}.jerk" in cases.overrides else None
            pc = profiles.scan(
                get("travel"),
                get("velocity"),
                get("acceleration"),
                jerk,
                dwell=get("dwell"),
                repeats=prof.repeats,
                start=get("start"),
            )
        else:
            segs = []
            for k, seg in enumerate(prof.segments):
                q = profile_segment(st.name, k)

                def sget(key: str, q: str = q, k: int = k) -> np.ndarray:
                    # the batch's scenes share one shape: this stage's profile is a sequence in each
                    return cases.get(
                        f"{q}.{key}",
                        lambda s: getattr(cast(SequenceProfile, s.stages[i].profile).segments[k], key),
                    )

                if isinstance(seg, MoveSegment):
                    d = {"move": sget("move"), "v_max": sget("velocity"), "a_max": sget("acceleration")}
                    if seg.jerk is not None or f"{q}.jerk" in cases.overrides:
                        d["j_max"] = sget("jerk")
                    segs.append(d)
                else:
                    segs.append({"dwell": sget("dwell")})
            pc = profiles.sequence(segs, start=get("start"))
        if prof.shaper is not None:
            pc = shaped_profile(pc, i, c, cases.get, cases.per_scene, modes)
    except SceneError as err:
        names = {"v_max": "velocity", "a_max": "acceleration", "j_max": "jerk", "distance": "travel"}
        field = err.field
        for old, new in names.items():
            field = field.replace(old, new)
        raise SceneError(f"{stage_entry(i)}.profile.{field}", err.reason) from None
    return pc


def build_batch(
    scenes: Sequence[Scene],
    overrides: Mapping[str, np.ndarray] | None = None,
    simulation: Simulation | None = None,
    n_cases: int | None = None,
    g: float = GRAVITY,
) -> SceneBatch:
    """The engine batch of ``scenes``, one case per scene, or ``n_cases`` cases of one scene.

    Args:
        scenes: validated scenes of one shape (see :func:`shape_signature`); a single scene is repeated
            over the cases of ``overrides``.
        overrides: per-case values (SI) of continuous inputs, by canonical leaf path (``stages.y.mass``,
            ``isolators.k.x``, ``machine.block.size.1`` ...), each of shape (C,) or scalar.
        simulation: the simulation block to use for every case (duration, settling tolerance, gravity
            stiffness); default: each scene's own.
        n_cases: number of cases ``C`` (default: from the scenes and overrides).
        g: gravitational acceleration, m/s^2.

    Raises:
        SceneError (a ValueError): naming the input and, for several cases, the first case that is not a
            physical scene (collinear mounts, a mount that would carry no load, a travel off the base ...).
    """
    scenes = list(scenes)
    if not scenes:
        raise ValueError("build_batch: no scenes")
    sig = shape_signature(scenes[0])
    for i, s in enumerate(scenes[1:], start=1):
        if shape_signature(s) != sig:
            raise ValueError(
                f"build_batch: scene {i} differs in shape from scene 0 (isolators, stages, points or "
                "floor); build such scenes in separate batches"
            )
    ov = {}
    for path, v in (overrides or {}).items():
        arr = np.asarray(v, dtype=np.float64).reshape(-1)
        check_leaf_values(path, arr)
        ov[path] = arr
    sizes = {len(scenes)} | {a.size for a in ov.values()}
    c = n_cases if n_cases is not None else max(sizes)
    if not sizes <= {1, c}:
        raise ValueError(f"build_batch: scenes and overrides disagree on the case count: {sorted(sizes)}")
    ov = {k: np.broadcast_to(a, (c,)) for k, a in ov.items()}
    cases = _Cases(scenes, ov, c)
    s0 = scenes[0]

    mass, inertia, cg, block_size = _machine(cases)

    # stages
    m = len(s0.stages)
    names = [st.name for st in s0.stages]
    stage_mass = np.zeros((c, m))
    stage_home = np.zeros((c, m, 3))
    for i, name in enumerate(names):

        def moving_mass(s: Scene, i: int = i) -> float:
            return s.stages[i].mass

        def home(s: Scene, i: int = i) -> Sequence[float]:
            return s.stages[i].home

        stage_mass[:, i] = cases.get(f"{stage(name)}.mass", moving_mass)
        stage_home[:, i] = cases.vec(f"{stage(name)}.home", home)
    stage_axis = cases.array(lambda s: [st.axis for st in s.stages]).reshape(c, m, 3)
    stage_parent = np.array(
        [-1 if st.parent is None else names.index(st.parent) for st in s0.stages], dtype=np.int64
    )

    # isolators
    iso0 = s0.isolators
    if iso0.layout is not None:
        n = 4

        def layout(s: Scene) -> Layout:  # the batch's scenes share one shape: each is placed by a layout
            return cast(Layout, s.isolators.layout)

        sx = cases.get(LAYOUT_SPAN_X, lambda s: layout(s).span_x)
        sy = cases.get(LAYOUT_SPAN_Y, lambda s: layout(s).span_y)
        h = cases.get(LAYOUT_HEIGHT, lambda s: layout(s).height)
        iso_pos = np.stack(
            [
                cg[:, None, 0] + _LAYOUT_SX * sx[:, None] / 2.0,
                cg[:, None, 1] + _LAYOUT_SY * sy[:, None] / 2.0,
                np.broadcast_to((cg[:, 2] - h)[:, None], (c, 4)),
            ],
            axis=-1,
        )
    else:
        n = len(iso0.listed)
        positions = []
        for j in range(n):

            def position(s: Scene, j: int = j) -> Sequence[float]:
                return s.isolators.listed[j].position

            positions.append(cases.vec(f"{mount(j)}.position", position))
        iso_pos = np.stack(positions, axis=1)
    total_mass = mass + stage_mass.sum(axis=1)
    weight_xy = mass[:, None] * cg[:, :2] + np.einsum("cm,cmi->ci", stage_mass, stage_home[..., :2])
    weight_xy = weight_xy / total_mass[:, None]
    try:
        load = load_share(iso_pos[..., :2], weight_xy, total_mass * g)
    except CollinearIsolatorsError as err:
        raise SceneError(ISOLATORS, str(err).removeprefix(f"{ISOLATORS}: ")) from None

    f_v, f_h, zeta, skyhook = mount_figures(cases, n)
    ff_gain, ff_bandwidth, ff_limit, ff_weight = mount_feedforward(cases, n)
    k_explicit = np.full((c, n, 3), np.nan)
    c_explicit = np.full((c, n, 3), np.nan)
    for a, axis in enumerate(AXES):

        def group_k(s: Scene, axis: str = axis) -> float | None:
            return getattr(s.isolators.k, axis, None)  # None: no explicit stiffness

        def group_c(s: Scene, axis: str = axis) -> float | None:
            return getattr(s.isolators.c, axis, None)

        k_explicit[:, :, a] = cases.get(group_axis("k", axis), group_k)[:, None]
        c_explicit[:, :, a] = cases.get(group_axis("c", axis), group_c)[:, None]
    for j, listed in enumerate(iso0.listed):  # none for a layout
        for kc, explicit in (("k", k_explicit), ("c", c_explicit)):
            if getattr(listed, kc) is not None:

                def own(s: Scene, j: int = j, kc: str = kc) -> Sequence[float] | None:
                    return getattr(s.isolators.listed[j], kc)

                explicit[:, j, :] = cases.vec(f"{mount(j)}.{kc}", own)
    freq = np.stack([f_h, f_h, f_v], axis=-1)
    needs_load = np.isnan(k_explicit) | np.isnan(c_explicit)
    bad_load = needs_load.any(axis=-1) & ~(load > 0.0)
    if bad_load.any():
        case, j = (int(x[0]) for x in np.nonzero(bad_load))
        raise SceneError(
            ISOLATORS,
            f"isolator {j} would carry a static load of {load[case, j]:.6g} N (not positive): the weight of "
            "machine "
            "and stages lies too far from the mounts' centre for preset (load-based) stiffness; move the "
            "mounts or give explicit k" + (f" (case {case})" if c > 1 else ""),
        )
    safe_load = np.where(load > 0.0, load, 0.0)[..., None]
    groups = cases.per_scene(lambda s: s.isolators)  # one shared by every case, or one per case
    zeta_axes = axis_damping_ratios(groups, zeta, isolator_group("zeta") in cases.overrides)
    iso_k = first_set(k_explicit, stiffness_from_frequency(safe_load, freq, g))
    iso_c = first_set(c_explicit, damping_from_ratio(iso_k, safe_load, zeta_axes, g))
    iso_k, iso_c, iso_frame = apply_mount_physics(groups, load, iso_k, iso_c, k_explicit, c_explicit, g)
    _fail(
        ISOLATORS,
        "stiffness and damping must be finite and non-negative",
        ~(np.isfinite(iso_k) & np.isfinite(iso_c) & (iso_k >= 0) & (iso_c >= 0)),
        c,
    )

    # motion (a shaper tuned to a mode is applied below, once the modes are known: it only delays motion)
    pieces = _profiles(cases)
    if m:
        reach = np.abs(pieces.s).max(axis=-1)  # (C or 1, m): farthest from home (monotonic in a piece)
        bound = travel_bound(stage_axis, block_size[:, None, :] if block_size is not None else None)
        over = beyond_travel(reach, bound)
        if over.any():
            i = int(np.flatnonzero(over.any(axis=0))[0])
            _fail(
                f"{stage_entry(i)}.profile.travel",
                "the stage would travel farther than the base's extent along its axis"
                if block_size is not None
                else f"the stage would travel more than {MAX_TRAVEL:g} m",
                over[:, i],
                c,
            )

    # points and floor
    point_names = list(s0.points)
    points = np.zeros((c, len(point_names), 3))
    for i, name in enumerate(point_names):

        def material_point(s: Scene, name: str = name) -> Sequence[float]:
            return s.material_points().get(name, (0.0, 0.0, 0.0))  # a relative point: precision_inputs

        points[:, i] = cases.vec(point(name), material_point)
    floor_amp = np.zeros((c, 3))
    floor_freq = np.zeros((c, 3))
    floor_phase = np.zeros((c, 3))
    floor_t = np.zeros(0)
    floor_disp = None
    # the batch's scenes share one shape: the floor of each moves as the first one's does
    if s0.floor is not None and s0.floor.sine is not None:

        def sine(s: Scene) -> SineFloor:
            return cast(SineFloor, cast(Floor, s.floor).sine)

        floor_amp = cases.vec(floor_sine("amplitude"), lambda s: sine(s).amplitude)
        floor_freq = cases.vec(floor_sine("frequency"), lambda s: sine(s).frequency)
        floor_phase = cases.vec(floor_sine("phase"), lambda s: sine(s).phase)
    elif s0.floor is not None and s0.floor.recorded is not None:
        rec = s0.floor.recorded

        def recorded(s: Scene) -> RecordedFloor:
            return cast(RecordedFloor, cast(Floor, s.floor).recorded)

        samples = cases.array(lambda s: recorded(s).displacement.samples())
        floor_t = np.arange(samples.shape[-1]) * rec.dt
        floor_disp = samples.reshape(c, 3, -1)
    # the floor spectrum: one-third-octave band velocity per axis, and per mount (studies.questions.floor)
    floor_spectra = spectrum_fields(cases, iso_pos, cg)

    # simulation
    def sim(s: Scene) -> Simulation:
        return simulation if simulation is not None else s.simulation

    gravity_stiffness = {sim(s).gravity_stiffness for s in scenes}
    if len(gravity_stiffness) != 1:
        raise ValueError("build_batch: scenes of one batch must agree on simulation.gravity_stiffness")
    preload = {sim(s).preload for s in scenes}
    if len(preload) != 1:
        raise ValueError("build_batch: scenes of one batch must agree on simulation.preload")

    def fixed_duration(s: Scene) -> float | None:
        duration = sim(s).duration
        return None if duration == "auto" else duration

    duration = cases.get(SIMULATION_DURATION, fixed_duration)
    settle = cases.get(SIMULATION_SETTLE_TOLERANCE, lambda s: sim(s).settle_tolerance)
    # each point settles to its own criterion's ``within`` (studies.questions.criteria), else to
    # settle_tolerance
    point_tol = np.repeat(np.asarray(settle, dtype=np.float64).reshape(-1, 1), len(point_names), axis=1)
    within = [s.criteria.settle_tolerances() if s.criteria is not None else {} for s in scenes]
    for j, name in enumerate(point_names):
        for i, w in enumerate(within):
            if name in w:
                point_tol[slice(None) if len(scenes) == 1 else i, j] = w[name]

    def per_case(x: np.ndarray) -> np.ndarray:  # a fresh (C, ...) array of what one case gives alone
        return np.ascontiguousarray(x) if x.shape[0] == c else np.repeat(x, c, axis=0)

    batch = SceneBatch(
        mass=np.array(mass, dtype=np.float64),
        inertia=inertia,
        cg=np.array(cg, dtype=np.float64),
        iso_pos=np.array(iso_pos, dtype=np.float64),
        iso_k=iso_k,
        iso_c=iso_c,
        iso_skyhook=skyhook,
        iso_frame=iso_frame,
        stage_mass=stage_mass,
        stage_home=stage_home,
        stage_axis=stage_axis,
        stage_parent=stage_parent,
        prof_t=per_case(pieces.t),
        prof_s=per_case(pieces.s),
        prof_v=per_case(pieces.v),
        prof_a=per_case(pieces.a),
        prof_j=per_case(pieces.j),
        points=points,
        floor_amp=np.array(floor_amp, dtype=np.float64),
        floor_freq=np.array(floor_freq, dtype=np.float64),
        floor_phase=np.array(floor_phase, dtype=np.float64),
        floor_t=floor_t,
        floor_disp=floor_disp,
        **floor_spectra,
        duration=np.array(duration, dtype=np.float64),
        settle_tol=np.array(settle, dtype=np.float64),
        point_settle_tol=point_tol,
        gravity_stiffness=gravity_stiffness.pop(),
        g=g,
        iso_ff_gain=ff_gain,
        iso_ff_bandwidth=ff_bandwidth,
        iso_ff_limit=ff_limit,
        iso_ff_weight=ff_weight,
        preload_with_base="base" in preload,
        preload_balanced="balanced" in preload,
    )
    batch = flexible_base(precision_inputs(batch, cases), cases)  # servos, relative points, elastic modes
    batch = mount_states(batch, cases, load, k_explicit, c_explicit)  # air orifices', elastomers' states
    batch = levelling_valves(batch, cases)  # air mounts' levelling valves
    if any(tuned_to_modes(s) for s in scenes):  # tuned to the modes of the scene as assembled
        pieces = _profiles(cases, scene_modes(batch))
        at = profiles.Pieces(*(per_case(x) for x in pieces))
        batch = replace(batch, prof_t=at.t, prof_s=at.s, prof_v=at.v, prof_a=at.a, prof_j=at.j)
    last_move = np.broadcast_to(profiles.end_time(pieces).max(axis=-1), (c,)) if m else np.zeros(c)
    auto = np.isnan(duration)
    if auto.any():
        decay = slowest_decay_time(batch.take(np.flatnonzero(auto)))
        margin = np.maximum(AUTO_DURATION_MARGIN, AUTO_DURATION_DECAYS * decay)
        durations = cast(np.ndarray, batch.duration)  # given above (and SceneBatch fills a missing one)
        durations[auto] = np.minimum(last_move[auto] + margin, AUTO_DURATION_CAP)
    return batch


def check_scene(scene: Scene) -> Scene:
    """The check step for one parsed scene: build its batch once, so that what only the assembled scene
    shows (collinear mounts, a mount that would carry no load, a travel off the base, a scene that tips)
    is reported before anything runs. Returns ``scene``.

    Raises:
        SceneError (a ValueError): naming the input and the reason.
    """
    build_batch([scene])
    return scene


def slowest_decay_time(batch: SceneBatch) -> np.ndarray:
    """(C,) largest time constant ``1 / (zeta w)`` over the modes that have stiffness and damping, s
    (0 where none has both; a mode without damping never decays and is left to the cap)."""
    from isolab.engine import modal
    from isolab.engine import model as engine_model

    try:
        md = modal.modes(
            engine_model.mass_matrix(batch),
            engine_model.stiffness_matrix(batch),
            engine_model.damping_matrix(batch),
        )
    except np.linalg.LinAlgError:
        return np.zeros(batch.n_cases)
    w = 2 * np.pi * md.frequency
    rate = md.damping_ratio * w
    tau = np.where((w > 0) & (rate > 0), 1.0 / np.where(rate > 0, rate, 1.0), 0.0)
    return np.maximum(tau.max(axis=1), valve_time(batch))


def isolator_loads(scene: Scene, g: float = GRAVITY) -> np.ndarray:
    """(n,) static vertical load of each mount of ``scene``, N (machine and stages at home)."""
    b = build_batch([scene], g=g)
    total = b.mass + b.stage_mass.sum(axis=1)
    wp = b.mass[:, None] * b.cg[:, :2] + np.einsum("cm,cmi->ci", b.stage_mass, b.stage_home[..., :2])
    return load_share(b.iso_pos[..., :2], wp / total[:, None], total * g)[0]
