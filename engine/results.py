"""What a simulation returns: per-case outputs that carry a status instead of raising; and the catalogue
of the outputs a study stores (:data:`OUTPUTS`): each one's name, dimensions, unit, meaning and which way
is worse, written once on the fields of :class:`SimulationResult`."""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from typing import Any, Final, Literal

import numpy as np

OK = 0
UNSTABLE = 1
"""The integration would be, or went, numerically unstable: no numbers are given."""
TIPPING = 2
"""The scene itself is statically unstable (gravity rocking stiffness beats the mounts)."""
FAILED = 3
"""Anything else went wrong for this case; ``message`` says what."""

STATUS_NAMES = ("ok", "unstable", "tipping", "failed")

DOF_NAMES = ("x", "y", "z", "rx", "ry", "rz")
"""Degrees of freedom of the base: c.g. translation, then rotation about X (pitch), Y (roll), Z (yaw)."""
AXES = DOF_NAMES[:3]
"""Names of the translation axes (the ``axis`` dimension of stored results)."""
ROTATIONS = DOF_NAMES[3:]
"""Names of the rotations about X, Y, Z (the ``rotation`` dimension of stored results)."""
N_MODES = len(DOF_NAMES)
"""Natural modes of the rigid base (one per degree of freedom)."""

AXIS = "axis"
"""The dimension of the translation axes, labelled :data:`AXES`."""
ROTATION = "rotation"
"""The dimension of the rotations, labelled :data:`ROTATIONS`."""
ISOLATOR = "isolator"
"""The dimension of the scene's isolators (one per isolator: its size and labels are the scene's)."""
POINT = "point"
"""The dimension of the scene's points of interest (likewise the scene's)."""
MODE = "mode"
"""The dimension of the natural modes, numbered 1 to :data:`N_MODES` by ascending frequency."""
DOF = "dof"
"""The dimension of the base's degrees of freedom, labelled :data:`DOF_NAMES`."""
DIMENSION_LABELS: dict[str, tuple[str, ...] | tuple[int, ...]] = {
    AXIS: AXES,
    ROTATION: ROTATIONS,
    MODE: tuple(range(1, N_MODES + 1)),
    DOF: DOF_NAMES,
}
"""Labels of the dimensions whose size is fixed (:data:`ISOLATOR` and :data:`POINT` are the scene's)."""

LARGER: Final = "larger"
"""A larger value is worse (a peak, a settling time; for a yes/no output, yes)."""
SMALLER: Final = "smaller"
"""A smaller value is worse (the smallest isolator load: the nearer to lift-off; for yes/no, no)."""


@dataclass(frozen=True)
class OutputSpec:
    """One per-case output a study stores: its name, shape, unit and meaning, and how it is judged.

    Attributes:
        name: the output's name (the dataset variable's, the case table's column prefix).
        dims: its dimensions after the case's (:data:`AXIS`, :data:`ROTATION`, :data:`ISOLATOR`,
            :data:`POINT`, :data:`MODE`, :data:`DOF`); ``()`` for one value per case.
        unit: SI unit (``"1"`` for dimensionless values and yes/no).
        long_name: what it holds, in words.
        flag: a yes/no output (yes/no rather than a number).
        worse: which way a case is worse, :data:`LARGER` or :data:`SMALLER`; a dimension left unnamed
            is reduced to the worst value (the largest, or the smallest).
        field: the :class:`SimulationResult` field its values are read from.
        components: ``(start, stop)`` of the field's last axis it holds, or None for the whole field.
        below_zero: a yes/no output read as ``field < 0`` (lift-off, from the smallest isolator load).
        setting: it says how a case was computed (the step) rather than what it gave: stored after the
            others.
    """

    name: str
    dims: tuple[str, ...]
    unit: str
    long_name: str
    flag: bool = False
    worse: Literal["larger", "smaller"] = LARGER
    field: str = ""
    components: tuple[int, int] | None = None
    below_zero: bool = False
    setting: bool = False

    @property
    def worst(self) -> Literal["max", "min"]:
        """The reduction that keeps the worst value: ``"max"`` or ``"min"``."""
        return "max" if self.worse == LARGER else "min"

    def shape(self, n_isolators: int, n_points: int) -> tuple[int, ...]:
        """Shape of one case's value in a scene of ``n_isolators`` isolators and ``n_points`` points."""
        return _shape(self.dims, n_isolators, n_points)

    def values(self, result: SimulationResult) -> np.ndarray:
        """The output's values (case first) in ``result``: its field, the components it holds, and for
        :attr:`below_zero` whether they are below zero (bool)."""
        a = np.asarray(getattr(result, self.field or self.name))
        if self.components is not None:
            a = a[..., self.components[0] : self.components[1]]
        return a < 0.0 if self.below_zero else a


