"""Request and response bodies of the REST API (the study definition itself is
:class:`studies.inputs.study.Study`).

Quantities in responses are SI (m, rad, N, s, Hz); every table says its units. The ``EXAMPLE_*`` dicts are
the examples the OpenAPI page (``/docs``) shows for each request body.
"""

from __future__ import annotations

from typing import Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, StrictBool, StrictFloat, StrictInt

from isolab.studies.answers.calibration.jobs import CalibrationTraces

StudyStatusName = Literal["queued", "running", "done", "failed", "cancelled"]
IsolatorType = Literal["active", "air", "elastomer"]
ISOLATOR_TYPES: tuple[str, ...] = ("active", "air", "elastomer")

# -------------------------------------------------------------------------------------------- examples
EXAMPLE_SCENE: dict[str, Any] = {
    "machine": {"block": {"size": ["2.6 m", "4.2 m", "0.34 m"], "density": "2700 kg/m^3"}},
    "isolators": {"preset": "air", "layout": {"span_x": "2.2 m", "span_y": "3.6 m", "height": "0.5 m"}},
    "stages": [
        {
            "name": "y",
            "mass": "1000 kg",
            "home": ["1.3 m", "0.6 m", "0.47 m"],
            "axis": [0, 1, 0],
            "profile": {"type": "trapezoid", "travel": "3 m", "velocity": "2 m/s", "acceleration": "2 g"},
        }
    ],
    "points": {"tool": ["1.3 m", "0.6 m", "0.6 m"]},
    "simulation": {"fidelity": "lti", "integrator": "exact", "dt": "2 ms", "duration": "3 s"},
}
"""The article's scriber, reduced to its 1,000 kg Y stage: 2 m/s, 2 g over 3 m on a 10 t granite base."""

EXAMPLE_STUDY: dict[str, Any] = {
    "name": "isolator-comparison",
    "description": "Three isolator types x two Y accelerations",
    "scene": EXAMPLE_SCENE,
    "parameters": [
        {"path": "isolators.preset", "values": ["active", "air", "elastomer"]},
        {"path": "stages.y.profile.acceleration", "values": ["1 g", "2 g"]},
    ],
    "design": {"type": "grid"},
}

EXAMPLE_LHS_STUDY: dict[str, Any] = {
    "name": "stiffness-screening",
    "scene": EXAMPLE_SCENE,
    "parameters": [
        {"path": "isolators.f_vertical", "range": {"start": "2 Hz", "stop": "6 Hz"}},
        {"path": "isolators.zeta", "range": {"start": "2 %", "stop": "30 %"}},
    ],
    "design": {"type": "lhs", "samples": 64, "seed": 1},
}

EXAMPLE_COMPARISON: dict[str, Any] = {
    "scene": EXAMPLE_SCENE,
    "isolator_types": ["active", "air", "elastomer"],
    "simulation": {"duration": "4 s"},
}


# ------------------------------------------------------------------------------------------- studies
class StudyLinks(BaseModel):
    self: str = Field(description="this study's status")
    dataset: str = Field(description="the netCDF dataset (once done)")
    cases: str = Field(description="the per-case table (once done)")


class StudyAccepted(BaseModel):
    """Answer to ``POST /studies``: the study is in the catalog and queued."""

    id: str = Field(description="study id, 32 hex digits")
    status: StudyStatusName
    n_cases: int
    links: StudyLinks

    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                {
                    "id": "3f2c9a1b4d5e6f708192a3b4c5d6e7f8",
                    "status": "queued",
                    "n_cases": 6,
                    "links": {
                        "self": "/studies/3f2c9a1b4d5e6f708192a3b4c5d6e7f8",
                        "dataset": "/studies/3f2c9a1b4d5e6f708192a3b4c5d6e7f8/dataset",
                        "cases": "/studies/3f2c9a1b4d5e6f708192a3b4c5d6e7f8/cases",
                    },
                }
            ]
        }
    )


class StudyProgress(BaseModel):
    done: int = Field(description="cases computed so far")
    total: int = Field(description="cases in the study")
    failed: int = Field(0, description="cases computed whose status is not ok")


