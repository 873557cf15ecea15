"""Tolerances and monte_carlo designs: the distributions against scipy's, the block's checks naming the
field, the Clopper-Pearson interval against the binomial tails, and the probability of meeting a criterion
against its closed form (a deflection that grows with one normally distributed stage mass)."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest
import xarray as xr
from pydantic import ValidationError
from scipy import stats

from isolab.engine import simulate
from isolab.service.api.schemas import EXAMPLE_SCENE
from isolab.studies.inputs.schema import error_messages
from isolab.studies.inputs.study import study_labels, validate_study
from isolab.studies.questions.criteria import add_criteria
from isolab.studies.questions.tolerances import (
    Spread,
    Tolerance,
    add_reliability,
    clopper_pearson,
    draw,
    resolve_spread,
)
from isolab.studies.results.dataset import to_dataset
from isolab.studies.results.store import netcdf_encoding


def scene() -> dict:
    s = copy.deepcopy(EXAMPLE_SCENE)
    s["simulation"] = {"fidelity": "lti", "integrator": "exact", "dt": "2 ms", "duration": "2.5 s"}
    return s


def study(tolerances: dict, n: int = 64, **extra) -> dict:
    return {
        "name": "mc",
        "scene": scene(),
        "criteria": {"isolators": {"max_deflection": "8 mm"}},
        "tolerances": tolerances,
        "design": {"type": "monte_carlo", "samples": n, **extra.pop("design", {})},
        **extra,
    }


def spread(distribution: str, nominal: float, **given) -> Spread:
    tol = Tolerance.model_validate({"distribution": distribution, **given})
    return resolve_spread(tol, name="p", path="p", unit="kg", dimension="mass", nominal=nominal, where="t")


# --------------------------------------------------------------------------------------- distributions
@pytest.mark.parametrize(
    ("s", "reference"),
    [
        (spread("normal", 1000.0, sigma="10 %"), stats.norm(1000.0, 100.0)),
        (spread("normal", 1000.0, sigma="50 kg", within="60 kg"), stats.truncnorm(-1.2, 1.2, 1000.0, 50.0)),
        (spread("uniform", 2700.0, within="100 kg"), stats.uniform(2600.0, 200.0)),
        (spread("lognormal", 4.0, sigma="20 %"), stats.lognorm(0.2, scale=4.0)),
        (spread("lognormal", 4.0, sigma=0.8, within=1.0), None),
    ],
)
@pytest.mark.parametrize("sampling", ["sobol", "random"])
def test_draws_follow_the_distribution(s: Spread, reference, sampling: str) -> None:
    x = draw([s], 4096, seed=3, sampling=sampling)[:, 0]
    assert np.isfinite(x).all()
    if np.isfinite(s.low):
        assert x.min() >= s.low and x.max() <= s.high
    if reference is None:  # a truncated lognormal: scipy's lognormal conditioned on the bounds
        ln = stats.lognorm(0.2, scale=4.0)
        lo, hi = ln.cdf(3.0), ln.cdf(5.0)
        cdf = lambda v: (ln.cdf(np.clip(v, 3.0, 5.0)) - lo) / (hi - lo)  # noqa: E731
    else:
        cdf = reference.cdf
    assert stats.kstest(x, cdf).pvalue > 0.01
    np.testing.assert_allclose(s.cdf(x), cdf(x), atol=1e-9)  # the stated closed form is scipy's


def test_a_percent_is_a_share_of_the_nominal_even_for_a_dimensionless_parameter() -> None:
    st = validate_study(
        study(
            {
                "isolators.zeta": {"distribution": "uniform", "within": "20 %"},
                "stages.y.mass": {"sigma": "40 kg"},
            },
            parameters=[{"path": "isolators.zeta", "values": ["30 %"]}],
        )
    )
    zeta, mass = st.spreads
    assert (zeta.nominal, zeta.low, zeta.high) == pytest.approx((0.30, 0.24, 0.36))
    assert (mass.nominal, mass.sigma) == pytest.approx((1000.0, 40.0))
    d = st.design()
    assert d.names == ["isolator_zeta", "stage_y_mass"] and d.n_cases == 64
    assert 0.24 <= d.values["isolator_zeta"].min() and d.values["isolator_zeta"].max() <= 0.36
    # the scene's own value is the nominal when no parameter sets it: the air preset's 2 Hz
    f = validate_study(study({"isolators.f_vertical": {"sigma": "5 %"}})).spreads[0]
    assert f.nominal > 0 and f.sigma == pytest.approx(0.05 * f.nominal)


@pytest.mark.parametrize(
    ("tolerances", "extra", "expected"),
    [
        (
            {"stages.y.mass": {"distribution": "uniform"}},
            {},
            "tolerances.stages.y.mass: within: a uniform tolerance needs",
        ),
        ({"stages.y.mass": {"sigma": "-5 %"}}, {}, "tolerances.stages.y.mass.sigma: must be positive"),
        ({"stages.y.mass": {"sigma": "5 m"}}, {}, "tolerances.stages.y.mass.sigma: expected a mass"),
        ({"stages.q.mass": {"sigma": "5 %"}}, {}, "tolerances.stages.q.mass: 'stages.q.mass' does not exist"),
        (
            {"isolators.preset": {"sigma": "5 %"}},
            {},
            "tolerances.isolators.preset: isolators.preset is a choice",
        ),
        ({"points.tool.z": {"sigma": "1 %"}}, {}, None),
        (
            {"machine.block.corner.x": {"sigma": "1 %"}},
            {},
            "tolerances.machine.block.corner.x.sigma: a share",
        ),
        (
            {"stages.y.mass": {"sigma": "5 %"}},
            {"parameters": [{"path": "stages.y.mass", "values": [1, 2]}]},
            "parameters[0]: a monte_carlo design draws its cases from the tolerances",
        ),
        ({}, {}, "tolerances: a monte_carlo design draws its cases from a tolerances block"),
    ],
)
def test_bad_tolerances_name_the_field(tolerances: dict, extra: dict, expected: str | None) -> None:
    body = study(tolerances, **extra)
    if expected is None:  # a point 0.6 m up: 1 % of it is a valid spread
        validate_study(body)
        return
    with pytest.raises(ValidationError) as err:
        validate_study(body)
    assert any(expected in m for m in error_messages(err.value)), error_messages(err.value)


def test_only_a_monte_carlo_design_samples_tolerances_and_other_designs_ignore_them() -> None:
    body = study({"stages.y.mass": {"sigma": "5 %"}}, design={"sampling": "random"})
    body["design"] = {"type": "lhs", "samples": 4, "sampling": "random"}
    body["parameters"] = [{"path": "stages.y.mass", "range": {"start": "900 kg", "stop": "1100 kg"}}]
    with pytest.raises(ValidationError) as err:
        validate_study(body)
    assert any("design.sampling: only a monte_carlo design" in m for m in error_messages(err.value))
    del body["design"]["sampling"]
    st = validate_study(body)
    assert st.spreads == [] and st.n_cases == 4


# ------------------------------------------------------------------------------------------ intervals
@pytest.mark.parametrize(("k", "n"), [(0, 10), (3, 10), (10, 10), (54, 100), (390, 400)])
def test_clopper_pearson_bounds_are_the_binomial_tails(k: int, n: int) -> None:
    lo, hi = clopper_pearson(k, n, 0.95)
    assert 0.0 <= lo <= k / n <= hi <= 1.0
    if k > 0:  # seeing k or more is a 2.5 % chance at the lower bound
        assert stats.binom.sf(k - 1, n, lo) == pytest.approx(0.025, rel=1e-6)
    else:
        assert lo == 0.0
    if k < n:
        assert stats.binom.cdf(k, n, hi) == pytest.approx(0.025, rel=1e-6)
    else:
        assert hi == 1.0
    assert clopper_pearson(0, 10)[1] == pytest.approx(1 - 0.025 ** (1 / 10))


# -------------------------------------------------------------------------------------- closed form
Z_STAR = 0.4
"""The threshold mass, in sigmas above the nominal: a deflection limit met below it."""


@pytest.fixture(scope="module")
def mass_study():
    """Stage mass normal about 1,000 kg (sigma 10 %); the deflection limit is the deflection at
    1,000 kg + 0.4 sigma, so a case meets it when its mass is below that: P = Phi(0.4)."""
    s = copy.deepcopy(EXAMPLE_SCENE)
    s["simulation"] = {"fidelity": "lti", "integrator": "exact", "dt": "2 ms", "duration": "2.5 s"}
    star = 1000.0 * (1.0 + 0.1 * Z_STAR)
    probe = validate_study(
        {"name": "p", "scene": s, "parameters": [{"path": "stages.y.mass", "values": [star]}]}
    )
    r = simulate(probe.batch([0]), "lti", "exact", 2e-3)
    limit = float(np.max(r.peak_isolator_deflection))
    body = {
        "name": "mc",
        "scene": s,
        "criteria": {"isolators": {"max_deflection": limit, "no_liftoff": True}},
        "tolerances": {"stages.y.mass": {"distribution": "normal", "sigma": "10 %"}},
        "design": {"type": "monte_carlo", "samples": 128, "seed": 7},
    }
    st = validate_study(body)
    result = simulate(st.batch(np.arange(st.n_cases)), "lti", "exact", 2e-3)
    iso, pts = study_labels(st)
    ds = add_criteria(to_dataset(result, st.design(), isolator_names=iso, point_names=pts), st.criteria)
    return add_reliability(ds, st.spreads, "sobol"), st, star


def test_probability_of_meeting_matches_the_normal_cdf(mass_study) -> None:
    ds, st, star = mass_study
    mass = ds["stage_y_mass"].values
    meets = ds["meets_criteria"].values == 1
    near = np.abs(mass - star) < 1e-6 * star
    np.testing.assert_array_equal(meets[~near], (mass <= star)[~near])  # the margin is monotonic in the mass
    exact = float(stats.norm.cdf(Z_STAR))
    p = float(ds["probability_meets_criteria"])
    lo, hi = ds["probability_meets_criteria_interval"].values
    assert lo < exact < hi
    assert p == pytest.approx(exact, abs=0.03)  # a scrambled Sobol' sequence of 128: close to Phi(0.4)
    fails = ds["criterion_failure_probability"].sel(criterion="isolators_max_deflection")
    assert float(fails) == pytest.approx(1 - p)
    assert float(ds["criterion_failure_probability"].sel(criterion="isolators_no_liftoff")) == 0.0
    lo0, hi0 = ds["criterion_failure_probability_interval"].sel(criterion="isolators_no_liftoff").values
    assert lo0 == 0.0 and 0 < hi0 < 0.03


def test_probabilities_carry_units_names_and_survive_netcdf(mass_study, tmp_path) -> None:
    ds, st, _ = mass_study
    for name in (
        "probability_meets_criteria",
        "probability_meets_criteria_interval",
        "criterion_failure_probability",
        "criterion_failure_probability_interval",
    ):
        assert ds[name].attrs["units"] == "1" and ds[name].attrs["long_name"]
        assert ds[name].attrs["interval_method"].startswith("Clopper-Pearson")
    path = tmp_path / "mc.nc"
    ds.to_netcdf(path, encoding=netcdf_encoding(ds))
    back = xr.load_dataset(path)
    assert float(back["probability_meets_criteria"]) == float(ds["probability_meets_criteria"])
    spreads = json.loads(back.attrs["tolerances"])
    assert spreads["stage_y_mass"] == {
        "path": "stages.y.mass",
        "distribution": "normal",
        "nominal": 1000.0,
        "sigma": pytest.approx(100.0),
        "unit": "kg",
    }