def _shape(dims: tuple[str, ...], n_isolators: int, n_points: int) -> tuple[int, ...]:
    size = {ISOLATOR: int(n_isolators), POINT: int(n_points)}
    return tuple(size[d] if d in size else len(DIMENSION_LABELS[d]) for d in dims)


def _output(
    *dims: str,
    unit: str,
    long_name: str,
    flag: bool = False,
    worse: Literal["larger", "smaller"] = LARGER,
    setting: bool = False,
    also: tuple[OutputSpec, ...] = (),
) -> dict[str, Any]:
    """Field metadata of a per-case output stored under the field's own name: its ``dims`` after the
    case axis and the rest of its :class:`OutputSpec`; ``also``: further outputs read from the field."""
    own = OutputSpec("", dims, unit, long_name, flag=flag, worse=worse, setting=setting)
    return {"dims": dims, "flag": flag, "outputs": (own, *also)}


def _stored_as(*dims: str, parts: tuple[OutputSpec, ...]) -> dict[str, Any]:
    """Field metadata of a per-case output (its ``dims`` after the case axis) stored as ``parts``, each
    some components of its last axis."""
    return {"dims": dims, "flag": False, "outputs": parts}


@dataclass
class SimulationResult:
    """Outputs of ``C`` cases.

    A case whose ``status`` is not OK has NaN in ``peak_displacement``, ``peak_rotation``,
    ``peak_point_displacement``, ``peak_isolator_force``, ``min_isolator_load``, ``rms_displacement``,
    ``final_displacement``, ``settling_time``, ``point_settling_time``, ``peak_isolator_deflection``,
    ``max_isolator_load``, ``transmissibility``, ``peak_following_error`` (``stage_following_error``),
    ``ready_time`` and ``point_ready_time``, and ``settled`` False. What does not depend on integrating its
    motion stays filled: ``dt`` (the step it was or would have been run with), ``move_time``,
    ``static_isolator_load`` and the modal analysis (``natural_frequency``, ``damping_ratio``,
    ``mode_energy``, ``mechanism``), so an unstable or tipping case still shows its modes and preloads.

    Attributes (shapes; units):
        status: (C,) int8, one of OK, UNSTABLE, TIPPING, FAILED.
        message: list of C strings, empty where OK (an OK case the stability guard sub-stepped says so).
        dt: (C,) step actually used, s.
        peak_displacement: (C, 3) peak |c.g. displacement| per axis, m.
        peak_rotation: (C, 3) peak |rotation| about X, Y, Z, rad.
        peak_point_displacement: (C, p, 3) peak |displacement| of each point of interest, m.
        peak_isolator_force: (C, n, 3) peak |dynamic force| of each isolator per axis, N.
        static_isolator_load: (C, n) vertical preload of each isolator at the reference state, N.
        min_isolator_load: (C, n) smallest total vertical load, N (below zero: the mount lifts off).
        rms_displacement: (C, 3) RMS c.g. displacement per axis over the simulation, m.
        final_displacement: (C, 6) static c.g. displacement and rotation with the stages parked at
            their final positions, m and rad.
        settling_time: (C,) time after the last stage move until the c.g. and every point stay within
            ``settle_tol`` of the final static position, s; a lower bound where ``settled`` is False.
        settled: (C,) bool.
        point_settling_time: (C, p) settling time of each point of interest after each stage move,
            worst over the moves, s. The rest intervals are the times every stage is at rest: from the
            end ``t_k`` of a move until the next move of any stage starts or the run ends (``s_k``); a
            run without stage motion has none and gives 0. In interval ``k`` the point's target is its
            static displacement with the stages parked where they rest in that interval
            (``engine.model.rest_offsets``, level-dependent as ``final_displacement``); its settling
            time there is the last output time in ``[t_k, s_k]`` at which the largest per-axis
            |displacement - target| exceeds ``point_settle_tol`` (scene input, default ``settle_tol``),
            minus ``t_k``: 0 if never, the interval's length (a lower bound) if still outside at its
            last output time. The value is the largest over the case's rest intervals.
        peak_isolator_deflection: (C, n, 3) peak |deflection| of each isolator per floor axis from its
            static (reference) state: the displacement of the base at the mount's point of action
            (rotated point at the nonlinear level) minus the floor's there, m. What sizes a mount's
            stroke.
        max_isolator_load: (C, n) largest total vertical load (preload plus dynamic), N.
        natural_frequency: (C, 6) undamped natural frequencies, ascending, Hz (0 for a mechanism, and for
            a mode with negative stiffness: the modes a TIPPING case tips in).
        damping_ratio: (C, 6) modal damping ratio of each mode, 1.
        mode_energy: (C, 6, 6) kinetic-energy share of each DOF (last axis, DOF_NAMES) in each mode.
        mechanism: (C, 6) bool, True for a zero-stiffness (rigid-body) mode.
        transmissibility: (C, 3) |c.g. displacement / floor displacement| per axis at the floor
            frequency (sine floor motion only; 0 where there is none), 1.
        floor_point_velocity: (C, p, 3) largest one-third-octave band RMS velocity (1 to 80 Hz) of each
            point of interest per axis under the scene's floor spectrum, steady state at the ``lti`` level
            (``engine.frequency``), m/s; 0 without a floor spectrum. Needs no time integration: filled
            for unstable and failed cases too, NaN only for a tipping case or one with a mechanism.
        floor_point_velocity_band: (C, p, 3) exact centre of that band, Hz (0 without a floor spectrum).
        move_time: (C,) end of the last stage move, s: when every stage has come to rest for good
            (``SceneBatch.last_move_end``, the instant ``settling_time`` counts from), a profile's input
            shaper included (it lengthens the move by its duration). Filled for every case; 0 without
            stage motion.
        ready_time: (C,) ``move_time + settling_time``, s: when the stages are at rest and the c.g. and
            every point have settled for good; a lower bound where ``settled`` is False.
        point_ready_time: (C, p) ``move_time + point_settling_time``, s: when each point is ready after
            the last move (exactly so when it settles after the last move no faster than after the
            others, as after a single move; an upper bound otherwise).
        history: time histories of recorded cases, or None (see ``simulate(record=...)``).

    The per-case outputs (every field but ``status``, ``message`` and ``history``) are listed, in this
    order, by :data:`OUTPUT_FIELDS`, with their trailing shapes from :func:`output_shape`. Each field's
    metadata says what a study stores of it (:data:`OUTPUTS`): the unit, long name and judgement written
    here are the only ones.
    """

    status: np.ndarray
    message: list[str]
    dt: np.ndarray = field(metadata=_output(unit="s", long_name="integration time step used", setting=True))
    peak_displacement: np.ndarray = field(
        metadata=_output(AXIS, unit="m", long_name="peak absolute displacement of the machine c.g.")
    )
    peak_rotation: np.ndarray = field(
        metadata=_output(ROTATION, unit="rad", long_name="peak absolute rotation of the machine base")
    )
    peak_point_displacement: np.ndarray = field(
        metadata=_output(POINT, AXIS, unit="m", long_name="peak absolute displacement of a point of interest")
    )
    peak_isolator_force: np.ndarray = field(
        metadata=_output(ISOLATOR, AXIS, unit="N", long_name="peak absolute dynamic isolator force")
    )
    static_isolator_load: np.ndarray = field(
        metadata=_output(ISOLATOR, unit="N", long_name="vertical isolator preload at the reference state")
    )
    min_isolator_load: np.ndarray = field(
        metadata=_output(
            ISOLATOR,
            unit="N",
            long_name="smallest total vertical isolator load",
            worse=SMALLER,
            also=(
                OutputSpec(
                    "liftoff",
                    (ISOLATOR,),
                    "1",
                    "isolator lifts off (smallest total vertical load below zero)",
                    flag=True,
                    below_zero=True,
                ),
            ),
        )
    )
    rms_displacement: np.ndarray = field(
        metadata=_output(AXIS, unit="m", long_name="RMS displacement of the machine c.g.")
    )
    final_displacement: np.ndarray = field(
        metadata=_stored_as(
            DOF,
            parts=(
                OutputSpec(
                    "final_displacement",
                    (AXIS,),
                    "m",
                    "static c.g. displacement with the stages parked at the end",
                    components=(0, 3),
                ),
                OutputSpec(
                    "final_rotation",
                    (ROTATION,),
                    "rad",
                    "static base rotation with the stages parked at the end",
                    components=(3, 6),
                ),
            ),
        )
    )
    settling_time: np.ndarray = field(
        metadata=_output(
            unit="s", long_name="settling time after the last stage move (lower bound if not settled)"
        )
    )
    settled: np.ndarray = field(
        metadata=_output(
            unit="1",
            long_name="motion settled within the tolerance before the end of the simulation",
            flag=True,
            worse=SMALLER,
        )
    )
    point_settling_time: np.ndarray = field(
        metadata=_output(
            POINT,
            unit="s",
            long_name="settling time of a point of interest after each stage move, worst over the moves",
        )
    )
    peak_isolator_deflection: np.ndarray = field(
        metadata=_output(
            ISOLATOR, AXIS, unit="m", long_name="peak absolute isolator deflection from its static state"
        )
    )
    max_isolator_load: np.ndarray = field(
        metadata=_output(ISOLATOR, unit="N", long_name="largest total vertical isolator load")
    )
    natural_frequency: np.ndarray = field(
        metadata=_output(MODE, unit="Hz", long_name="undamped natural frequency (0 for a mechanism)")
    )
    damping_ratio: np.ndarray = field(metadata=_output(MODE, unit="1", long_name="modal damping ratio"))
    mode_energy: np.ndarray = field(
        metadata=_output(
            MODE, DOF, unit="1", long_name="kinetic-energy share of a degree of freedom in a mode"
        )
    )
    mechanism: np.ndarray = field(
        metadata=_output(MODE, unit="1", long_name="zero-stiffness (rigid-body) mode", flag=True)
    )
    transmissibility: np.ndarray = field(
        metadata=_output(
            AXIS,
            unit="1",
            long_name="floor-to-c.g. displacement transmissibility at the floor frequency",
        )
    )
    floor_point_velocity: np.ndarray | None = field(
        default=None,
        metadata=_output(
            POINT,
            AXIS,
            unit="m/s",
            long_name="largest one-third-octave band RMS velocity (1 to 80 Hz) of a point of interest "
            "under the floor spectrum (0 without one)",
        ),
    )
    floor_point_velocity_band: np.ndarray | None = field(
        default=None,
        metadata=_output(
            POINT,
            AXIS,
            unit="Hz",
            long_name="centre frequency of the one-third-octave band of floor_point_velocity (0 without a "
            "floor spectrum)",
        ),
    )
    peak_following_error: np.ndarray | None = field(
        default=None,
        metadata=_output(
            unit="m",
            long_name="peak following error of the stages on a servo, worst over them (0 without one)",
        ),
    )
    stage_following_error: np.ndarray | None = field(default=None)
    """(C, m) each stage's peak following error, m (0 for a stage that follows its profile exactly); the
    stored output is the worst of them, ``peak_following_error``."""
    move_time: np.ndarray | None = field(
        default=None,
        metadata=_output(
            unit="s",
            long_name="end of the last stage move, its input shaper included (every stage at rest for good)",
        ),
    )
    ready_time: np.ndarray | None = field(
        default=None,
        metadata=_output(
            unit="s",
            long_name="move_time plus settling_time: the stages at rest and the c.g. and every point settled "
            "(lower bound if not settled)",
        ),
    )
    point_ready_time: np.ndarray | None = field(
        default=None,
        metadata=_output(
            POINT,
            unit="s",
            long_name="move_time plus the point's settling time (its worst over the moves): the point ready "
            "after the last move",
        ),
    )
    history: dict[str, np.ndarray] | None = field(default=None)

    def __post_init__(self) -> None:
        if self.peak_following_error is None:
            self.peak_following_error = np.zeros(np.shape(self.status)[0])
        # a result assembled without the floor-spectrum outputs has none: zeros (no floor spectrum)
        c, p = np.shape(self.peak_point_displacement)[:2]
        for name in ("floor_point_velocity", "floor_point_velocity_band"):
            if getattr(self, name) is None:
                setattr(self, name, np.zeros((c, p, len(AXES))))
        # nor without the move times: not known
        for name, shape in (("move_time", (c,)), ("ready_time", (c,)), ("point_ready_time", (c, p))):
            if getattr(self, name) is None:
                setattr(self, name, np.full(shape, np.nan))

    @property
    def n_cases(self) -> int:
        return int(self.status.shape[0])

    @property
    def ok(self) -> np.ndarray:
        return self.status == OK

    def to_dict(self, case: int = 0) -> dict:
        """One case's outputs as plain JSON-able Python (SI units, keys named for the quantity)."""
        out: dict = {"status": STATUS_NAMES[int(self.status[case])], "message": self.message[case]}
        for name in OUTPUT_FIELDS:
            v = np.asarray(getattr(self, name)[case])
            out[name] = None if v.dtype.kind == "f" and not np.all(np.isfinite(v)) else v.tolist()
        return out


