"""The scene and study inputs as pydantic models: what a user writes in YAML/JSON, checked and in SI.

Every model forbids unknown keys (a typo is an error, not a silently ignored input). Quantities accept a
number in SI or a string with units (see :mod:`studies.units`). Positions are in the floor frame XYZ
(Z up, Y the machine's long axis), with the origin at the bottom-left corner of the machine base unless the
user places it elsewhere. Errors carry the path of the offending input in their ``loc``; checks that
involve several inputs name the field in their message (``stages[1].parent: ...``).

A study (parameters and design on top of a scene) is :class:`studies.study.Study`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Discriminator,
    Field,
    GetCoreSchemaHandler,
    GetJsonSchemaHandler,
    StrictFloat,
    StrictInt,
    StrictStr,
    Tag,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)
from pydantic_core import CoreSchema, core_schema

from isolab.engine.results import AXES
from isolab.studies.inputs.block import MAX_TRAVEL, beyond_travel, block_properties, travel_bound
from isolab.studies.inputs.isolators import (
    PRESETS,
    CollinearIsolatorsError,
    Feedforward,
    IsolatorPreset,
    load_share,
)
from isolab.studies.questions.criteria import Criteria
from isolab.studies.questions.floor import MAX_BAND_VELOCITY, band_number, canonical_vc
from isolab.studies.units import (
    Acceleration,
    Angle,
    Damping,
    Density,
    Dimensionless,
    DisplacementPSD,
    Force,
    Frequency,
    Inertia,
    Jerk,
    Length,
    Mass,
    Stiffness,
    Time,
    Velocity,
    VelocityPSD,
    si_unit,
    to_si,
)

AUTO_DURATION_MARGIN = 3.0
"""``duration: auto`` simulates at least this long after the last stage move ends, s."""
AUTO_DURATION_DECAYS = 9.2
"""...and at least this many time constants ``1 / (zeta w)`` of the slowest-decaying mode: long enough for
its amplitude to fall by 10^4 (ln 10^4 = 9.2), so a settling time is measured, not cut off."""
AUTO_DURATION_CAP = 60.0
"""Longest ``duration: auto``, s."""

MIN_MACHINE_MASS, MAX_MACHINE_MASS = 10.0, 1e5
"""Machine base mass without stages, kg."""
MIN_MOUNT_FREQUENCY, MAX_MOUNT_FREQUENCY = 0.5, 60.0
"""Isolator natural frequency under its load, Hz."""
MAX_DAMPING_RATIO = 2.0
"""Isolator damping ratio (1; 200 %)."""
MIN_STAGE_MASS, MAX_STAGE_MASS = 0.1, 5000.0
"""Stage moving mass, kg."""
MIN_STAGE_VELOCITY, MAX_STAGE_VELOCITY = 1e-3, 10.0
"""Stage velocity, m/s."""
MIN_STAGE_ACCELERATION, MAX_STAGE_ACCELERATION = 0.01, 50.0
"""Stage acceleration, m/s^2 (50 m/s^2 is about 5 g)."""
MIN_STAGE_JERK, MAX_STAGE_JERK = 1.0, 1e5
"""Stage jerk, m/s^3."""
MIN_BASE_SIZE, MAX_BASE_SIZE = 0.05, 20.0
"""Side of a block base, m."""
MIN_SPAN, MAX_SPAN = 0.05, 20.0
"""Distance between the mounts of a layout, m."""
MAX_MOUNT_HEIGHT = 5.0
"""How far the c.g. may sit above (or below, negative) the mounts of a layout, m."""
MAX_COORDINATE = 100.0
"""Largest |coordinate| of a position, m. A machine, its mounts, stages and points sit within 100 m of the
floor origin; beyond that only typos (mm read as m) reach, and float64 positions lose the sub-micrometre
resolution the peaks are reported at."""
MAX_FLOOR_DISPLACEMENT = 0.1
"""Largest floor displacement (amplitude or sample), m."""
MAX_STAGE_MASS_RATIO = 1.0
"""The stages together weigh at most this many times the machine base. Stages are point masses: a base
lighter than its stages leaves the composite body almost without rotational inertia, its rocking modes
reach kHz, and they shift with the stages' positions faster than the stability guard allows for."""
# The accepted ranges above (and MIN_DT/MAX_DT) are the ranges tests/engine/test_extremes.py draws scenes
# from: within them every result is finite and bounded, or flagged unstable/tipping, or refused.


@dataclass(frozen=True)
class _Within:
    """Refuses a value outside [low, high] (SI) after conversion, saying ``why`` the range is what it is;
    its JSON schema carries the range as ``minimum``/``maximum`` and ``why`` as ``x-range-reason`` (what
    the study-file reference, :mod:`studies.file_reference`, and editors show)."""

    low: float
    high: float
    dimension: str
    why: str

    def check(self, value: float) -> float:
        if not self.low <= value <= self.high:
            unit = si_unit(self.dimension)
            u = f" {unit}" if unit else ""
            raise ValueError(
                f"must lie between {self.low:g}{u} and {self.high:g}{u} ({self.why}), got {value:.6g}{u}"
            )
        return value

    def __get_pydantic_core_schema__(self, source: Any, handler: GetCoreSchemaHandler) -> CoreSchema:
        return core_schema.no_info_after_validator_function(self.check, handler(source))

    def __get_pydantic_json_schema__(
        self, schema: CoreSchema, handler: GetJsonSchemaHandler
    ) -> dict[str, Any]:
        out = dict(handler(schema))
        out["minimum"] = max(self.low, out.get("minimum", self.low))
        out["maximum"] = min(self.high, out.get("maximum", self.high))
        out["x-range-reason"] = self.why
        return out


def _within(low: float, high: float, dimension: str, why: str) -> _Within:
    """Refuse a value of ``dimension`` outside [low, high] (SI), saying ``why`` the range is what it is."""
    si_unit(dimension)  # a known dimension
    return _Within(low, high, dimension, why)


def _tested_range(low: float, high: float, dimension: str) -> _Within:
    """Refuse a value of ``dimension`` outside [low, high] (SI): the range tests/engine/test_extremes.py
    covers."""
    return _within(low, high, dimension, "the range the engine is tested over")


PresetName = Literal["active", "air", "elastomer"]
Name = Annotated[str, Field(pattern=r"^[A-Za-z][A-Za-z0-9_]*$", max_length=64)]
"""Names of stages and points: a letter, then letters, digits or underscores (they appear in parameter
paths and dataset coordinates)."""