class StudySummary(BaseModel):
    """A study as the catalog lists it."""

    id: str
    name: str
    status: StudyStatusName
    progress: StudyProgress
    created: str = Field(description="ISO 8601 UTC")
    started: str | None = None
    finished: str | None = None
    error: str | None = Field(None, description="why the study failed")
    note: str | None = Field(
        None,
        description="why a queued or running study has no cases yet, e.g. \"compiling the engine's kernels "
        '(first start only)"; null otherwise',
    )
    failures: str | None = Field(
        None,
        description="how many cases failed (status not ok: unstable, tipping, failed) when any did, and "
        "where to read why; null when none did",
    )
    parameters: list[str] = Field(description="names of the varied parameters")
    isolator_types: list[str]
    fidelity: str | None = Field(
        None,
        description="model fidelity the cases run at (chosen by the runner "
        "for an accuracy request; null until then)",
    )
    integrator: str | None = None
    dt: float | None = Field(None, description="integration step the cases run at, s")
    generation: int | None = Field(
        None, description="optimize designs: generations evaluated so far (null for other designs)"
    )
    generations: int | None = Field(
        None,
        description="optimize designs: generations the budget allows (budget // population; null for the "
        "local searches until done), the generations run once done",
    )
    links: StudyLinks


class StudyDetail(StudySummary):
    """A study with its full definition (as validated: SI numbers, defaults filled in)."""

    definition: dict[str, Any]


class StudyList(BaseModel):
    items: list[StudySummary]
    total: int = Field(description="studies matching the filters")
    limit: int
    offset: int


# -------------------------------------------------------------------------------------------- cases
class CaseTable(BaseModel):
    """One row per case; parameters and outputs flattened to columns (see ``columns`` and ``units``)."""

    study_id: str
    n_cases: int = Field(description="cases in the study")
    n_matched: int = Field(description="cases that pass the filter (rows before limit/offset)")
    offset: int
    limit: int
    columns: list[str]
    units: dict[str, str] = Field(description="column -> SI unit ('1' dimensionless, '' text)")
    long_names: dict[str, str] = Field(default_factory=dict, description="output column -> what it holds")
    rows: list[dict[str, Any]] = Field(description="missing values are null")

    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                {
                    "study_id": "3f2c9a1b4d5e6f708192a3b4c5d6e7f8",
                    "n_cases": 6,
                    "n_matched": 1,
                    "offset": 0,
                    "limit": 100,
                    "columns": [
                        "case",
                        "isolator_type",
                        "stage_y_acceleration",
                        "peak_displacement_y",
                        "liftoff_any",
                    ],
                    "units": {
                        "case": "1",
                        "isolator_type": "",
                        "stage_y_acceleration": "m/s^2",
                        "peak_displacement_y": "m",
                        "liftoff_any": "1",
                    },
                    "rows": [
                        {
                            "case": 2,
                            "isolator_type": "air",
                            "stage_y_acceleration": 9.80665,
                            "peak_displacement_y": 0.0041,
                            "liftoff_any": False,
                        }
                    ],
                }
            ]
        }
    )


class CaseMode(BaseModel):
    """One natural mode of a case: frequency, damping and what moves (kinetic-energy shares)."""

    mode: int
    frequency: float | None = Field(description="undamped natural frequency, Hz")
    damping_ratio: float | None
    energy: dict[str, float | None] = Field(description="DOF (x, y, z, rx, ry, rz) -> kinetic-energy share")
    name: str = Field(description="dominant motion: heave, pitch, roll, yaw, surge, sway (+ a coupled one)")
    shape: dict[str, float | None] | None = Field(
        None, exclude_if=lambda v: v is None, description="x, y, z (m), rx, ry, rz (rad): 1 m at far mount"
    )


PLACES = "isolator -> place (front-left: -X left, -Y front), position (x, y, z in m), label"


class Timeseries(BaseModel):
    """Time histories of one case, recomputed from the study definition."""

    study_id: str
    case: int
    parameters: dict[str, Any] = Field(description="the case's parameter values (SI)")
    status: str
    message: str
    units: dict[str, str]
    time: list[float]
    displacement: dict[str, list[float | None]] = Field(description="c.g. displacement per axis x, y, z")
    rotation: dict[str, list[float | None]] = Field(description="base rotation rx, ry, rz")
    isolator_force: dict[str, dict[str, list[float | None]]] = Field(
        description="isolator -> axis -> dynamic force"
    )
    point_displacement: dict[str, dict[str, list[float | None]]] = Field(
        description="point of interest -> axis -> displacement"
    )
    stages: dict[str, dict[str, list[float | None]]] = Field(
        default_factory=dict,
        description="stage -> position, velocity, acceleration along its axis, on the same time axis",
    )
    isolators: dict[str, dict[str, Any]] = Field(default_factory=dict, description=PLACES)
    modes: list[CaseMode] = Field(default_factory=list, description="natural modes, ascending")
    settling_time: float | None = Field(None, description="s after the last stage move")
    settled: bool | None = None
    last_move_end: float | None = Field(None, description="time the last stage move ends, s")


