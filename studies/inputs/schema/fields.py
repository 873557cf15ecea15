"""The kinds of value the scene and study files hold: accepted ranges, bounded quantities, names and
positions, and :class:`InputModel`, the base of every model (unknown keys refused).

The accepted ranges (and :data:`~studies.inputs.schema.simulation.MIN_DT`/``MAX_DT``) are the ranges
tests/engine/test_extremes.py draws scenes from. Quantities are SI after conversion (:mod:`studies.units`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, GetCoreSchemaHandler, GetJsonSchemaHandler
from pydantic_core import CoreSchema, core_schema

from isolab.studies.units import (
    Acceleration,
    Damping,
    Density,
    Dimensionless,
    Frequency,
    Inertia,
    Jerk,
    Length,
    Mass,
    Stiffness,
    Time,
    Velocity,
    si_unit,
)

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
MAX_MOUNTS = 64
"""Most mounts of a ``list`` placement (a machine base stands on 3 to 5; a long beam on a few more)."""
MAX_STAGES = 32
"""Most stages of a scene."""
MAX_POINTS = 256
"""Most points of interest of a scene."""
MAX_CRITERIA = 256
"""Most entries of a ``criteria`` block (its points and ``isolators``)."""
MAX_SEGMENTS = 10_000
"""Most segments of one sequence profile."""
MAX_PARAMETERS = 64
"""Most parameters one study varies."""
MAX_RECORDED_SAMPLES = 2_000_000
"""Most samples of one axis of a recorded floor displacement."""
MAX_STAGE_MASS_RATIO = 1.0
"""The stages together weigh at most this many times the machine base. Stages are point masses: a base
lighter than its stages leaves the composite body almost without rotational inertia, its rocking modes
reach kHz, and they shift with the stages' positions faster than the stability guard allows for."""
# The accepted ranges above (and MIN_DT/MAX_DT) are the ranges tests/engine/test_extremes.py draws scenes
# from: within them every result is finite and bounded, or flagged unstable/tipping, or refused.


@dataclass(frozen=True)
class Within:
    """Refuses a value outside [low, high] (SI) after conversion, saying ``why`` the range is what it is;
    its JSON schema carries the range as ``minimum``/``maximum`` and ``why`` as ``x-range-reason`` (what
    the study-file reference, :mod:`studies.authoring.file_reference`, and editors show)."""

    low: float
    high: float
    dimension: str
    why: str

    def check(self, value: float) -> float:
        """``value`` (SI) if it lies in [low, high]; else ValueError saying the range and why."""
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


def within(low: float, high: float, dimension: str, why: str) -> Within:
    """Refuse a value of ``dimension`` outside [low, high] (SI), saying ``why`` the range is what it is."""
    si_unit(dimension)  # a known dimension
    return Within(low, high, dimension, why)


def tested_range(low: float, high: float, dimension: str) -> Within:
    """Refuse a value of ``dimension`` outside [low, high] (SI): the range tests/engine/test_extremes.py
    covers."""
    return within(low, high, dimension, "the range the engine is tested over")


PresetName = Literal["active", "air", "elastomer"]
Name = Annotated[str, Field(pattern=r"^[A-Za-z][A-Za-z0-9_]*$", max_length=64)]
"""Names of stages and points: a letter, then letters, digits or underscores (they appear in parameter
paths and dataset coordinates)."""

PositiveLength = Annotated[Length, Field(gt=0)]
BaseSize = Annotated[Length, Field(gt=0), tested_range(MIN_BASE_SIZE, MAX_BASE_SIZE, "length")]
Span = Annotated[Length, Field(gt=0), tested_range(MIN_SPAN, MAX_SPAN, "length")]
MachineMass = Annotated[Mass, Field(gt=0), tested_range(MIN_MACHINE_MASS, MAX_MACHINE_MASS, "mass")]
StageMass = Annotated[Mass, Field(gt=0), tested_range(MIN_STAGE_MASS, MAX_STAGE_MASS, "mass")]
PositiveTime = Annotated[Time, Field(gt=0)]
NonNegativeTime = Annotated[Time, Field(ge=0)]
StageVelocity = Annotated[
    Velocity, Field(gt=0), tested_range(MIN_STAGE_VELOCITY, MAX_STAGE_VELOCITY, "velocity")
]
StageAcceleration = Annotated[
    Acceleration, Field(gt=0), tested_range(MIN_STAGE_ACCELERATION, MAX_STAGE_ACCELERATION, "acceleration")
]
StageJerk = Annotated[Jerk, Field(gt=0), tested_range(MIN_STAGE_JERK, MAX_STAGE_JERK, "jerk")]
MountFrequency = Annotated[
    Frequency, Field(gt=0), tested_range(MIN_MOUNT_FREQUENCY, MAX_MOUNT_FREQUENCY, "frequency")
]
NonNegativeFrequency = Annotated[Frequency, Field(ge=0)]
NonNegativeStiffness = Annotated[Stiffness, Field(ge=0)]
NonNegativeDamping = Annotated[Damping, Field(ge=0)]
PositiveDensity = Annotated[Density, Field(gt=0)]
PositiveInertia = Annotated[Inertia, Field(gt=0)]
DampingRatio = Annotated[Dimensionless, Field(ge=0), tested_range(0.0, MAX_DAMPING_RATIO, "dimensionless")]
Coordinate = Annotated[
    Length, within(-MAX_COORDINATE, MAX_COORDINATE, "length", "coordinates of a machine on its floor")
]
Position = tuple[Coordinate, Coordinate, Coordinate]
"""A position [x, y, z] in the floor frame, m, each coordinate within :data:`MAX_COORDINATE`."""
FloorDisplacement = Annotated[
    Length,
    within(-MAX_FLOOR_DISPLACEMENT, MAX_FLOOR_DISPLACEMENT, "length", "a floor vibration, not an earthquake"),
]


class InputModel(BaseModel):
    """A block of a scene or study file: unknown keys are refused, aliased keys accepted by either name."""

    model_config = ConfigDict(extra="forbid", populate_by_name=True)
