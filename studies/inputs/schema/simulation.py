"""How a scene is simulated: model fidelity, integrator and step or an accuracy request (a level, or a
tolerance overall or per output), duration and settling tolerance; and how tolerances are read."""

from __future__ import annotations

from typing import Annotated, Any, Literal

import numpy as np
from pydantic import Field, field_validator, model_validator

from isolab.engine.results import OUTPUTS
from isolab.studies.inputs.schema.fields import InputModel, PositiveLength, tested_range
from isolab.studies.units import Time, dimension_of, to_si

AUTO_DURATION_MARGIN = 3.0
"""``duration: auto`` simulates at least this long after the last stage move ends, s."""
AUTO_DURATION_DECAYS = 9.2
"""...and at least this many time constants ``1 / (zeta w)`` of the slowest-decaying mode: long enough for
its amplitude to fall by 10^4 (ln 10^4 = 9.2), so a settling time is measured, not cut off."""
AUTO_DURATION_CAP = 60.0
"""Longest ``duration: auto``, s."""

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


TOLERANCE_OUTPUTS: dict[str, str] = {
    name: dimension_of(OUTPUTS[name].unit) or "dimensionless"
    for name in (
        "peak_displacement",
        "peak_point_displacement",
        "peak_rotation",
        "peak_isolator_force",
        "peak_isolator_deflection",
        "min_isolator_load",
        "max_isolator_load",
        "settling_time",
    )
}
"""Outputs a per-output tolerance may name, and the dimension of an absolute tolerance on each (that of
the output's unit in the catalogue, :data:`isolab.engine.results.OUTPUTS`)."""


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


class Simulation(InputModel):
    """How to simulate: model fidelity, integrator and step, or an accuracy request; duration and settling
    tolerance.

    Give either ``fidelity``/``integrator`` (defaults ltv and rk4, step ``dt`` default 1 ms) or an accuracy
    request: ``accuracy`` (fast ~5 %, balanced ~0.5 %, reference) or ``tolerance`` (``"10 um"`` of peak
    displacement, or a relative error ``"1 %"``). An accuracy request lets the study runner pick the
    cheapest fidelity, integrator and step whose error, measured on pilot cases of the study against the
    nonlinear reference, stays inside it (:mod:`studies.run.accuracy`); ``dt`` then caps the step it may pick
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
    dt: Annotated[Time, Field(gt=0), tested_range(MIN_DT, MAX_DT, "time")] | None = Field(
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
    preload: Literal["floor", "base", "balanced"] = Field(
        "floor",
        description="nonlinear level: the mounts' preload stays vertical (floor) or turns with the base "
        "(base: mounts that tilt with it, no rocking stiffness -W h from the preload), or balances the "
        "weights with the stages at home in every attitude (balanced: no rocking stiffness from preload "
        "and weights, only the stages' travel tilts the base)",
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
                    f"simulation.preload: {self.preload!r} is a choice of the nonlinear level; an accuracy "
                    "request picks the level itself (name fidelity: nonlinear)"
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
                f"simulation.preload: {self.preload!r} (a convention of the preload at finite rotations) is "
                f"a choice of the nonlinear level, got fidelity {self.fidelity!r}"
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