PositiveLength = Annotated[Length, Field(gt=0)]
BaseSize = Annotated[Length, Field(gt=0), _tested_range(MIN_BASE_SIZE, MAX_BASE_SIZE, "length")]
Span = Annotated[Length, Field(gt=0), _tested_range(MIN_SPAN, MAX_SPAN, "length")]
MachineMass = Annotated[Mass, Field(gt=0), _tested_range(MIN_MACHINE_MASS, MAX_MACHINE_MASS, "mass")]
StageMass = Annotated[Mass, Field(gt=0), _tested_range(MIN_STAGE_MASS, MAX_STAGE_MASS, "mass")]
PositiveTime = Annotated[Time, Field(gt=0)]
NonNegativeTime = Annotated[Time, Field(ge=0)]
StageVelocity = Annotated[
    Velocity, Field(gt=0), _tested_range(MIN_STAGE_VELOCITY, MAX_STAGE_VELOCITY, "velocity")
]
StageAcceleration = Annotated[
    Acceleration, Field(gt=0), _tested_range(MIN_STAGE_ACCELERATION, MAX_STAGE_ACCELERATION, "acceleration")
]
StageJerk = Annotated[Jerk, Field(gt=0), _tested_range(MIN_STAGE_JERK, MAX_STAGE_JERK, "jerk")]
MountFrequency = Annotated[
    Frequency, Field(gt=0), _tested_range(MIN_MOUNT_FREQUENCY, MAX_MOUNT_FREQUENCY, "frequency")
]
NonNegativeFrequency = Annotated[Frequency, Field(ge=0)]
NonNegativeStiffness = Annotated[Stiffness, Field(ge=0)]
NonNegativeDamping = Annotated[Damping, Field(ge=0)]
PositiveDensity = Annotated[Density, Field(gt=0)]
PositiveInertia = Annotated[Inertia, Field(gt=0)]
DampingRatio = Annotated[Dimensionless, Field(ge=0), _tested_range(0.0, MAX_DAMPING_RATIO, "dimensionless")]
Coordinate = Annotated[
    Length, _within(-MAX_COORDINATE, MAX_COORDINATE, "length", "coordinates of a machine on its floor")
]
Position = tuple[Coordinate, Coordinate, Coordinate]
"""A position [x, y, z] in the floor frame, m, each coordinate within :data:`MAX_COORDINATE`."""
FloorDisplacement = Annotated[
    Length,
    _within(
        -MAX_FLOOR_DISPLACEMENT, MAX_FLOOR_DISPLACEMENT, "length", "a floor vibration, not an earthquake"
    ),
]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", populate_by_name=True)


# ---------------------------------------------------------------------------------------------------------
# machine


def _check_principal_moments(moments: np.ndarray, field: str) -> None:
    """Each principal moment of a rigid body is at most the sum of the other two."""
    a, b, c = sorted(float(x) for x in moments)
    if c > (a + b) * (1.0 + 1e-9):
        raise ValueError(
            f"{field}: principal moments {a:.6g}, {b:.6g}, {c:.6g} kg m^2 break the triangle inequality "
            f"({c:.6g} > {a:.6g} + {b:.6g}): no rigid body has them"
        )


class Block(_Model):
    """A solid rectangular block (the granite base): mass and inertia computed from size and density."""

    size: tuple[BaseSize, BaseSize, BaseSize] = Field(description="[lx, ly, lz], m")
    density: PositiveDensity = Field(description="kg/m^3 (granite: about 2700)")
    corner: Position = Field((0.0, 0.0, 0.0), description="position of the block's minimum corner, m")

    def properties(self) -> tuple[float, np.ndarray, np.ndarray]:
        """Mass (kg), inertia about the c.g. (3, 3) kg m^2 and c.g. (3,) m of the block
        (:func:`studies.block.block_properties`)."""
        mass, inertia, cg = block_properties(self.size, self.density, self.corner)
        return float(mass), inertia, cg


class Machine(_Model):
    """The rigid machine base, without its stages.

    Either ``mass``, ``cg`` and one of ``inertia`` (full 3x3 tensor about the c.g., floor axes, products
    allowed) or ``inertia_diagonal``; or a ``block`` (size, density, corner) from which all three follow.
    """

    mass: MachineMass | None = Field(None, description="kg")
    inertia: list[list[Inertia]] | None = Field(None, description="3x3 tensor about the c.g., kg m^2")
    inertia_diagonal: tuple[PositiveInertia, PositiveInertia, PositiveInertia] | None = Field(
        None, description="[Ixx, Iyy, Izz] about the c.g., kg m^2"
    )
    cg: Position | None = Field(None, description="c.g. position, m")
    block: Block | None = None

    @field_validator("inertia")
    @classmethod
    def _inertia_tensor(cls, value: list[list[float]] | None) -> list[list[float]] | None:
        if value is None:
            return value
        tensor = np.asarray(value, dtype=float) if all(len(r) == 3 for r in value) else None
        if tensor is None or tensor.shape != (3, 3):
            raise ValueError("machine.inertia: must be a 3x3 list of lists")
        scale = float(np.max(np.abs(tensor)))
        if not np.allclose(tensor, tensor.T, rtol=0.0, atol=1e-9 * scale):
            raise ValueError("machine.inertia: must be symmetric (I[i][j] == I[j][i])")
        eig = np.linalg.eigvalsh(tensor)
        if not eig[0] > 1e-12 * scale:
            raise ValueError(
                f"machine.inertia: must be positive definite, principal moments are "
                f"{', '.join(f'{e:.6g}' for e in eig)} kg m^2"
            )
        _check_principal_moments(eig, "machine.inertia")
        return value

    @field_validator("inertia_diagonal")
    @classmethod
    def _inertia_moments(cls, value: tuple[float, float, float] | None) -> tuple[float, float, float] | None:
        if value is not None:
            _check_principal_moments(np.asarray(value), "machine.inertia_diagonal")
        return value

    @model_validator(mode="after")
    def _one_description(self) -> Machine:
        direct = {k for k in ("mass", "inertia", "inertia_diagonal", "cg") if getattr(self, k) is not None}
        if self.block is not None:
            if direct:
                raise ValueError(
                    "machine: give either block or mass/inertia/cg, not both "
                    f"(got block and {sorted(direct)})"
                )
            mass = self.block.properties()[0]
            if not MIN_MACHINE_MASS <= mass <= MAX_MACHINE_MASS:
                raise ValueError(
                    f"machine.block: size and density give a mass of {mass:.6g} kg, outside the accepted "
                    f"{MIN_MACHINE_MASS:g} kg to {MAX_MACHINE_MASS:g} kg"
                )
            return self
        missing = [k for k in ("mass", "cg") if getattr(self, k) is None]
        if self.inertia is None and self.inertia_diagonal is None:
            missing.append("inertia (or inertia_diagonal)")
        if missing:
            raise ValueError(f"machine: missing {', '.join(missing)} (or describe the base as a block)")
        if self.inertia is not None and self.inertia_diagonal is not None:
            raise ValueError("machine: give inertia or inertia_diagonal, not both")
        return self

    def properties(self) -> tuple[float, np.ndarray, np.ndarray]:
        """Mass (kg), inertia tensor about the c.g. (3, 3) kg m^2 and c.g. (3,) m."""
        if self.block is not None:
            return self.block.properties()
        inertia = (
            np.asarray(self.inertia, dtype=float)
            if self.inertia is not None
            else np.diag(np.asarray(self.inertia_diagonal, dtype=float))
        )
        return float(self.mass), inertia, np.asarray(self.cg, dtype=float)