class SimulationRequest(BaseModel):
    """One scene to run at once."""

    model_config = ConfigDict(extra="forbid")

    scene: dict[str, Any] = Field(description="inline scene (as in a study's scene block)")
    simulation: dict[str, Any] | None = Field(None, description="overrides of the scene's simulation block")
    max_points: int = Field(2000, ge=2, le=20_000, description="most samples per trace in the answer")


class SimulationAnswer(BaseModel):
    """One case's summary (SI, each value with its unit and long name) and its traces, thinned."""

    status: str
    message: str
    model: dict[str, Any] = Field(description="fidelity, integrator, dt (s), duration (s), engine_seconds")
    summary: dict[str, dict[str, Any]] = Field(description="case-table column -> value, unit, long_name")
    isolators: dict[str, dict[str, Any]] = Field(description=PLACES)
    modes: list[CaseMode]
    settling_time: float | None = Field(None, description="s after the last stage move")
    settled: bool | None = None
    last_move_end: float | None = Field(None, description="time the last stage move ends, s")
    n_samples: int = Field(description="samples the case recorded")
    every: int = Field(description="the traces keep every n-th of them")
    max_points: int
    traces: dict[str, Any] = Field(description="units, time, displacement, rotation, isolator_force...")


# --------------------------------------------------------------------------------------- comparisons
class ComparisonRequest(BaseModel):
    """One scene under several isolator types."""

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [EXAMPLE_COMPARISON]})

    scene: dict[str, Any] = Field(description="inline scene (as in a study's scene block)")
    isolator_types: list[IsolatorType] = Field(
        default_factory=lambda: list(ISOLATOR_TYPES),  # type: ignore[arg-type]  # the Literal's values
        min_length=1,
        max_length=3,
        description="isolator presets to compare (default all three)",
    )
    simulation: dict[str, Any] | None = Field(
        None, description="overrides of the scene's simulation block (fidelity, integrator, dt, duration...)"
    )
    cost_order: list[IsolatorType] | None = Field(
        None,
        min_length=1,
        max_length=3,
        description="isolator types from the cheapest to the dearest, for the recommendation "
        "(default elastomer, air, active)",
    )
    tune: StrictBool = Field(
        False,
        description="first tune each type's frequencies and damping, within what the type can reach, to "
        "the scene's criteria (maximising the smallest margin); the answer's tuning gives the values",
    )
    samples: StrictInt = Field(200, ge=1, le=2000, description="with tolerances: machines drawn per type")
    require: StrictFloat = Field(
        0.95, gt=0, le=1, description="with tolerances: P a recommended type reaches"
    )
    seed: StrictInt = Field(0, ge=0, le=2**32 - 1, description="with tolerances: seed of the draws")


class Recommendation(BaseModel):
    """The one isolator type to buy, and why."""

    isolator_type: str | None = Field(
        description="the cheapest type that meets every criterion; with tolerances, the most probable type "
        "that reaches require (null: no criteria, or none meets them)"
    )
    reason: str
    cost_order: list[str] = Field(description="the types from the cheapest to the dearest")
    basis: str | None = Field(None, exclude_if=lambda v: v is None, description="probability: on tolerances")
    require: float | None = Field(None, exclude_if=lambda v: v is None, description="probability required")


class Requirement(BaseModel):
    """One design criterion the types were judged by."""

    name: str = Field(description="e.g. tool_displacement, isolators_no_liftoff")
    limit: float = Field(description="the limit, in SI")
    unit: str
    description: str


