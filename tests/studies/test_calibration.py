"""Calibration against measured motion (:mod:`isolab.studies.answers.calibration`).

A measurement is synthesised from a known scene (the article's scriber cut to under 3 s, with
isolators different from the scene it calibrates), with sensor noise, an unknown time offset, a sample
rate other than the engine's step and an accelerometer that drifts; the fit must recover the true
isolators within the uncertainty it states. A parameter nothing in the measurement responds to must come
back as not determined, not as a number.
"""

from __future__ import annotations

import copy
import functools
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
from isolab.studies.answers.calibration.measurements import Measurement
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
    # the chi-square against each channel's noise (estimated from the record alone): the residuals are it
    gof = fitted.goodness_of_fit
    assert fitted.residual_variance == gof["reduced_chi_square"] == pytest.approx(1.0, abs=0.2)
    assert "larger than" not in gof["verdict"], gof["verdict"]
    disp = fitted.channels[0]  # the tracker's 3 % noise, found without the model
    assert disp["noise"] == pytest.approx(0.03 * np.sqrt(np.mean(measured.channels[0].values ** 2)), rel=0.1)
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


# ------------------------------------------------------------------------------------ honest answers
def heldout_record(seed: int) -> object:
    """What a finer machine records: the truth simulated at 0.25 ms (the fit runs at 1 ms), the
    accelerometer band-limited (2nd-order Butterworth at 100 Hz, zero phase), 3 % noise on both channels
    and a 0.05 m/s^2 bias on the accelerometer."""
    from scipy.signal import butter, sosfiltfilt

    m = copy.deepcopy(fine_record())
    rng = np.random.default_rng(seed)
    d, a = m.channels
    d.values = d.values + 0.03 * np.sqrt(np.mean(d.values**2)) * rng.standard_normal(d.values.size)
    band = sosfiltfilt(butter(2, 100.0, fs=400.0, output="sos"), a.values)
    a.values = band + 0.03 * np.sqrt(np.mean(band**2)) * rng.standard_normal(band.size) + 0.05
    return m


@functools.cache
def fine_record() -> Measurement:
    """The truth simulated at 0.25 ms (not the fit's 1 ms), sampled at 400 Hz: made once, on first use (not
    while the suite is collected, in every test process)."""
    return synthetic_measurement(
        TRUTH,
        [("cg.z.displacement", "mm"), ("tool.y.acceleration", "g")],
        np.arange(0.0, 2.8, 1 / 400),
        offset=OFFSET,
        simulation={"dt": "0.25 ms"},
    )


THREE = [
    FitSpec("isolators.f_vertical", "1 Hz", "6 Hz"),
    FitSpec("isolators.f_horizontal", "1 Hz", "8 Hz"),
    FitSpec("isolators.zeta", 0.01, 0.5),
]


@pytest.mark.parametrize("seed", [1, 2, 5])
def test_a_finer_record_with_a_band_limited_accelerometer_keeps_every_error_within_three_sigma(seed):
    """Displacement plus acceleration from a record the fit's model did not make: every (fitted - true) /
    sigma within +-3 (before the noise was stated per channel, the offset came out 3.5 sigma off)."""
    out = calibrate(NOMINAL, heldout_record(seed), THREE)
    truth = {**TRUE, "time_offset": OFFSET}
    for p in [*out.parameters, out.time_offset]:
        assert p.value is not None and p.sigma is not None, p.reason
        assert abs(p.value - truth[p.path]) < 3 * p.sigma, (p.path, p.value, p.sigma)
    assert out.goodness_of_fit["dof"] > 1000