# ---------------------------------------------------------------------------------------------------------
# isolators


def _axis_aliases(value: Any) -> Any:
    """Accept ``horizontal`` (X and Y) and ``vertical`` (Z) for per-axis isolator values."""
    if not isinstance(value, dict):
        return value
    out = {k: v for k, v in value.items() if k not in ("horizontal", "vertical")}
    for alias, axes in (("horizontal", ("x", "y")), ("vertical", ("z",))):
        if alias in value:
            clash = [a for a in axes if a in out]
            if clash:
                raise ValueError(f"give {alias} or {'/'.join(clash)}, not both")
            out.update({a: value[alias] for a in axes})
    return out


class AxisStiffness(_Model):
    """Explicit stiffness per floor axis for every mount, N/m.

    ``horizontal`` sets x and y, ``vertical`` sets z."""

    x: NonNegativeStiffness | None = None
    y: NonNegativeStiffness | None = None
    z: NonNegativeStiffness | None = None

    @model_validator(mode="before")
    @classmethod
    def _aliases(cls, value: Any) -> Any:
        return _axis_aliases(value)


class AxisDamping(_Model):
    """Explicit damping per floor axis for every mount, N s/m.

    ``horizontal`` sets x and y, ``vertical`` sets z."""

    x: NonNegativeDamping | None = None
    y: NonNegativeDamping | None = None
    z: NonNegativeDamping | None = None

    @model_validator(mode="before")
    @classmethod
    def _aliases(cls, value: Any) -> Any:
        return _axis_aliases(value)


class Layout(_Model):
    """Four mounts at (cg_x +- span_x/2, cg_y +- span_y/2, cg_z - height) around the machine's c.g."""

    span_x: Span = Field(description="distance between the mounts along X, m")
    span_y: Span = Field(description="distance between the mounts along Y, m")
    height: Annotated[Length, _tested_range(-MAX_MOUNT_HEIGHT, MAX_MOUNT_HEIGHT, "length")] = Field(
        description="how far the machine's c.g. sits above the mounts, m"
    )

    def positions(self, cg: np.ndarray) -> np.ndarray:
        """(4, 3) mount positions, m, for a machine c.g. at ``cg`` (m)."""
        sx = np.array([-1.0, 1.0, 1.0, -1.0]) * self.span_x / 2.0
        sy = np.array([-1.0, -1.0, 1.0, 1.0]) * self.span_y / 2.0
        return np.stack([cg[0] + sx, cg[1] + sy, np.full(4, cg[2] - self.height)], axis=-1)


LAYOUT_ORDER = "(-x,-y), (+x,-y), (+x,+y), (-x,+y)"
"""Order of the four mounts of a layout around the c.g."""


class FeedforwardSpec(_Model):
    """Feedforward of the stages' inertial wrench to an active mount's actuators (docs/physics.md, "Active
    mounts with feedforward"): ``gain`` times the opposite of the stages' reaction, low-passed at
    ``bandwidth``, clipped to ``force_limit`` per mount and axis. ``gain: 0`` turns it off."""

    gain: Annotated[
        Dimensionless, _within(0.0, 1.5, "dimensionless", "0 (off) to a 50 % over-compensation")
    ] = Field(1.0, description="fraction of the stages' inertial wrench fed forward, 1")
    bandwidth: Annotated[
        Frequency, _within(1.0, 1000.0, "frequency", "the corner of an isolation controller's feedforward")
    ] = Field(50.0, description="corner frequency of the first-order low-pass, Hz")
    force_limit: (
        Annotated[Force, _within(1.0, 1e6, "force", "an actuator of 1 N to 1 MN per mount and axis")] | None
    ) = Field(None, description="largest actuator force per mount and axis, N (none: unlimited)")
    weight: bool = Field(
        False,
        description="also feed forward the change of the stages' weight moment (a stage that has travelled); "
        "false: the inertial wrench only",
    )

    def figures(self) -> Feedforward:
        """The engine's figures (SI; an unlimited actuator as ``inf``)."""
        return Feedforward(
            gain=float(self.gain),
            bandwidth=float(self.bandwidth),
            force_limit=float("inf") if self.force_limit is None else float(self.force_limit),
            weight=bool(self.weight),
        )


class Mount(_Model):
    """One isolator of an explicit list. Its own values win over the group's: explicit ``k``/``c`` first,
    then its overrides, then its own ``preset``; without a preset of its own it takes the group's
    overrides and preset."""

    position: Position = Field(description="point of action, m")
    preset: PresetName | None = None
    f_vertical: MountFrequency | None = None
    f_horizontal: MountFrequency | None = None
    zeta: DampingRatio | None = None
    skyhook: bool | None = None
    feedforward: FeedforwardSpec | None = None
    k: tuple[NonNegativeStiffness, NonNegativeStiffness, NonNegativeStiffness] | None = Field(
        None, description="[kx, ky, kz], N/m"
    )
    c: tuple[NonNegativeDamping, NonNegativeDamping, NonNegativeDamping] | None = Field(
        None, description="[cx, cy, cz], N s/m"
    )


class PresetTuning(_Model):
    """The figures of the model of one isolator type this machine would use (vendor data)."""

    f_vertical: MountFrequency | None = None
    f_horizontal: MountFrequency | None = None
    zeta: DampingRatio | None = None
    skyhook: bool | None = None
    feedforward: FeedforwardSpec | None = None


