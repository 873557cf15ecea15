"""``POST /calibrations``: fit a scene's parameters to measured motion.

The calibration itself is :mod:`isolab.studies.answers.calibration` (a few dozen small engine batches, run in
a
worker thread of the API process); the figure is :mod:`isolab.service.plots.calibration`, answered as
base64 PNG in ``plot_png`` when the request asks for it (the default).
"""

from __future__ import annotations

import base64

from fastapi import APIRouter, Body, Request

from isolab.service.api.routes import INVALID, run_heavy
from isolab.service.api.schemas import EXAMPLE_CALIBRATION, Calibration, CalibrationRequest
from isolab.service.plots.calibration import calibration_notes, calibration_png
from isolab.studies.answers.calibration import calibrate_request

router = APIRouter(prefix="/calibrations", tags=["calibrations"])


@router.post(
    "", response_model=Calibration, responses=INVALID, summary="Calibrate a scene against measured motion"
)
async def calibrate(
    http: Request,
    request: CalibrationRequest = Body(
        openapi_examples={
            "laser tracker": {
                "summary": "the mounts' horizontal frequency from a Y trace of the c.g. at 20 Hz",
                "value": EXAMPLE_CALIBRATION,
            },
        }
    ),
) -> Calibration:
    """Fit the parameters named in ``fit`` (and the measurement's time offset) so that the scene's
    simulated motion matches the measured channels; answer the fitted values with 1-sigma uncertainties
    (or "not determined by this measurement"), the misfit per channel before and after, and the
    calibrated scene as YAML. Acceleration channels are fitted in acceleration, measured and simulated
    alike detrended and band-passed (``highpass``, ``lowpass``)."""
    result = await run_heavy(http, calibrate_request, request.model_dump(exclude_none=True))
    answer = result.to_json()
    if request.plot:
        png = await run_heavy(http, calibration_png, result.traces, "calibration", calibration_notes(answer))
        answer["plot_png"] = base64.b64encode(png).decode("ascii")
    return Calibration(**answer)
