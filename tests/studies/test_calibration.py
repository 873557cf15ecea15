"""Calibration against measured motion (:mod:`isolab.studies.answers.calibration`).

A measurement is synthesised from a known scene (the article's scriber cut to under 3 s, with
isolators different from the scene it calibrates), with sensor noise, an unknown time offset, a sample
rate other than the engine's step and an accelerometer that drifts; the fit must recover the true
isolators within the uncertainty it states. A parameter nothing in the measurement responds to must come
back as not determined, not as a number.
"""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
import yaml

from isolab.studies.answers.calibration import (
    FitSpec,
    calibrate,
    measurement_csv,
    measurement_from_columns,
    measurement_from_csv,
    parse_fit,
    read_measurement,
    synthetic_measurement,
)
from isolab.studies.inputs.definitions import DefinitionError
from isolab.studies.inputs.study import load_scene

EXAMPLES = Path(__file__).resolve().parents[2] / "studies" / "examples"
G = 9.80665
SIM = {"fidelity": "ltv", "integrator": "rk4", "dt": "1 ms", "duration": "3 s"}
TRUE = {"isolators.f_vertical": 3.5, "isolators.f_horizontal": 5.0, "isolators.zeta": 0.14}
OFFSET = 0.137  # s: the recorder started this long before the stages moved


def scriber(f_vertical: str, f_horizontal: str, zeta: float) -> dict:
    scene = yaml.safe_load((EXAMPLES / "article-scriber.yaml").read_text())
    scene["isolators"]["tuning"]["air"] = {
        "f_vertical": f_vertical,
        "f_horizontal": f_horizontal,
        "zeta": zeta,
    }
    scene["simulation"] = dict(SIM)
    return scene


TRUTH = scriber("3.5 Hz", "5 Hz", 0.14)
NOMINAL = scriber("3 Hz", "4 Hz", 0.10)  # the preset-like guess the user starts from


@pytest.fixture(scope="module")
def measured():
    """cg.z by a laser tracker (mm) and tool.y by an accelerometer (g, biased and drifting), at 400 Hz
    for 2.8 s, 3 % noise; the motion starts 137 ms into the record."""
    return synthetic_measurement(
        TRUTH,
        [("cg.z.displacement", "mm"), ("tool.y.acceleration", "g")],
        np.arange(0.0, 2.8, 1 / 400),
        offset=OFFSET,
        noise=0.03,
        bias=0.05,
        drift=0.02,
        seed=7,
    )


@pytest.fixture(scope="module")
def fitted(measured):
    fit = [
        FitSpec("isolators.f_vertical", "1 Hz", "6 Hz"),
        FitSpec("isolators.f_horizontal", "1 Hz", "8 Hz"),
        FitSpec("isolators.zeta", 0.01, 0.5),
    ]
    return calibrate(NOMINAL, measured, fit)


def test_recovers_the_true_isolators_within_the_stated_uncertainty(fitted):
    for p in fitted.parameters:
        assert p.determined, p.reason
        assert p.value is not None and p.sigma is not None
        true = TRUE[p.path]
        assert abs(p.value - true) < 3 * p.sigma, (p.path, p.value, p.sigma)
        assert p.sigma < 0.01 * true, (p.path, p.sigma)  # and the measurement pins it well
        assert p.start != pytest.approx(true, rel=0.1)  # it had to move: the fit did the work
    off = fitted.time_offset
    assert off.determined and off.value is not None and off.sigma is not None
    assert abs(off.value - OFFSET) < 3 * off.sigma
    assert off.sigma < 1e-3  # a fraction of the 2.5 ms sample interval


def test_misfit_falls_to_the_noise(fitted, measured):
    assert fitted.residual_variance == pytest.approx(1.0, abs=0.1)  # residuals are the noise
    for ch, m in zip(fitted.channels, measured.channels, strict=True):
        assert ch["rms_after"] < 0.2 * ch["rms_before"], ch
        if ch["quantity"] == "displacement":  # 3 % noise of the signal's RMS, nothing else left
            assert ch["rms_after"] == pytest.approx(0.03 * np.sqrt(np.mean(m.values**2)), rel=0.15)


def test_calibrated_scene_carries_the_fitted_isolators(fitted):
    scene = load_scene(fitted.scene_yaml)
    for p in fitted.parameters:
        key = p.path.split(".")[-1]
        assert getattr(scene.isolators, key) == pytest.approx(p.value)
    assert "+-" in fitted.scene_yaml.splitlines()[1]  # the header says what was fitted, with sigma


def test_jacobian_columns_come_from_one_engine_batch(fitted):
    ev = fitted.evaluations
    # every engine call is either the base case or the base plus one case per fitted parameter
    assert ev["engine_calls"] <= ev["nfev"] + ev["njev"] + 3
    assert ev["cases"] >= ev["njev"] * 4  # base + 3 perturbed parameters per Jacobian


def test_a_parameter_the_measurement_does_not_see_is_reported_undetermined():
    """The scriber's Y stage alone, over the base's c.g. in X: nothing moves the base along X or about
    Y or Z, so the mounts' X stiffness leaves the measured heave untouched."""
    scene = scriber("3.5 Hz", "5 Hz", 0.14)
    scene["stages"] = scene["stages"][:1]
    scene["points"] = {}
    meas = synthetic_measurement(
        scene, [("cg.z.displacement", "um")], np.arange(0.0, 2.0, 1 / 500), offset=0.05, noise=0.02, seed=3
    )
    out = calibrate(
        scene,
        meas,
        [FitSpec("isolators.f_vertical", 1, 6, start=3.0), FitSpec("isolators.k.x", "1e5 N/m", "1e7 N/m")],
    )
    fv, kx = out.parameters
    assert fv.determined and fv.value is not None and fv.sigma is not None
    assert abs(fv.value - 3.5) < 3 * fv.sigma
    assert not kx.determined and kx.value is None and kx.sigma is None
    assert "not determined by this measurement" in kx.reason
    assert "k:\n" not in out.scene_yaml.split("isolators:")[1].split("stages:")[0]  # left as it was