class Isolators(_Model):
    """The isolators: a type (``preset``) with optional overrides, placed by a ``layout`` or a ``list``.

    Stiffness and damping of a mount along each floor axis come, in order of precedence, from the mount's
    explicit ``k``/``c``, the group's ``k``/``c`` for that axis, or the preset frequency (X, Y from
    ``f_horizontal``, Z from ``f_vertical``) and ``zeta`` applied to the static load the mount carries.
    ``tuning`` replaces a type's preset figures by those of the model this machine would use, whenever
    that type is chosen: a study that varies ``preset`` then compares those models, where the group's
    overrides would apply to every type alike. ``feedforward`` (active mounts: the stages' inertial wrench
    fed to the actuators) comes as a whole from the mount's own, its preset's, the group's, or the group
    preset's (on for ``active``, off for ``air`` and ``elastomer``).
    """

    preset: PresetName = "air"
    tuning: dict[PresetName, PresetTuning] = Field(default_factory=dict)
    f_vertical: MountFrequency | None = None
    f_horizontal: MountFrequency | None = None
    zeta: DampingRatio | None = None
    skyhook: bool | None = None
    feedforward: FeedforwardSpec | None = None
    k: AxisStiffness | None = None
    c: AxisDamping | None = None
    layout: Layout | None = None
    mounts: list[Mount] | None = Field(None, alias="list")

    @model_validator(mode="after")
    def _placement(self) -> Isolators:
        if (self.layout is None) == (self.mounts is None):
            raise ValueError("isolators: give either layout (four mounts around the c.g.) or list, not both")
        if self.mounts is not None:
            if len(self.mounts) < 3:
                raise ValueError(
                    f"isolators: at least 3 are needed to carry a rigid base, got {len(self.mounts)}"
                )
            xy = np.array([m.position[:2] for m in self.mounts])
            try:
                load_share(xy, xy.mean(axis=0), 1.0)
            except CollinearIsolatorsError as err:
                raise ValueError(str(err)) from None
        return self

    @property
    def count(self) -> int:
        return 4 if self.mounts is None else len(self.mounts)

    def preset_of(self, name: str) -> IsolatorPreset:
        """The figures of type ``name``: the preset, with this machine's ``tuning`` of it applied."""
        base = PRESETS[name]
        tune = self.tuning.get(name)
        if tune is None:
            return base
        given = {k: getattr(tune, k) for k, v in tune.model_dump().items() if v is not None}
        if "feedforward" in given:
            given["feedforward"] = given["feedforward"].figures()
        return replace(base, **given)


# ---------------------------------------------------------------------------------------------------------
# stages and their motion


class TrapezoidProfile(_Model):
    """One trapezoidal move by ``travel`` from home (triangular when too short to reach the velocity)."""

    type: Literal["trapezoid"]
    travel: Length = Field(description="signed distance along the stage axis, m")
    velocity: StageVelocity
    acceleration: StageAcceleration
    start: NonNegativeTime = 0.0


class SCurveProfile(_Model):
    """One jerk-limited (S-curve) move by ``travel`` from home."""

    type: Literal["scurve"]
    travel: Length
    velocity: StageVelocity
    acceleration: StageAcceleration
    jerk: StageJerk
    start: NonNegativeTime = 0.0


class ScanProfile(_Model):
    """Out by ``travel``, dwell, back home, dwell; ``repeats`` times (S-curves when ``jerk`` is given)."""

    type: Literal["scan"]
    travel: Length
    velocity: StageVelocity
    acceleration: StageAcceleration
    jerk: StageJerk | None = None
    dwell: NonNegativeTime = 0.0
    repeats: int = Field(1, ge=1, le=1000)
    start: NonNegativeTime = 0.0


class MoveSegment(_Model):
    move: Length = Field(description="signed distance, m")
    velocity: StageVelocity
    acceleration: StageAcceleration
    jerk: StageJerk | None = None


class DwellSegment(_Model):
    dwell: NonNegativeTime


def _segment_kind(value: Any) -> str:
    if isinstance(value, dict):
        return "dwell" if "dwell" in value and "move" not in value else "move"
    return "dwell" if isinstance(value, DwellSegment) else "move"


Segment = Annotated[
    Annotated[MoveSegment, Tag("move")] | Annotated[DwellSegment, Tag("dwell")], Discriminator(_segment_kind)
]


class SequenceProfile(_Model):
    """Moves and dwells one after the other, from home."""

    type: Literal["sequence"]
    segments: list[Segment] = Field(min_length=1)
    start: NonNegativeTime = 0.0


Profile = Annotated[
    TrapezoidProfile | SCurveProfile | ScanProfile | SequenceProfile, Field(discriminator="type")
]


def profile_excursion(profile: Any) -> float:
    """Largest distance from home the profile takes its stage to, m."""
    if isinstance(profile, SequenceProfile):
        pos, far = 0.0, 0.0
        for seg in profile.segments:
            if isinstance(seg, MoveSegment):
                pos += seg.move
                far = max(far, abs(pos))
        return far
    return abs(profile.travel)


class Stage(_Model):
    """A moving mass that travels along a unit axis fixed in the machine (or in its parent stage)."""

    name: Name
    mass: StageMass = Field(description="moving mass, kg")
    home: Position = Field(description="the stage's c.g. at home, floor frame, m")
    axis: tuple[Dimensionless, Dimensionless, Dimensionless] = Field(description="travel direction")
    parent: Name | None = Field(None, description="the stage this one rides on (listed earlier)")
    profile: Profile

    @field_validator("axis")
    @classmethod
    def _unit_axis(cls, value: tuple[float, float, float]) -> tuple[float, float, float]:
        norm = float(np.linalg.norm(value))
        if not norm > 0.0:
            raise ValueError("axis: the zero vector has no direction")
        return tuple(float(x) / norm for x in value)


# ---------------------------------------------------------------------------------------------------------
# floor motion


class SineFloor(_Model):
    """Floor displacement amplitude_i sin(2 pi frequency_i t + phase_i) along each floor axis."""

    amplitude: tuple[FloorDisplacement, FloorDisplacement, FloorDisplacement] = Field(description="m")
    frequency: tuple[NonNegativeFrequency, NonNegativeFrequency, NonNegativeFrequency] = Field(
        description="Hz"
    )
    phase: tuple[Angle, Angle, Angle] = Field((0.0, 0.0, 0.0), description="rad")