class Comparison(BaseModel):
    """A side-by-side table: one row per isolator type; ``best`` names the best type per column."""

    isolator_types: list[str]
    columns: list[str]
    units: dict[str, str]
    rows: dict[str, dict[str, Any]] = Field(description="isolator type -> column -> value")
    best: dict[str, str] = Field(description="column -> isolator type with the best value")
    criteria: dict[str, str] = Field(description="column -> what 'best' means (lowest, highest, false, true)")
    requirements: list[Requirement] = Field(
        default_factory=list,
        description="the scene's design criteria; each row has meets_criteria and margin_<name> "
        "(fraction of the limit to spare, positive: met)",
    )
    recommendation: Recommendation
    tuning: dict[str, dict[str, Any]] | None = Field(
        None, description="with tune: per type, the values found (f_vertical, f_horizontal in Hz, zeta)"
    )
    robustness: dict[str, Any] | None = Field(
        None,
        exclude_if=lambda v: v is None,
        description="with tolerances: per type (types.<type>.nominal, .tuned) the probability of meeting "
        "every criterion, its interval and each criterion's failure probability",
    )
    simulation: dict[str, Any] = Field(description="the simulation block every type ran with")

    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                {
                    "isolator_types": ["active", "air", "elastomer"],
                    "columns": ["peak_displacement_y", "natural_frequency_1"],
                    "units": {"peak_displacement_y": "m", "natural_frequency_1": "Hz"},
                    "rows": {
                        "active": {"peak_displacement_y": 0.012, "natural_frequency_1": 0.84},
                        "air": {"peak_displacement_y": 0.0046, "natural_frequency_1": 2.6},
                        "elastomer": {"peak_displacement_y": 0.0005, "natural_frequency_1": 8.6},
                    },
                    "best": {"peak_displacement_y": "elastomer", "natural_frequency_1": "active"},
                    "criteria": {"peak_displacement_y": "lowest", "natural_frequency_1": "lowest"},
                    "requirements": [
                        {
                            "name": "tool_displacement",
                            "limit": 5e-4,
                            "unit": "m",
                            "description": "peak displacement of tool",
                        }
                    ],
                    "recommendation": {
                        "isolator_type": "air",
                        "reason": "air is the cheapest type (cost order elastomer < air < active) that meets "
                        "every criterion; its smallest margin is +12% on tool_displacement",
                        "cost_order": ["elastomer", "air", "active"],
                    },
                    "simulation": {"fidelity": "lti", "integrator": "exact", "dt": 0.002},
                }
            ]
        }
    )


EXAMPLE_FLOOR_PLOT: dict[str, Any] = {
    **EXAMPLE_COMPARISON,
    "scene": {**EXAMPLE_SCENE, "floor": {"spectrum": {"x": "VC-D", "y": "VC-D", "z": "VC-D"}}},
    "point": "tool",
}
"""The example comparison on a floor at the VC-D level (6.25 um/s RMS per one-third-octave band) along
every axis, drawn at the tool point."""


class FloorPlotRequest(ComparisonRequest):
    """One scene under several isolator types, and the point of interest whose floor-induced velocity
    spectrum to draw (the scene needs a ``floor.spectrum``)."""

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [EXAMPLE_FLOOR_PLOT]})

    point: str = Field(min_length=1, max_length=64, description="the point of interest to draw, e.g. tool")


# -------------------------------------------------------------------------------------------- errors
class ErrorDetail(BaseModel):
    loc: list[str | int] = Field(
        description="path of the offending input, e.g. ['body', 'design', 'samples']"
    )
    msg: str
    type: str


class ValidationErrorBody(BaseModel):
    detail: list[ErrorDetail]


class MessageBody(BaseModel):
    detail: str


# -------------------------------------------------------------------------- authoring (the web page)
class ExampleList(BaseModel):
    names: list[str] = Field(description="example studies shipped with isolab (GET /examples/{name})")


class ExampleStudy(BaseModel):
    """An example study as YAML text, its scene inlined (comments kept)."""

    name: str
    text: str = Field(description="YAML text, ready to edit and check (POST /studies/validate)")


EXAMPLE_STUDY_TEXT: str = yaml.safe_dump(EXAMPLE_STUDY, sort_keys=False)
"""The grid example study as YAML text (the body of ``POST /studies/validate``)."""


class StudyText(BaseModel):
    """A study definition as YAML (or JSON) text, its scene inline."""

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{"text": EXAMPLE_STUDY_TEXT}]})

    text: str = Field(
        min_length=1, max_length=1_000_000, description="YAML or JSON text of a study definition"
    )


class StudyCheck(BaseModel):
    """A study checked as a submission would be, nothing stored: submit ``definition`` to POST /studies."""

    definition: dict[str, Any] = Field(description="the text as data (JSON)")
    name: str
    n_cases: int
    parameters: list[str] = Field(description="names of the varied parameters")
    estimated_seconds: float = Field(description="rough run time on this service's workers, s")


class LineErrorDetail(ErrorDetail):
    line: int | None = Field(None, description="1-based line of the text the problem points at")