def test_a_misfit_the_noise_does_not_explain_is_flagged_and_widens_the_sigmas(measured):
    """A stated noise ten times smaller than the record's: the chi-square is far above its range, the
    verdict says so, and the sigmas grow with the misfit instead of shrinking with the stated noise."""
    honest = calibrate(NOMINAL, measured, THREE)
    tiny = {
        c.name: f"{0.003 * np.sqrt(np.mean(c.values**2)) / c.factor:.6g} {c.unit}" for c in measured.channels
    }
    out = calibrate(NOMINAL, measured, THREE, noise=tiny)
    gof = out.goodness_of_fit
    assert gof["reduced_chi_square"] > 50 and gof["reduced_chi_square"] > gof["expected_range"][1]
    assert "larger than the stated sensor noise explains" in gof["verdict"]
    assert all(c["noise_source"] == "stated" for c in out.channels)
    for a, b in zip(out.parameters, honest.parameters, strict=True):
        assert a.sigma is not None and b.sigma is not None
        assert a.sigma > 0.5 * b.sigma, (a.path, a.sigma, b.sigma)  # not ten times smaller


def test_correlated_residuals_widen_the_uncertainty():
    from isolab.studies.answers.calibration.uncertainty import correlation_length

    rng = np.random.default_rng(0)
    white = rng.standard_normal(4000)
    smooth = np.convolve(white, np.ones(20) / 20, mode="same")
    assert correlation_length(white) == pytest.approx(1.0, abs=0.2)
    assert correlation_length(smooth) > 10  # twenty samples averaged: about twenty count as one


def test_the_zero_column_verdict_does_not_depend_on_units():
    """One parameter with a tiny column in its own units, but a strong one over its bounds' width."""
    from isolab.studies.answers.calibration.uncertainty import parameter_verdict

    rng = np.random.default_rng(1)
    J = rng.standard_normal((200, 2))
    x = np.array([1.0, 1e12])
    for scale in (1.0, 1e-12):
        Jx = J * np.array([1.0, scale])
        width = np.array([1.0, 1.0 / scale])
        _, reasons, _ = parameter_verdict(
            Jx, width, x * np.array([1.0, 1.0 / scale]) / 1e12 * 1e12, ["a", "b"]
        )
        assert "do not respond" not in reasons[1], (scale, reasons)


def test_the_fit_starts_at_the_scene_and_more_starts_agree(measured, fitted):
    """Four starts: the scene's values (its tuning, not the bounds' midpoints) and three Sobol' points;
    one of those ends in a far worse minimum at a bound, and the best kept is the scene's own."""
    out = calibrate(NOMINAL, measured, THREE, starts=4)
    assert [p.start for p in out.parameters] == pytest.approx([3.0, 4.0, 0.10])
    st = out.starts
    assert st["count"] == 4 and st["start"]["isolators.f_vertical"][0] == pytest.approx(3.0)
    assert len(set(st["start"]["isolators.f_vertical"])) == 4  # Sobol' points, all different
    assert st["chi_square"][st["best"]] == min(st["chi_square"]) and st["agreeing"] >= 3
    assert max(st["chi_square"]) > 10 * min(st["chi_square"])  # a start that went elsewhere, reported
    for a, b in zip(out.parameters, fitted.parameters, strict=True):
        assert a.value == pytest.approx(b.value, rel=1e-6)  # the same answer as one start


def test_the_scene_start_of_a_stiffness_is_the_mounts_own():
    from isolab.studies.answers.calibration.parameters import fit_parameters
    from isolab.studies.inputs.scenes import build_batch
    from isolab.studies.inputs.study import validate_scene

    sc = validate_scene(NOMINAL)
    (kx,) = fit_parameters(sc, [FitSpec("isolators.k.x", 1e5, 1e7)], ["body"])
    assert kx.start == pytest.approx(float(build_batch([sc]).iso_k[0, :, 0].mean()))
    assert kx.start != pytest.approx(0.5 * (1e5 + 1e7))