class RecordedDisplacement(_Model):
    """Sampled floor displacement per axis, m (an axis left out does not move)."""

    x: list[FloorDisplacement] | None = None
    y: list[FloorDisplacement] | None = None
    z: list[FloorDisplacement] | None = None

    @model_validator(mode="after")
    def _equal_lengths(self) -> RecordedDisplacement:
        lengths = {a: len(getattr(self, a)) for a in AXES if getattr(self, a) is not None}
        if not lengths:
            raise ValueError("floor.recorded.displacement: give at least one of x, y, z")
        if len(set(lengths.values())) != 1:
            raise ValueError(f"floor.recorded.displacement: x, y, z must have equal lengths, got {lengths}")
        if next(iter(lengths.values())) < 2:
            raise ValueError("floor.recorded.displacement: needs at least 2 samples")
        return self

    def samples(self) -> np.ndarray:
        """(3, F) displacement, m."""
        n = next(len(getattr(self, a)) for a in AXES if getattr(self, a) is not None)
        return np.array([getattr(self, a) if getattr(self, a) is not None else np.zeros(n) for a in AXES])


class RecordedFloor(_Model):
    dt: PositiveTime = Field(description="sample interval, s")
    displacement: RecordedDisplacement


BandVelocity = Annotated[
    Velocity,
    _within(0.0, MAX_BAND_VELOCITY, "velocity", "a floor vibration in one band, not an earthquake"),
]
MAX_SPECTRUM_POINTS = 100_000
"""Most points of a floor PSD per axis."""


class SpectrumBands(_Model):
    """One-third-octave RMS velocity of the floor by band centre (``{4 Hz: 20 um/s, 8 Hz: 10 um/s}``):
    bands between given ones are interpolated on log-log axes, bands outside them are zero
    (:mod:`studies.floor`)."""

    bands: dict[Annotated[Frequency, Field(gt=0)], BandVelocity] = Field(
        min_length=1, description="band centre (Hz, nominal or exact) -> RMS velocity in that band, m/s"
    )

    @field_validator("bands")
    @classmethod
    def _centres(cls, value: dict[float, float]) -> dict[float, float]:
        seen: dict[int, float] = {}
        for f in value:
            n = band_number(f)  # ValueError naming the frequency
            if n in seen:
                raise ValueError(f"{f:g} Hz and {seen[n]:g} Hz are the same band")
            seen[n] = f
        return value


class SpectrumPSD(_Model):
    """A one-sided power spectral density of the floor: ``frequency`` (Hz, increasing) with either
    ``displacement`` (m^2/Hz) or ``velocity`` ((m/s)^2/Hz) at each frequency."""

    frequency: list[Annotated[Frequency, Field(gt=0)]] = Field(
        min_length=2, max_length=MAX_SPECTRUM_POINTS, description="Hz, increasing"
    )
    displacement: list[Annotated[DisplacementPSD, Field(ge=0)]] | None = Field(
        None, max_length=MAX_SPECTRUM_POINTS, description="displacement PSD, m^2/Hz"
    )
    velocity: list[Annotated[VelocityPSD, Field(ge=0)]] | None = Field(
        None, max_length=MAX_SPECTRUM_POINTS, description="velocity PSD, (m/s)^2/Hz (m^2/s^2/Hz)"
    )

    @model_validator(mode="after")
    def _one_series(self) -> SpectrumPSD:
        if (self.displacement is None) == (self.velocity is None):
            raise ValueError("psd: give either displacement (m^2/Hz) or velocity ((m/s)^2/Hz)")
        values = self.displacement if self.displacement is not None else self.velocity
        if len(values) != len(self.frequency):
            raise ValueError(
                f"psd: {len(values)} PSD values for {len(self.frequency)} frequencies; give one per frequency"
            )
        if any(b <= a for a, b in zip(self.frequency, self.frequency[1:], strict=False)):
            raise ValueError("psd.frequency: must increase")
        return self


class PSDSpectrum(_Model):
    psd: SpectrumPSD


def _axis_spectrum(value: Any) -> Any:
    """One axis of a floor spectrum: a VC level name, ``{bands: ...}`` or ``{psd: ...}``; errors name the
    reason (pydantic adds the axis)."""
    if value is None or isinstance(value, SpectrumBands | PSDSpectrum):
        return value
    if isinstance(value, str):
        return canonical_vc(value)
    if isinstance(value, dict) and len(value) == 1 and ("bands" in value or "psd" in value):
        kind = SpectrumBands if "bands" in value else PSDSpectrum
        try:
            return kind.model_validate(value)
        except ValidationError as err:
            raise ValueError("; ".join(error_messages(err))) from None
    raise ValueError(
        "give a VC level (such as 'VC-D'), {bands: {<centre>: <RMS velocity>, ...}} or "
        f"{{psd: {{frequency: [...], displacement: [...]}}}}, got {value!r}"
    )


AxisSpectrum = Annotated[str | SpectrumBands | PSDSpectrum | None, BeforeValidator(_axis_spectrum)]


class FloorSpectrum(_Model):
    """The floor's steady vibration per axis as a spectrum (what ``floor_point_velocity`` is computed
    from; :mod:`studies.floor`): per floor axis a VC level (``z: VC-D``), one-third-octave band levels
    (``z: {bands: {4 Hz: 20 um/s, ...}}``) or a PSD (``z: {psd: {frequency: [...], displacement:
    [...]}}``). An axis left out does not move; the axes are uncorrelated."""

    x: AxisSpectrum = None
    y: AxisSpectrum = None
    z: AxisSpectrum = None

    @model_validator(mode="after")
    def _some_axis(self) -> FloorSpectrum:
        if self.x is None and self.y is None and self.z is None:
            raise ValueError("floor.spectrum: give at least one of x, y, z")
        return self


class Floor(_Model):
    """Motion of the floor under the isolators: a sine per axis or a recorded displacement (the time
    integration sees them), and/or a ``spectrum`` (steady state, one-third-octave bands: the velocity at
    the points of interest, :mod:`studies.floor`)."""

    sine: SineFloor | None = None
    recorded: RecordedFloor | None = None
    spectrum: FloorSpectrum | None = None

    @model_validator(mode="after")
    def _one_kind(self) -> Floor:
        if self.sine is not None and self.recorded is not None:
            raise ValueError("floor: give either sine or recorded, not both")
        if self.sine is None and self.recorded is None and self.spectrum is None:
            raise ValueError("floor: give sine, recorded or spectrum")
        return self


# ---------------------------------------------------------------------------------------------------------
# simulation


ACCURACY_LEVELS: dict[str, float | None] = {"fast": 0.05, "balanced": 0.005, "reference": None}
"""Accuracy requests and the relative error each allows on the sizing outputs (``reference`` runs the
nonlinear level with the reference integrator itself)."""
DEFAULT_FIDELITY = "ltv"
DEFAULT_INTEGRATOR = "rk4"
DEFAULT_DT = 1e-3
"""Fidelity, integrator and step (s) of a simulation block that names neither them nor an accuracy."""
MIN_DT = 1e-4
MAX_DT = 5e-2
"""Accepted time steps, s: the range the engine's extreme-scene tests cover."""
_CHOICE_FIELDS = ("fidelity", "integrator")
_REQUEST_FIELDS = ("accuracy", "tolerance")