class TextValidationErrorBody(BaseModel):
    detail: list[LineErrorDetail]


class ParameterDesign(BaseModel):
    name: str = Field(description="column of the case table")
    path: str
    unit: str = Field(description="SI unit of the column")
    categorical: bool
    values: list[Any] | None = Field(None, description="values as written")
    range: dict[str, Any] | None = Field(None, description="range as written (start, stop, num, scale)")
    scale: str = Field(description="linear or log")
    display_unit: str = Field(description="the unit the author wrote the values in")
    display_scale: float = Field(description="SI value of one display unit")
    index: int


class StudyDesign(BaseModel):
    """A stored study's design in the units its author wrote."""

    name: str
    description: str
    design: dict[str, Any]
    n_cases: int
    parameters: list[ParameterDesign]


class ErrorEstimateOutput(BaseModel):
    value: float | None = Field(description="largest error over the sampled cases (null: none compared)")
    units: str
    meaning: str
    worst_case: int | None


class ErrorEstimate(BaseModel):
    """The measured error of a done study and the model it ran with."""

    fidelity: str | None
    integrator: str | None
    dt: float | None = Field(description="s")
    method: str | None
    cases: list[int] = Field(description="the sampled cases")
    excluded: dict[str, str] = Field(description="case -> why it could not be compared")
    outputs: dict[str, ErrorEstimateOutput]


# -------------------------------------------------------------------------------------- calibrations
EXAMPLE_CALIBRATION: dict[str, Any] = {
    "scene": EXAMPLE_SCENE,
    "measurement": {
        "time": [round(0.05 * i, 2) for i in range(49)],
        "time_unit": "s",
        "channels": [
            {
                "name": "cg.y.displacement",
                "unit": "mm",
                "values": [
                    *(0.0, 0.0, 0.0, -1.881, -5.316, -5.229, -0.652, 3.576, 4.145, 1.413, -1.797, -2.779),
                    *(-1.022, 1.626, 2.795, 1.746, -0.212, -1.211, -0.547, 0.944, 1.899, 1.652, 0.654, -0.1),
                    *(0.014, 0.786, 1.486, 1.568, 1.103, 0.611, 0.545, 0.917, 1.371, 3.425, 6.689, 6.323),
                    *(1.645, -2.418, -2.71, 0.193, 3.374, 4.22, 2.385, -0.194, -1.198, -0.011, 1.98, 2.93),
                    2.224,
                ],
            }
        ],
    },
    "fit": [{"path": "isolators.f_horizontal", "lower": "1 Hz", "upper": "6 Hz"}],
    "plot": False,
}
"""The scene of :data:`EXAMPLE_SCENE` measured in Y at 20 Hz by a laser tracker whose record starts 0.1 s
before the stage: the mounts are 3.6 Hz sideways, not the air preset's 3 Hz."""


class FitParameterIn(BaseModel):
    """A parameter to fit: a study parameter path and its bounds (numbers in SI or text with units)."""

    model_config = ConfigDict(extra="forbid", strict=True)

    path: str = Field(max_length=200, description="e.g. isolators.f_vertical, isolators.zeta, stages.y.mass")
    lower: float | str
    upper: float | str
    start: float | str | None = Field(None, description="default: the scene's value, inside the bounds")


class ChannelIn(BaseModel):
    """One measured channel: ``LOCATION.AXIS.QUANTITY`` (cg or a point; x, y, z, rx, ry, rz;
    displacement, velocity or acceleration), its unit and its samples."""

    model_config = ConfigDict(extra="forbid", strict=True)

    name: str = Field(max_length=200, description="e.g. cg.z.displacement, tool.y.acceleration")
    unit: str = Field("", max_length=64, description="e.g. mm, um, m/s, g, mrad (default SI)")
    values: list[float]


class MeasurementIn(BaseModel):
    """A measurement: CSV text (a header ``time [s], cg.z.displacement [mm], ...`` then rows), or columns."""

    model_config = ConfigDict(extra="forbid", strict=True)

    csv: str | None = Field(None, description="CSV text with a header naming each column")
    time: list[float] | None = Field(None, description="sample times (columns form)")
    time_unit: str = Field("s", max_length=32)
    channels: list[ChannelIn] | None = Field(None, max_length=16)