_FIELDS = {f.name: f.metadata for f in fields(SimulationResult) if "outputs" in f.metadata}
OUTPUT_FIELDS: tuple[str, ...] = tuple(_FIELDS)
"""Names of the per-case outputs of :class:`SimulationResult`, in declaration order (every field but
``status``, ``message`` and ``history``)."""
FLAG_FIELDS: frozenset[str] = frozenset(name for name, meta in _FIELDS.items() if meta["flag"])
"""The yes/no (bool) outputs among :data:`OUTPUT_FIELDS`; the others are floats."""

_STORED = [
    replace(spec, name=spec.name or name, field=name)
    for name, meta in _FIELDS.items()
    for spec in meta["outputs"]
]
OUTPUTS: dict[str, OutputSpec] = {spec.name: spec for spec in sorted(_STORED, key=lambda s: s.setting)}
"""The catalogue of the outputs a study stores, name -> :class:`OutputSpec`, in the order stored: the
fields' outputs in declaration order (``liftoff`` after the smallest isolator load it is read from,
``final_rotation`` after ``final_displacement``), the settings (the step ``dt``) last."""


def output_shape(name: str, n_isolators: int, n_points: int) -> tuple[int, ...]:
    """Shape of one case's value of the :class:`SimulationResult` field ``name`` in a scene of
    ``n_isolators`` isolators and ``n_points`` points of interest (``()`` for a scalar)."""
    return _shape(_FIELDS[name]["dims"], n_isolators, n_points)