def parse_tolerance(value: Any, field: str = "simulation.tolerance") -> tuple[float, bool]:
    """An accuracy tolerance: ``(value, relative)``.

    ``"10 um"`` (a length) is an absolute tolerance on peak displacement, m; ``"1 %"`` (dimensionless) a
    relative error of the sizing outputs. A bare number is refused: it would be ambiguous.
    """
    if not isinstance(value, str):
        raise ValueError(
            f"{field}: give a length such as '10 um' (absolute error of peak displacement) or "
            f"a percentage such as '1 %' (relative error), got {value!r}"
        )
    try:
        float(value.strip())
    except ValueError:
        pass
    else:
        raise ValueError(
            f"{field}: {value!r} has no unit; write '10 um' (absolute error of peak "
            "displacement) or '1 %' (relative error)"
        )
    try:
        x, relative = to_si(value, "length", field), False
    except ValueError:
        try:
            x, relative = to_si(value, "dimensionless", field), True
        except ValueError:
            raise ValueError(
                f"{field}: cannot read {value!r} as a length ('10 um') or a relative error ('1 %')"
            ) from None
    if relative and not 0.0 < x <= 1.0:
        raise ValueError(f"{field}: a relative tolerance must lie in (0, 100 %], got {value!r}")
    if not relative and not 0.0 < x <= 1.0:
        raise ValueError(f"{field}: an absolute tolerance must lie in (0, 1 m], got {value!r}")
    return x, relative


TOLERANCE_OUTPUTS = {
    "peak_displacement": "length",
    "peak_point_displacement": "length",
    "peak_rotation": "angle",
    "peak_isolator_force": "force",
    "peak_isolator_deflection": "length",
    "min_isolator_load": "force",
    "max_isolator_load": "force",
    "settling_time": "time",
}
"""Outputs a per-output tolerance may name, and the dimension of an absolute tolerance on each."""


def parse_output_tolerance(name: str, value: Any, field: str) -> tuple[float, bool]:
    """One entry of a per-output tolerance: ``(value, relative)``; ``"1 %"`` relative to each component's
    own reference value, or an absolute error in the output's unit (``"10 um"``, ``"0.1 mrad"``,
    ``"50 N"``, ``"5 ms"``: :data:`TOLERANCE_OUTPUTS`), SI."""
    if name not in TOLERANCE_OUTPUTS:
        raise ValueError(f"{field}: unknown output {name!r}; one of {', '.join(TOLERANCE_OUTPUTS)}")
    dimension = TOLERANCE_OUTPUTS[name]
    example = {"length": "10 um", "angle": "0.1 mrad", "force": "50 N", "time": "5 ms"}[dimension]
    if not isinstance(value, str) or "%" not in value and not any(c.isalpha() for c in value):
        raise ValueError(
            f"{field}: give a relative error such as '1 %' or an absolute one in {dimension} such as "
            f"{example!r}, got {value!r}"
        )
    if "%" in value:
        x, relative = to_si(value, "dimensionless", field), True
        if not 0.0 < x <= 1.0:
            raise ValueError(f"{field}: a relative tolerance must lie in (0, 100 %], got {value!r}")
    else:
        x, relative = to_si(value, dimension, field), False
        if not (np.isfinite(x) and x > 0.0):
            raise ValueError(f"{field}: an absolute tolerance must be positive, got {value!r}")
    return x, relative


def tolerance_text(x: float, relative: bool, dimension: str = "length") -> str:
    """A parsed tolerance as text: ``"1 %"`` or ``"1e-05 m"`` (SI unit of ``dimension``)."""
    unit = {"length": "m", "angle": "rad", "force": "N", "time": "s"}[dimension]
    return f"{x * 100:.6g} %" if relative else f"{x:.6g} {unit}"