@pytest.mark.slow  # about 10 s: the fit wanders along the valley before it gives up
def test_collinear_parameters_are_reported_undetermined():
    """Base density and stage mass: a vertical measurement sees the ratio of stage to base mass only
    (with preset mounts tuned to the load, the frequencies do not move), so neither is determined."""
    scene = scriber("3.5 Hz", "5 Hz", 0.14)
    scene["stages"] = scene["stages"][:1]
    scene["points"] = {}
    meas = synthetic_measurement(
        scene, [("cg.z.displacement", "um")], np.arange(0.0, 1.5, 1 / 250), noise=0.02, seed=4
    )
    out = calibrate(
        scene,
        meas,
        [FitSpec("machine.block.density", 2000, 3400), FitSpec("stages.y.mass", 700, 1300)],
        offset={"value": 0.0},
    )
    for p in out.parameters:
        assert not p.determined, (p.path, p.value, p.sigma)
        assert "not determined" in p.reason


# ------------------------------------------------------------------------------------------- input
def test_csv_round_trip_and_units(measured):
    text = measurement_csv(measured)
    assert text.splitlines()[0] == "time [s],cg.z.displacement [mm],tool.y.acceleration [g]"
    back = measurement_from_csv(text)
    for a, b in zip(measured.channels, back.channels, strict=True):
        assert b.name == a.name and b.unit == a.unit
        np.testing.assert_allclose(b.values, a.values, rtol=1e-8, atol=1e-12)
    # 1 g is standard gravity; mm is 1e-3 m
    one = measurement_from_csv(
        "time (ms), tool.y.acc (g), cg.rx.velocity [mrad/s]\n" + "\n".join(f"{i}, 1, 2" for i in range(20))
    )
    assert one.time[1] == pytest.approx(1e-3)
    assert one.channels[0].values[0] == pytest.approx(G)
    assert one.channels[0].quantity == "acceleration"
    assert one.channels[1].values[0] == pytest.approx(2e-3) and one.channels[1].si_unit == "rad/s"


def test_netcdf_measurement(measured, tmp_path):
    import xarray as xr

    ds = xr.Dataset(
        {c.name: ("time", c.values / c.factor, {"units": c.unit}) for c in measured.channels},
        coords={"time": ("time", measured.time * 1e3, {"units": "ms"})},
    )
    ds.to_netcdf(tmp_path / "m.nc")
    back = read_measurement(tmp_path / "m.nc")
    np.testing.assert_allclose(back.time, measured.time)
    np.testing.assert_allclose(back.channels[1].values, measured.channels[1].values)


@pytest.mark.parametrize(
    ("columns", "where", "words"),
    [
        ({"name": "cg.q.displacement", "unit": "mm"}, ["channels", 0, "name"], "axis"),
        ({"name": "cg.z.jerk", "unit": "mm"}, ["channels", 0, "name"], "quantity"),
        ({"name": "cg.z.displacement", "unit": "kg"}, ["channels", 0, "name"], "unit"),
        ({"name": "cg.z", "unit": "mm"}, ["channels", 0, "name"], "LOCATION.AXIS.QUANTITY"),
    ],
)
def test_bad_channels_name_the_field(columns, where, words):
    with pytest.raises(DefinitionError) as err:
        measurement_from_columns(list(range(20)), [{**columns, "values": [0.0] * 20}])
    d = err.value.details[0]
    assert d["loc"] == ["body", "measurement", *where]
    assert words in d["msg"]


def test_bad_fit_requests_name_the_field(measured):
    cases = [
        ([FitSpec("isolators.f_sideways", 1, 6)], ["body", "fit", 0, "path"]),
        ([FitSpec("isolators.f_vertical", 6, 1)], ["body", "fit", 0, "upper"]),
        ([FitSpec("isolators.f_vertical", "1 kg", 6)], ["body", "fit", 0, "lower"]),
        ([FitSpec("isolators.preset", 1, 6)], ["body", "fit", 0, "path"]),
        ([], ["body", "fit"]),
    ]
    for fit, loc in cases:
        with pytest.raises(DefinitionError) as err:
            calibrate(NOMINAL, measured, fit)
        assert err.value.details[0]["loc"] == loc, (fit, err.value.details)


def test_a_channel_at_a_point_the_scene_lacks(measured):
    m = copy.deepcopy(measured)
    m.channels[1].location = "laser"
    with pytest.raises(DefinitionError) as err:
        calibrate(NOMINAL, m, [FitSpec("isolators.zeta", 0.01, 0.5)])
    assert err.value.details[0]["loc"] == ["body", "measurement", "channels", 1]
    assert "laser" in err.value.details[0]["msg"]


def test_parse_fit():
    assert parse_fit("isolators.f_vertical=1:6") == FitSpec("isolators.f_vertical", "1", "6", None)
    assert parse_fit("stages.y.mass = 800 kg : 1.2 t @ 1000 kg") == FitSpec(
        "stages.y.mass", "800 kg", "1.2 t", "1000 kg"
    )
    with pytest.raises(ValueError, match="PATH=LOWER:UPPER"):
        parse_fit("isolators.zeta")