def test_calibrated_yaml_keeps_units_and_comments_and_drops_stale_tuning(fitted):
    from isolab.studies.answers.calibration.scene_text import calibrated_text
    from isolab.studies.inputs.parameters import resolve

    text = (EXAMPLES / "article-scriber.yaml").read_text()
    sc = load_scene(text)
    values = [(resolve(p.path, sc), p.value) for p in fitted.parameters]
    out = calibrated_text(text, ["# calibrated"], values)
    assert out.startswith("# calibrated\n# The laser scriber of the source article")
    assert "density: 2700 kg/m^3" in out and "# the base's c.g. sits 0.5 m above the mounts" in out
    assert "tuning" not in out  # the fitted group figures override every type's tuning
    scene = load_scene(out)
    for p in fitted.parameters:
        assert getattr(scene.isolators, p.path.split(".")[-1]) == pytest.approx(p.value, rel=1e-7)
    assert f"f_vertical: {fitted.parameters[0].value:.8g} Hz" in out  # in the scene's unit


def test_csv_errors_name_the_line_a_text_editor_shows_and_the_column():
    rows = "\n".join(f"{i * 0.01}, {i}" for i in range(20))
    head = "# a comment\ntime [s], cg.z.displacement [mm]\n"
    cases = [
        (head + rows + "\n0.3, abc\n", "line 23, column 'cg.z.displacement [mm]': 'abc' is not a number"),
        (head + "\n" + rows + "\n0.3\n", "line 24 has 1 value, but the header (line 2) names 2 columns"),
        (head + rows + "\n0.3, nan\n", "line 23, column 'cg.z.displacement [mm]': 'nan' is not a finite"),
        (head + rows + "\n0.1, 3\n", "line 23, column 'time [s]': times must increase, and 0.1 does not"),
    ]
    for text, words in cases:
        with pytest.raises(DefinitionError) as err:
            measurement_from_csv(text)
        msg = err.value.details[0]["msg"]
        assert words in msg and "usecols" not in msg, msg


@pytest.mark.parametrize(
    ("simulation", "words"),
    [
        ({"dt": "0 s"}, "must be a positive step"),
        ({"dt": "0.2 s"}, "longer than the measurement's sample interval"),
        ({"dt": "9 ms"}, "too coarse for the scene's fastest mode (6.07 Hz)"),
        ({"auto_step": "yes"}, "must be true or false"),
    ],
)
def test_simulation_choices_the_fit_cannot_use_are_refused(simulation, words):
    """A 100 Hz record: a step may not exceed its 10 ms, nor a twentieth of the fastest mode's period."""
    coarse = measurement_from_columns(
        np.arange(0.0, 1.0, 0.01), [{"name": "cg.z.displacement", "values": np.sin(np.arange(100.0))}]
    )
    with pytest.raises(DefinitionError) as err:
        calibrate(NOMINAL, coarse, THREE[:1], simulation=simulation)
    (d,) = err.value.details
    assert d["loc"] == ["body", "simulation", next(iter(simulation))] and words in d["msg"], d


def test_the_offset_scan_filters_its_predictions_side_by_side_as_each_alone(measured):
    """``predict_many`` (the offset scan's, filtered in blocks of columns) gives each offset's ``predict``
    to round-off, also across the blocks it splits a long scan into, and the filtered acceleration
    channel is really filtered (zero mean, unlike the raw interpolation)."""
    from isolab.studies.answers.calibration import model as channel_model
    from isolab.studies.answers.calibration.fit import prepare_calibration

    prep = prepare_calibration(NOMINAL, measured, THREE)
    m = prep.model
    hist = m.histories(np.array([[p.start for p in prep.params]]))[0]
    taus = np.linspace(-0.05, 0.3, 37)
    alone = np.stack([m.predict(hist, t) for t in taus])
    scale = np.max(np.abs(alone), axis=(0, 1))
    assert np.max(np.abs(m.predict_many(hist, taus) - alone) / scale) < 1e-12
    block = channel_model.FILTER_BLOCK
    try:
        channel_model.FILTER_BLOCK = 5 * m.t.size * alone.shape[2]  # 5 offsets a block: 8 blocks
        assert np.max(np.abs(m.predict_many(hist, taus) - alone) / scale) < 1e-12
    finally:
        channel_model.FILTER_BLOCK = block
    raw = np.stack([m.sample(hist, t) for t in taus])
    acc = m.accel[0]
    assert np.max(np.abs(raw[..., acc] - alone[..., acc])) > 0.01 * scale[acc]