class Simulation(_Model):
    """How to simulate: model fidelity, integrator and step, or an accuracy request; duration and settling
    tolerance.

    Give either ``fidelity``/``integrator`` (defaults ltv and rk4, step ``dt`` default 1 ms) or an accuracy
    request: ``accuracy`` (fast ~5 %, balanced ~0.5 %, reference) or ``tolerance`` (``"10 um"`` of peak
    displacement, or a relative error ``"1 %"``). An accuracy request lets the study runner pick the
    cheapest fidelity, integrator and step whose error, measured on pilot cases of the study against the
    nonlinear reference, stays inside it (:mod:`studies.accuracy`); ``dt`` then caps the step it may pick
    (``reference``: the step). Until a runner resolves it, ``fidelity``, ``integrator`` and ``dt`` of such
    a block are None.

    Where a study's simulation block overrides its scene's, an accuracy request replaces the scene's
    fidelity, integrator and step as a whole (and an explicit fidelity or integrator replaces a scene's
    accuracy request).
    """

    fidelity: Literal["lti", "ltv", "nonlinear"] | None = Field(
        None, description=f"model level (default {DEFAULT_FIDELITY}); not with accuracy/tolerance"
    )
    integrator: Literal["euler", "rk4", "exact", "reference"] | None = Field(
        None, description=f"time integrator (default {DEFAULT_INTEGRATOR}); not with accuracy/tolerance"
    )
    dt: Annotated[Time, Field(gt=0), _tested_range(MIN_DT, MAX_DT, "time")] | None = Field(
        None,
        description=f"time step, s ({MIN_DT * 1e3:g} to {MAX_DT * 1e3:g} ms; default "
        f"{DEFAULT_DT * 1e3:g} ms); with an accuracy request the largest step it may pick",
    )
    accuracy: Literal["fast", "balanced", "reference"] | None = Field(
        None,
        description="let the runner pick fidelity, integrator and step: fast (~5 % error), balanced (~0.5 %) "
        "or reference (nonlinear level, reference integrator)",
    )
    tolerance: str | dict[str, str] | None = Field(
        None,
        description="let the runner pick fidelity, integrator and step for this error: a length such as "
        "'10 um' (peak displacement) or a relative error such as '1 %' (of every sizing output, relative "
        "to the largest reference peak of its kind); or per output, bounding each component of each named "
        "output: {peak_point_displacement: '1 %', settling_time: '5 ms'} (relative to the component's own "
        "reference value, or absolute in the output's unit)",
    )
    auto_step: bool = Field(True, description="shorten the step where the integrator would be unstable")

    def engine_choice(self) -> tuple[str, str, float]:
        """(fidelity, integrator, dt in s) the engine runs with. Raises ValueError while an accuracy request
        is unresolved (the study runner resolves it before any case runs)."""
        if self.fidelity is None or self.integrator is None or self.dt is None:
            raise ValueError(
                "simulation: the accuracy request is not resolved to a fidelity, integrator and step"
            )
        return self.fidelity, self.integrator, float(self.dt)

    duration: Literal["auto"] | Annotated[Time, Field(gt=0, le=3600)] = Field(
        "auto",
        description=f"s, or auto: last stage move end + the larger of {AUTO_DURATION_MARGIN:g} s and "
        f"{AUTO_DURATION_DECAYS:g} time constants of the slowest-decaying mode "
        f"(at most {AUTO_DURATION_CAP:g} s)",
    )
    settle_tolerance: PositiveLength = Field(10e-6, description="m")
    gravity_stiffness: bool = Field(
        True, description="include the rocking stiffness of preload and weights that tilt with the base"
    )
    preload: Literal["floor", "base"] = Field(
        "floor",
        description="nonlinear level: the mounts' preload stays vertical (floor) or turns with the base "
        "(base: mounts that tilt with it, no rocking stiffness -W h from the preload)",
    )

    @field_validator("tolerance", mode="before")
    @classmethod
    def _tolerance_text(cls, value: Any) -> str | dict[str, str] | None:
        if value is None:
            return value
        if isinstance(value, dict):
            if not value:
                raise ValueError("simulation.tolerance: name at least one output, e.g. {settling_time: 5 %}")
            out = {}
            for name, v in value.items():
                x, relative = parse_output_tolerance(str(name), v, f"simulation.tolerance.{name}")
                out[str(name)] = tolerance_text(x, relative, TOLERANCE_OUTPUTS[str(name)])
            return out
        x, relative = parse_tolerance(value)
        return tolerance_text(x, relative)

    @model_validator(mode="after")
    def _choice_or_request(self) -> Simulation:
        if self.accuracy is not None and self.tolerance is not None:
            raise ValueError(
                f"simulation.accuracy: give accuracy or tolerance, not both (got accuracy {self.accuracy!r} "
                f"and tolerance {self.tolerance!r})"
            )
        fields_set = self.__pydantic_fields_set__
        request = self.accuracy if self.accuracy is not None else self.tolerance
        if request is not None:
            given = {k: getattr(self, k) for k in _CHOICE_FIELDS if getattr(self, k) is not None}
            if given:
                what = " and ".join(f"{k} {v!r}" for k, v in given.items())
                kind = "accuracy" if self.accuracy is not None else "tolerance"
                raise ValueError(
                    f"simulation.accuracy: an accuracy request ({kind} {request!r}) picks the fidelity and "
                    f"integrator itself; give either the request or "
                    f"{'/'.join(_CHOICE_FIELDS)}, not both (got {what})"
                )
            if not self.gravity_stiffness:
                raise ValueError(
                    "simulation.gravity_stiffness: an accuracy request measures against the nonlinear level, "
                    "which always has the weights' rocking stiffness; gravity_stiffness: false is for the "
                    "lti and ltv levels named explicitly"
                )
            if self.preload != "floor":
                raise ValueError(
                    "simulation.preload: 'base' is a choice of the nonlinear level; an accuracy request "
                    "picks the level itself (name fidelity: nonlinear)"
                )
            # a request overrides a scene's choice as a whole when this block is merged over it
            fields_set.update(_CHOICE_FIELDS)
            if self.dt is None:
                fields_set.add("dt")
            return self
        if any(getattr(self, k) is not None for k in _CHOICE_FIELDS):
            fields_set.update(_REQUEST_FIELDS)  # and an explicit choice overrides a scene's request
        for name, default in (
            ("fidelity", DEFAULT_FIDELITY),
            ("integrator", DEFAULT_INTEGRATOR),
            ("dt", DEFAULT_DT),
        ):
            if getattr(self, name) is None:  # a default, not an input: it must not override when merged
                setattr(self, name, default)
                fields_set.discard(name)
        if not self.gravity_stiffness and self.fidelity == "nonlinear":
            raise ValueError(
                "simulation.gravity_stiffness: the nonlinear level always has the rocking stiffness of the "
                "weights that tilt with the base (false applies to lti and ltv only); without it a base that "
                "would tip is not reported as tipping"
            )
        if self.preload != "floor" and self.fidelity != "nonlinear":
            raise ValueError(
                f"simulation.preload: 'base' (the preload turning with the base) is a choice of the "
                f"nonlinear level, got fidelity {self.fidelity!r}"
            )
        if self.integrator == "exact" and self.fidelity != "lti":
            raise ValueError(
                f"simulation.integrator: 'exact' discretisation needs a time-invariant model "
                f"(fidelity lti), got fidelity {self.fidelity!r}"
            )
        return self

    @property
    def request(self) -> str | None:
        """The accuracy request as text (``"fast"``, ``"tolerance 1 %"``), or None for an explicit choice."""
        if self.accuracy is not None:
            return self.accuracy
        if isinstance(self.tolerance, dict):
            return "tolerance " + ", ".join(f"{k} {v}" for k, v in self.tolerance.items())
        return None if self.tolerance is None else f"tolerance {self.tolerance}"


# ---------------------------------------------------------------------------------------------------------
# scene


