"""Request and response bodies of the REST API (the study definition itself is :class:`studies.study.Study`).

Quantities in responses are SI (m, rad, N, s, Hz); every table says its units. The ``EXAMPLE_*`` dicts are
the examples the OpenAPI page (``/docs``) shows for each request body.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

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
    parameters: list[str] = Field(description="names of the varied parameters")
    isolator_types: list[str]
    fidelity: str | None = Field(
        None,
        description="model fidelity the cases run at (chosen by the runner "
        "for an accuracy request; null until then)",
    )
    integrator: str | None = None
    dt: float | None = Field(None, description="integration step the cases run at, s")
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


class Comparison(BaseModel):
    """A side-by-side table: one row per isolator type; ``best`` names the best type per column."""

    isolator_types: list[str]
    columns: list[str]
    units: dict[str, str]
    rows: dict[str, dict[str, Any]] = Field(description="isolator type -> column -> value")
    best: dict[str, str] = Field(description="column -> isolator type with the best value")
    criteria: dict[str, str] = Field(description="column -> what 'best' means (lowest, highest, false)")
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
                    "simulation": {"fidelity": "lti", "integrator": "exact", "dt": 0.002},
                }
            ]
        }
    )


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