class OffsetIn(BaseModel):
    """The time offset (when the motion starts on the measurement's clock): bounds and start, or a value
    to hold fixed. Default bounds: +- a quarter of the measurement's span."""

    model_config = ConfigDict(extra="forbid", strict=True)

    lower: float | str | None = None
    upper: float | str | None = None
    start: float | str | None = None
    value: float | str | None = Field(None, description="hold the offset at this value instead of fitting it")


class CalibrationRequest(BaseModel):
    """A scene, a measurement of its motion and the parameters to fit."""

    model_config = ConfigDict(
        extra="forbid", strict=True, json_schema_extra={"examples": [EXAMPLE_CALIBRATION]}
    )

    scene: dict[str, Any] = Field(description="inline scene (as in a study's scene block)")
    measurement: MeasurementIn
    fit: list[FitParameterIn] = Field(min_length=1, max_length=8)
    offset: OffsetIn | None = None
    simulation: dict[str, Any] | None = Field(
        None,
        description="fidelity, integrator, dt, auto_step overriding the scene's (keep it cheap: lti/ltv)",
    )
    highpass: float | str | None = Field(
        None, description="high-pass corner of acceleration channels, Hz (default 0.5 Hz; 0: off)"
    )
    lowpass: float | str | None = Field(
        None, description="low-pass corner of acceleration channels, Hz (default min(fs/5, 0.03/dt); 0: off)"
    )
    plot: StrictBool = Field(
        True, description="answer a PNG of measured against simulated traces in plot_png"
    )
    noise: dict[str, float | str] | None = Field(None, max_length=16, description="channel -> sensor noise")
    starts: int = Field(1, ge=1, le=16, description="fits from the scene's values and Sobol' points")


class FittedParameter(BaseModel):
    path: str
    name: str
    unit: str = Field(description="SI unit of lower, upper, start, value and sigma")
    lower: float
    upper: float
    start: float
    value: float | None = Field(description="fitted value; null when the measurement does not determine it")
    sigma: float | None = Field(description="1-sigma uncertainty, from s^2 (J^T J)^-1")
    determined: bool
    reason: str | None = Field(None, description="why it is not determined")


class Calibration(BaseModel):
    """Fitted values with 1-sigma uncertainties, the misfit before and after per channel (SI), the
    identifiability figures of the Jacobian and the calibrated scene."""

    parameters: list[FittedParameter]
    time_offset: FittedParameter
    channels: list[dict[str, Any]] = Field(
        description="per channel: rms_measured, rms_before, rms_after (SI)"
    )
    identifiability: dict[str, Any] = Field(
        description="singular values and condition number of the column-normalised Jacobian, correlations"
    )
    residual_variance: float = Field(description="chi-square against the sensor noise per degree of freedom")
    degrees_of_freedom: float
    goodness_of_fit: dict[str, Any] = Field(default_factory=dict, description="chi-square test and verdict")
    starts: dict[str, Any] = Field(default_factory=dict, description="where each start began and ended")
    scene: dict[str, Any] = Field(description="the calibrated scene (SI)")
    scene_yaml: str = Field(description="the calibrated scene as YAML, ready for a study")
    simulation: dict[str, Any]
    highpass: float
    lowpass: float
    evaluations: dict[str, Any]
    message: str
    plot_png: str | None = Field(None, description="base64 PNG of measured against simulated traces")
    traces: CalibrationTraces | None = Field(None, description="measured against simulated, decimated")


class CalibrationCost(BaseModel):
    """The estimated engine work of a calibration (rough: a factor of two either way)."""

    seconds: float = Field(description="engine time on one core, s")
    engine_calls: int = Field(description="engine batches the fit is expected to run")
    cases: int = Field(description="cases over all batches")
    steps_per_case: int = Field(description="engine steps of one case")
    limit_seconds: float = Field(description="the largest estimate accepted, s")


class CalibrationProgress(BaseModel):
    engine_calls: int = Field(description="engine batches run so far")
    cases: int = Field(description="cases run so far")
    fraction: float = Field(description="cases run over the estimate's, at most 0.99 until done (1)")


class CalibrationJob(BaseModel):
    """A calibration job: where it is, its cost estimate and progress, and its answer once done."""

    id: str = Field(description="32 hex digits")
    status: Literal["queued", "running", "done", "failed"]
    created: str
    started: str | None = None
    finished: str | None = None
    estimate: CalibrationCost
    progress: CalibrationProgress
    error: str | None = Field(None, description="why a failed calibration failed")
    result: Calibration | None = Field(None, description="the answer, once done")