class Scene(_Model):
    """A machine base on isolators with its stages, points of interest, floor motion and simulation."""

    machine: Machine
    isolators: Isolators
    stages: list[Stage] = Field(default_factory=list)
    points: dict[Name, Position] = Field(
        default_factory=dict, description="material points of the machine, m"
    )
    floor: Floor | None = None
    simulation: Simulation = Field(default_factory=Simulation)
    criteria: Criteria | None = Field(
        None, description="limits at the points of interest and on the mounts (studies.criteria)"
    )

    @field_validator("stages")
    @classmethod
    def _stage_tree_and_travel(cls, stages: list[Stage], info: ValidationInfo) -> list[Stage]:
        names = [s.name for s in stages]
        index = {}
        for i, s in enumerate(stages):
            if s.name in index:
                raise ValueError(
                    f"stages[{i}].name: {s.name!r} is already the name of stages[{index[s.name]}]"
                )
            index[s.name] = i
        for i, s in enumerate(stages):
            if s.parent is None:
                continue
            if s.parent == s.name:
                raise ValueError(f"stages[{i}].parent: stage {s.name!r} cannot ride on itself")
            if s.parent not in index:
                raise ValueError(
                    f"stages[{i}].parent: no stage named {s.parent!r} (stages: {', '.join(names)})"
                )
            if index[s.parent] > i:
                chain, cur = [s.name], s.parent
                while cur is not None and cur not in chain:
                    chain.append(cur)
                    cur = stages[index[cur]].parent
                if cur is not None:
                    raise ValueError(f"stages[{i}].parent: cycle {' -> '.join([*chain, cur])}")
                raise ValueError(
                    f"stages[{i}].parent: {s.parent!r} must be listed before {s.name!r} (parents come first)"
                )
        machine = info.data.get("machine")
        block = machine.block if machine is not None else None
        for i, s in enumerate(stages):
            bound = float(travel_bound(s.axis, block.size if block is not None else None))
            if block is not None:
                where = f"the base's {bound:.6g} m extent along the stage axis"
            else:
                where = f"{MAX_TRAVEL:g} m"
            far = profile_excursion(s.profile)
            if beyond_travel(far, bound):
                raise ValueError(
                    f"stages[{i}].profile.travel: the stage would travel {far:.6g} m from home, "
                    f"more than {where}"
                )
        return stages

    @model_validator(mode="after")
    def _stage_mass(self) -> Scene:
        """Stages heavier than the base are refused. What only the assembled scene shows (mounts that
        cannot carry the weight, moves off the base) is the check step's, :func:`studies.scenes.check_scene`:
        parsing builds nothing."""
        stages = sum(s.mass for s in self.stages)
        base = self.machine.properties()[0]
        if stages > MAX_STAGE_MASS_RATIO * base * (1.0 + 1e-12):
            raise ValueError(
                f"stages: together they weigh {stages:.6g} kg, more than {MAX_STAGE_MASS_RATIO:g} times the "
                f"machine base ({base:.6g} kg); stages are point masses, and a base lighter than its stages "
                "leaves the machine almost without rotational inertia"
            )
        return self

    @model_validator(mode="after")
    def _criteria_points(self) -> Scene:
        if self.criteria is not None:
            self.criteria.check_points(self.points, self.has_floor_spectrum())
        return self

    def has_floor_spectrum(self) -> bool:
        """Whether the floor's vibration is given as a spectrum (what a velocity criterion judges)."""
        return self.floor is not None and getattr(self.floor, "spectrum", None) is not None

    def total_mass(self) -> float:
        """Machine plus all stages, kg."""
        return float(self.machine.properties()[0] + sum(s.mass for s in self.stages))


# ---------------------------------------------------------------------------------------------------------
# study inputs (the Study model itself is in studies.study)

Value = StrictFloat | StrictInt | StrictStr
MAX_LIST_ENTRIES = 10_000_000
"""Most entries of a parameter's ``values`` or a list design's ``cases``: the most cases a design holds
(:data:`studies.designs.GRID_LIMIT`). A service refuses lists longer than its case limit
(``ISOLAB_MAX_CASES``) before parsing (:func:`studies.definitions.long_lists`)."""


class RangeSpec(_Model):
    """A continuous range; ``num`` levels for a grid (sampled designs draw from it)."""

    start: Value
    stop: Value
    num: int | None = Field(None, ge=1, le=100_000)
    scale: Literal["linear", "log"] = "linear"


class ParameterSpec(_Model):
    """One varied input: a path into the scene and its ``values`` or ``range`` (units allowed)."""

    name: Name | None = None
    path: str = Field(min_length=1, max_length=200)
    values: list[Value] | None = Field(None, min_length=1, max_length=MAX_LIST_ENTRIES)
    range: RangeSpec | None = None

    @model_validator(mode="after")
    def _values_or_range(self) -> ParameterSpec:
        if self.values is not None and self.range is not None:
            raise ValueError("give values or range, not both")
        return self


class DesignSpec(_Model):
    """How cases are drawn: full factorial ``grid``, ``lhs``, ``sobol``, ``random``, ``saltelli`` (Sobol'
    indices: ``samples`` is the base sample N and the study runs N (D + 2) cases, N (2D + 2) with
    ``second_order``), explicit ``list``, or ``optimize`` (a pymoo optimiser picks the cases generation
    by generation within ``budget``: :mod:`studies.optimisation`)."""

    type: Literal["grid", "lhs", "sobol", "random", "saltelli", "list", "optimize"] = "grid"
    samples: int | None = Field(None, ge=1, le=10_000_000)
    seed: int = Field(0, ge=0)
    second_order: bool | None = Field(
        None, description="saltelli only: also run the cases pairwise (second-order) indices need; default no"
    )
    cases: list[dict[str, Value]] | None = Field(None, max_length=MAX_LIST_ENTRIES)
    # optimize only (see studies.optimisation and studies.goals, which check them against the outputs)
    objective: str | list[str] | None = Field(
        None,
        description="optimize: 'minimize <quantity>' or 'maximize <quantity>', or a list of them "
        "(multi-objective), e.g. 'minimize settling_time.tool'",
    )
    constraints: list[str] | None = Field(
        None,
        max_length=100,
        description="optimize: 'criteria' (every criterion of the study's criteria block is met) or "
        "'<quantity> <= <value>' / '<quantity> >= <value>' with units, e.g. 'min_isolator_load >= 0 N'",
    )
    algorithm: str | None = Field(
        None,
        description="optimize: a pymoo algorithm (ga, de, pso, nelder-mead, pattern, nsga2); default "
        "ga for one objective, nsga2 for several",
    )
    budget: int | None = Field(None, ge=1, le=1_000_000, description="optimize: total cases to evaluate")
    population: int | None = Field(
        None, ge=2, le=10_000, description="optimize: cases per generation (default 40, at most the budget)"
    )


def error_messages(err: ValidationError) -> list[str]:
    """One line per error, ``dotted.path: reason``, e.g. ``scene.machine.inertia: must be symmetric``.

    Pydantic's "Value error, " prefix is dropped, and a message that already names its field
    (``stages[1].parent: ...`` under ``stages``) is not prefixed twice."""
    out = []
    for e in err.errors():
        parts = [str(x) for x in e["loc"]]
        loc = ".".join(parts)
        msg = e["msg"].removeprefix("Value error, ")
        head, sep, rest = msg.partition(": ")
        if sep and " " not in head and parts:
            if loc.endswith(head) or head in parts:
                msg = rest
            elif head.startswith(parts[-1]):
                loc, msg = ".".join([*parts[:-1], head]), rest
        out.append(f"{loc}: {msg}" if loc else msg)
    return out
