"""The stages: moving masses on the machine, each travelling along its axis by a motion profile
(trapezoid, S-curve, scan or a sequence of moves and dwells)."""

from __future__ import annotations

from typing import Annotated, Any, Literal

import numpy as np
from pydantic import Discriminator, Field, Tag, field_validator, model_validator

from isolab.engine.modal import MOTION_NAMES
from isolab.engine.results import N_MODES
from isolab.studies.inputs.schema.fields import (
    MAX_SEGMENTS,
    InputModel,
    Name,
    NonNegativeTime,
    Position,
    StageAcceleration,
    StageJerk,
    StageMass,
    StageVelocity,
    within,
)
from isolab.studies.units import Damping, Dimensionless, Frequency, Length, Stiffness

SHAPER_MODES: dict[str, str] = {
    **{motion: dof for dof, motion in MOTION_NAMES.items()},
    **{dof: dof for dof in MOTION_NAMES},
}
"""The names a shaper's ``mode`` may take -> the degree of freedom the mode moves most: the motions
(surge, sway, heave, pitch, roll, yaw) and the degrees of freedom (x, y, z, rx, ry, rz)."""


class ShaperSpec(InputModel):
    """An input shaper on the profile (docs/physics.md, "Input shaping"): the profile's acceleration
    convolved with the shaper's impulses, tuned to a mode of ``frequency`` and ``damping``, or to one of
    the scene's own rigid-body modes (``mode``: its frequency and damping ratio in each case). The move gets
    longer by the shaper's duration: half the mode's damped period (ZV) or a whole one (ZVD, EI)."""

    type: Literal["zv", "zvd", "ei"] = Field(
        description="zv (zero vibration), zvd (zero vibration and derivative: less sensitive to a frequency "
        "error) or ei (extra insensitive, 5 % vibration tolerated at the frequency)"
    )
    frequency: (
        Annotated[Frequency, within(0.1, 1000.0, "frequency", "a mode of a machine on isolators")] | None
    ) = Field(None, description="the mode's natural frequency, Hz (or name the mode)")
    damping: Annotated[Dimensionless, within(0.0, 0.9, "dimensionless", "an underdamped mode")] | None = (
        Field(
            None,
            description="the mode's damping ratio, 1 (with frequency, 0 if not given; a named mode "
            "brings its own)",
        )
    )
    mode: int | str | None = Field(
        None,
        description=f"tune to one of the scene's own rigid-body modes instead, its frequency and damping "
        f"ratio those of each case: its number (1 to {N_MODES}, ascending frequency) or the motion it moves "
        "most (surge, sway, heave, pitch, roll, yaw; or x, y, z, rx, ry, rz)",
    )

    @field_validator("mode", mode="before")
    @classmethod
    def _known_mode(cls, value: Any) -> int | str | None:
        if value is None:
            return None
        if isinstance(value, str) and value.strip().isdigit():
            value = int(value.strip())
        if isinstance(value, bool) or not isinstance(value, int | str):
            raise ValueError(f"must be a mode number or name, got {value!r}")
        if isinstance(value, int) and not 1 <= value <= N_MODES:
            raise ValueError(
                f"mode number {value!r} is out of range: the rigid base has modes 1 to {N_MODES}"
            )
        if isinstance(value, str):
            name = value.strip().lower()
            if name not in SHAPER_MODES:
                raise ValueError(
                    f"unknown mode {value!r}: name a mode by its number (1 to {N_MODES}, ascending "
                    f"frequency) or by the motion it moves most ({', '.join(SHAPER_MODES)})"
                )
            return name
        return value

    @model_validator(mode="after")
    def _one_tuning(self) -> ShaperSpec:
        if self.mode is not None and self.frequency is not None:
            raise ValueError(
                "shaper.frequency: give frequency or mode, not both (a mode brings its frequency)"
            )
        if self.mode is None and self.frequency is None:
            raise ValueError("shaper.frequency: give the frequency to tune to, or the mode (mode: heave)")
        if self.mode is not None and self.damping is not None:
            raise ValueError(
                "shaper.damping: a shaper tuned to a mode takes the mode's damping ratio; give damping "
                "with frequency only"
            )
        return self


class TrapezoidProfile(InputModel):
    """One trapezoidal move by ``travel`` from home (triangular when too short to reach the velocity)."""

    type: Literal["trapezoid"]
    travel: Length = Field(description="signed distance along the stage axis, m")
    velocity: StageVelocity
    acceleration: StageAcceleration
    start: NonNegativeTime = 0.0
    shaper: ShaperSpec | None = None


