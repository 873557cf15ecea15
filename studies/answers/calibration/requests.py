"""A calibration as the API receives it: a request body's measurement and fit, errors located under
``body``."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from isolab.studies.answers.calibration.fit import Calibration, PreparedFit, prepare_calibration
from isolab.studies.answers.calibration.measurements import (
    Measurement,
    measurement_from_columns,
    measurement_from_csv,
)
from isolab.studies.inputs.definitions import DefinitionError, Loc, detail


def request_measurement(data: Mapping[str, Any], prefix: Loc | None = None) -> Measurement:
    """The measurement of a request: ``{"csv": text}`` or ``{"time": [...], "time_unit": "s",
    "channels": [{"name", "unit", "values"}]}``."""
    pre: Loc = ["body", "measurement"] if prefix is None else list(prefix)
    if data.get("csv") is not None:
        if data.get("time") is not None or data.get("channels") is not None:
            raise DefinitionError([detail(pre, "give csv, or time and channels, not both")])
        return measurement_from_csv(str(data["csv"]), pre, source="the request's CSV")
    if data.get("time") is None or data.get("channels") is None:
        raise DefinitionError([detail(pre, "give csv (text), or time and channels (columns)")])
    return measurement_from_columns(data["time"], data["channels"], str(data.get("time_unit") or "s"), pre)


def calibrate_request(body: Mapping[str, Any]) -> Calibration:
    """:func:`calibrate` of a request body (``scene``, ``measurement``, ``fit``, and optionally
    ``offset``, ``simulation``, ``highpass``, ``lowpass``, ``noise``, ``starts``), errors located under
    ``body``."""
    return prepare_request(body).run()


def prepare_request(body: Mapping[str, Any]) -> PreparedFit:
    """:func:`prepare_calibration` of a request body (see :func:`calibrate_request`): every check, no
    engine run."""
    meas = request_measurement(dict(body.get("measurement") or {}))
    fit = [{k: v for k, v in dict(f).items() if v is not None} for f in body.get("fit") or []]
    return prepare_calibration(
        dict(body.get("scene") or {}),
        meas,
        fit,
        offset={k: v for k, v in dict(body.get("offset") or {}).items() if v is not None} or None,
        simulation=body.get("simulation"),
        highpass=body.get("highpass"),
        lowpass=body.get("lowpass"),
        noise=body.get("noise"),
        starts=body.get("starts", 1),
    )