class SCurveProfile(InputModel):
    """One jerk-limited (S-curve) move by ``travel`` from home."""

    type: Literal["scurve"]
    travel: Length
    velocity: StageVelocity
    acceleration: StageAcceleration
    jerk: StageJerk
    start: NonNegativeTime = 0.0
    shaper: ShaperSpec | None = None


class ScanProfile(InputModel):
    """Out by ``travel``, dwell, back home, dwell; ``repeats`` times (S-curves when ``jerk`` is given)."""

    type: Literal["scan"]
    travel: Length
    velocity: StageVelocity
    acceleration: StageAcceleration
    jerk: StageJerk | None = None
    dwell: NonNegativeTime = 0.0
    repeats: int = Field(1, ge=1, le=1000)
    start: NonNegativeTime = 0.0
    shaper: ShaperSpec | None = None


class MoveSegment(InputModel):
    move: Length = Field(description="signed distance, m")
    velocity: StageVelocity
    acceleration: StageAcceleration
    jerk: StageJerk | None = None


class DwellSegment(InputModel):
    dwell: NonNegativeTime


def _segment_kind(value: Any) -> str:
    if isinstance(value, dict):
        return "dwell" if "dwell" in value and "move" not in value else "move"
    return "dwell" if isinstance(value, DwellSegment) else "move"


Segment = Annotated[
    Annotated[MoveSegment, Tag("move")] | Annotated[DwellSegment, Tag("dwell")], Discriminator(_segment_kind)
]


class SequenceProfile(InputModel):
    """Moves and dwells one after the other, from home."""

    type: Literal["sequence"]
    segments: list[Segment] = Field(min_length=1, max_length=MAX_SEGMENTS)
    start: NonNegativeTime = 0.0
    shaper: ShaperSpec | None = None


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


class Servo(InputModel):
    """The stage driven by a servo along its axis instead of following its profile exactly: the following
    error ``e`` (the profile minus the stage's position) obeys ``e'' + 2 zeta w e' + w^2 e = r'' + (the
    base's acceleration along the axis)`` (docs/physics.md, "Servo stages"). Give the closed loop's
    ``bandwidth`` (its natural frequency ``w / 2 pi``) and ``damping_ratio``, or the servo's ``stiffness``
    and ``damping`` (``w^2 = stiffness / M``, ``M`` the mass the drive moves: the stage and every stage
    riding on it)."""

    bandwidth: Annotated[Frequency, Field(gt=0)] | None = Field(
        None, description="natural frequency of the following error, Hz (a linear stage: 20 to 200 Hz)"
    )
    damping_ratio: Annotated[Dimensionless, Field(ge=0, le=5)] | None = Field(
        None, description="damping ratio of the following error, 1 (with bandwidth; 0.7 when omitted)"
    )
    stiffness: Annotated[Stiffness, Field(gt=0)] | None = Field(
        None, description="servo stiffness along the axis, N/m (instead of bandwidth)"
    )
    damping: Annotated[Damping, Field(ge=0)] | None = Field(
        None, description="servo damping along the axis, N s/m (with stiffness; 0 when omitted)"
    )

    @model_validator(mode="after")
    def _one_description(self) -> Servo:
        by_bandwidth = self.bandwidth is not None or self.damping_ratio is not None
        by_stiffness = self.stiffness is not None or self.damping is not None
        if by_bandwidth and by_stiffness:
            raise ValueError("servo: give bandwidth and damping_ratio, or stiffness and damping, not both")
        if self.bandwidth is None and self.stiffness is None:
            raise ValueError("servo: give bandwidth (and damping_ratio) or stiffness (and damping)")
        return self


class Stage(InputModel):
    """A moving mass that travels along a unit axis fixed in the machine (or in its parent stage)."""

    name: Name
    mass: StageMass = Field(description="moving mass, kg")
    home: Position = Field(description="the stage's c.g. at home, floor frame, m")
    axis: tuple[Dimensionless, Dimensionless, Dimensionless] = Field(description="travel direction")
    parent: Name | None = Field(None, description="the stage this one rides on (listed earlier)")
    profile: Profile
    servo: Servo | None = Field(
        None, description="driven by a servo along its axis (none: the stage follows its profile exactly)"
    )

    @field_validator("axis")
    @classmethod
    def _unit_axis(cls, value: tuple[float, float, float]) -> tuple[float, float, float]:
        norm = float(np.linalg.norm(value))
        if not norm > 0.0:
            raise ValueError("axis: the zero vector has no direction")
        x, y, z = (float(v) / norm for v in value)
        return x, y, z
