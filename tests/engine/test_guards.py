"""Guards: the stability guard and the integrators' real stability limits, lift-off, tipping, mechanisms,
and the refusal of input that cannot describe a scene."""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pytest
from scenes import (
    ONE_MODE_W,
    mount,
    one_mode,
    pieces_array,
    run_unguarded,
    scene,
    trapezoid_pieces,
    y_stage,
)

from isolab.engine import GRAVITY, SceneError, model, simulate
from isolab.engine.modal import state_matrix
from isolab.engine.profiles import scurve
from isolab.engine.results import OK, OUTPUT_FIELDS, TIPPING, UNSTABLE
from isolab.engine.stability import euler_limit, rk4_limit, spectral_radius, step_matrix

# ------------------------------------------------------------------------------------ stability guard
M_STIFF = 500.0


def _stiff_scene():
    """A 500 kg base on stiff (400 Hz per mount, 1 % damped) levelling mounts: fastest mode 625 Hz, so
    w dt = 3.9 at 1 ms, past both Euler's limit (2) and RK4's (2.83). A smooth S-curve drives it, so the
    response is mostly quasi-static and a stable step can also be an accurate one."""
    k, c = mount(M_STIFF / 4, 400.0, 0.01)
    stage = {
        "mass": 50.0,
        "home": (0.1, -0.3, 0.15),
        "axis": (0.0, 1.0, 0.0),
        "pieces": pieces_array(scurve(0.2, 0.5, 5.0, 50.0, start=0.01)),
    }
    return scene(
        mass=M_STIFF,
        size=(1.0, 1.2, 0.15),
        span=(0.9, 1.1),
        k=(k, k, k),
        c=(c, c, c),
        stages=[stage],
        duration=0.6,
    )


@pytest.mark.parametrize(("integrator", "sub_steps"), [("euler", 3), ("rk4", 2)])
def test_guard_refuses_or_subdivides_a_step_past_the_limit(integrator: str, sub_steps: int) -> None:
    b = _stiff_scene()
    refused = simulate(b, "lti", integrator, dt=1e-3, auto_step=False)
    assert refused.status[0] == UNSTABLE
    assert f"{integrator} stability limit" in refused.message[0]
    assert "624.6 Hz" in refused.message[0]  # names the fastest mode
    assert f"needs {sub_steps} sub-steps" in refused.message[0]
    for name in (
        "peak_displacement",
        "peak_rotation",
        "peak_isolator_force",
        "min_isolator_load",
        "final_displacement",
        "settling_time",
    ):
        assert np.isnan(getattr(refused, name)[0]).all(), name
    assert refused.natural_frequency[0].max() == pytest.approx(624.6, abs=0.1)

    ok = simulate(b, "lti", integrator, dt=1e-3, auto_step=True)
    assert ok.status[0] == OK and ok.message[0].startswith("sub-stepped: 1 ms cut to ")
    assert f"({sub_steps} sub-steps)" in ok.message[0] and "accuracy may be poor" in ok.message[0]
    # smallest stable division with the guard's 1.25 margin: w h = 3.92 / n * 1.25 below 2 (euler)
    # or 2.83 (rk4)
    assert ok.dt[0] == pytest.approx(1e-3 / sub_steps, rel=1e-12)
    # the reference sampled at the same sub-step (peaks of a 625 Hz ringing depend on the sampling)
    ref = simulate(b, "lti", "reference", dt=ok.dt[0])
    # the outputs a user sizes hardware with agree within 1 % (measured: Y 0.7 %, pitch 0.04 %,
    # isolator forces 0.75 %, minimum loads 0.01 %)
    assert ok.peak_displacement[0, 1] == pytest.approx(ref.peak_displacement[0, 1], rel=1e-2)
    assert ok.peak_rotation[0, 0] == pytest.approx(ref.peak_rotation[0, 0], rel=1e-2)
    np.testing.assert_allclose(ok.peak_isolator_force, ref.peak_isolator_force, rtol=1e-2)
    np.testing.assert_allclose(ok.min_isolator_load, ref.min_isolator_load, rtol=1e-3)
    # (the tiny, ringing-dominated outputs are not: at w h ~ 1.3 to 2 Euler inflates and RK4 damps the
    # 1 %-damped ringing; roll is off by +72 % / -87 %. A stable step is not an accurate one.)


def _stage_to_the_centre():
    """A 5 t stage on a light (1 t) base travels 2 m in Y from y = 2 m to the c.g.: the inertia in roll
    falls from 20,000 to 90 kg m^2, so the fastest mode rises from 11 Hz (stage at home) to 34 Hz (at the
    end of its travel)."""
    stage = {
        "mass": 5000.0,
        "home": (0.0, 2.0, 0.0),
        "axis": (0.0, -1.0, 0.0),
        "pieces": trapezoid_pieces(2.0, 1.0, 2.0),
    }
    return scene(
        mass=1000.0,
        size=(1.0, 1.0, 0.2),
        span=(0.5, 2.0),
        k=(1e6, 1e6, 1e6),
        c=(1e3, 1e3, 1e3),
        stages=[stage],
        duration=5.0,
    )


def test_guard_looks_at_the_stages_at_the_ends_of_their_travel() -> None:
    b = _stage_to_the_centre()
    assert len(model.travel_positions(b)) == 2  # the stage at either end of its travel
    A_home = state_matrix(model.mass_matrix(b), model.stiffness_matrix(b), model.damping_matrix(b))
    assert spectral_radius(step_matrix(A_home, np.array([0.03]), "rk4"))[0] <= 1.0  # stable at home
    ref = simulate(b, "ltv", "reference", dt=0.03)
    for integrator, dt in (("rk4", 0.03), ("euler", 0.01)):
        r = simulate(b, "ltv", integrator, dt=dt)
        # without the check at the travel's end the run diverged at t = 1.9 s (rk4) and 2.3 s (euler)
        assert r.status[0] == OK, r.message[0]
        assert r.dt[0] < dt
        assert r.peak_rotation[0, 0] == pytest.approx(ref.peak_rotation[0, 0], rel=1e-3)
    lti = simulate(b, "lti", "rk4", dt=0.03)  # the frozen-mass level keeps the stage at home
    assert lti.status[0] == OK and lti.dt[0] == 0.03


def test_a_stage_that_climbs_too_high_tips_the_time_varying_levels() -> None:
    # 1 t climbing 2 m on 0.4 m square of soft mounts: weight x height (24.5 kN m at 2.5 m) exceeds the
    # mounts' rocking stiffness (16 kN m/rad) at the top, not at home (4.9 kN m at 0.5 m)
    def climb(travel: float):
        stage = {
            "mass": 1000.0,
            "home": (0.0, 0.0, 0.5),
            "axis": (0.0, 0.0, 1.0),
            "pieces": trapezoid_pieces(travel, 1.0, 2.0),
        }
        return scene(span=(0.4, 0.4), k=(1e5, 1e5, 1e5), c=(1e3, 1e3, 1e3), stages=[stage], duration=4.0)

    for fidelity, integrator in (("ltv", "rk4"), ("nonlinear", "euler"), ("ltv", "reference")):
        r = simulate(climb(2.0), fidelity, integrator, dt=1e-3)
        assert r.status[0] == TIPPING and "ends of their travel" in r.message[0]
        assert np.isnan(r.peak_displacement[0]).all()
        assert simulate(climb(0.5), fidelity, integrator, dt=1e-3).status[0] == OK  # 1.0 m: 9.8 kN m
    assert simulate(climb(2.0), "lti", "exact", dt=1e-3).status[0] == OK  # frozen at home


def test_exact_needs_no_guard() -> None:
    b = _stiff_scene()
    ex = simulate(b, "lti", "exact", dt=1e-3, auto_step=False)
    assert ex.status[0] == OK and ex.dt[0] == 1e-3
    ref = simulate(b, "lti", "reference", dt=1e-3)
    # exact discretisation against DOP853 at rtol 1e-10, atol 1e-13: 1e-6 of the largest peak (the
    # smallest peaks, 1e-10 m and 3e-11 rad, sit near the reference's absolute tolerance)
    for name in ("peak_displacement", "peak_rotation", "peak_isolator_force"):
        e, r = getattr(ex, name), getattr(ref, name)
        np.testing.assert_allclose(e, r, rtol=1e-6, atol=1e-6 * np.abs(r).max(), err_msg=name)


# ----------------------------------------------------------------------------- the limits themselves
W_HEAVE = ONE_MODE_W  # rad/s
ZETA = 0.05


def test_one_mode_is_the_fastest_and_has_the_expected_damping() -> None:
    r = simulate(one_mode(ZETA), "lti", "exact", dt=1e-3)
    j = int(np.argmax(r.natural_frequency[0]))
    assert r.mode_energy[0, j, 2] > 1 - 1e-9
    assert r.natural_frequency[0, j] == pytest.approx(W_HEAVE / (2 * np.pi), rel=1e-9)
    assert r.damping_ratio[0, j] == pytest.approx(ZETA, rel=1e-9)
    assert np.sort(r.natural_frequency[0])[-2] < 0.4 * r.natural_frequency[0, j]


@pytest.mark.parametrize(("integrator", "limit"), [("euler", euler_limit(ZETA)), ("rk4", rk4_limit(ZETA))])
def test_measured_stability_limit_of_one_mode(integrator: str, limit: float) -> None:
    h_lim = limit / W_HEAVE
    b = one_mode(ZETA, n_cases=2)
    # integrate 3000 steps 2 % below and 2 % above the limit: above it the mode grows by >= 10 % per step
    # and passes the divergence bound (1 m) from its 1e-8 m start within ~200 steps
    status, u = run_unguarded(b, integrator, np.array([0.98, 1.02]) * h_lim, 3000)
    assert status[0] == 0 and np.isfinite(u[0]).all() and u[0, 2] < 1e-6
    assert status[1] == 1
    # the one-step map of the linear model: spectral radius 1 at the limit, to a part in a thousand
    A = state_matrix(model.mass_matrix(b), model.stiffness_matrix(b), model.damping_matrix(b))[:1]
    below = spectral_radius(step_matrix(A, np.array([0.999 * h_lim]), integrator))[0]
    above = spectral_radius(step_matrix(A, np.array([1.001 * h_lim]), integrator))[0]
    assert below <= 1 + 1e-9 < 1 + 1e-4 < above
    # the guard refuses from limit / 1.25 on (its margin for stage-dependent mass): just below, it runs
    edge = h_lim / 1.25
    ok = simulate(b.take([0]), "lti", integrator, dt=0.99 * edge, auto_step=False)
    assert ok.status[0] == OK
    no = simulate(b.take([0]), "lti", integrator, dt=1.01 * edge, auto_step=False)
    assert no.status[0] == UNSTABLE
    split = simulate(b.take([0]), "lti", integrator, dt=1.01 * edge, auto_step=True)
    assert split.status[0] == OK and split.dt[0] == pytest.approx(1.01 * edge / 2, rel=1e-12)


def test_stability_limit_formulas() -> None:
    # semi-implicit Euler: 2 undamped; 2 (sqrt(1 + zeta^2) - zeta) damped
    assert euler_limit(0.0) == 2.0
    assert euler_limit(0.05) == pytest.approx(2 * (np.sqrt(1.0025) - 0.05), rel=1e-15)
    # RK4: 2 sqrt(2) on the imaginary axis (undamped), 2.785 on the negative real axis (zeta = 1)
    assert rk4_limit(0.0) == pytest.approx(2 * np.sqrt(2), rel=1e-9)
    assert rk4_limit(1.0) == pytest.approx(2.785293563, rel=1e-8)


# -------------------------------------------------------------------------------------------- lift-off
def test_a_heavy_fast_stage_lifts_one_mount_off() -> None:
    base, ms, hx = 2000.0, 600.0, 0.5
    kz, cz = mount((base + ms) / 4, 2.0, 0.05)  # soft (2 Hz) vertically, four times stiffer horizontally
    # the stage runs 0.8 m above the c.g., off-centre in X: the -X mounts carry less preload
    stage = y_stage(mass=ms, travel=1.0, v=2.0, a=2 * GRAVITY, home=(hx, 0.0, 0.8))
    b = scene(
        mass=base,
        size=(1.2, 1.6, 0.3),
        span=(1.1, 1.4),
        height=0.3,
        k=(4 * kz, 4 * kz, kz),
        c=(cz, cz, cz),
        stages=[stage],
        duration=1.5,
    )
    r = simulate(b, "ltv", "rk4", dt=1e-3)
    assert r.status[0] == OK
    f0 = r.static_isolator_load[0]
    # the preload carries every weight and balances the stage's moment at home
    assert f0.sum() == pytest.approx((base + ms) * GRAVITY, rel=1e-12)
    assert f0 @ b.iso_pos[0, :, 0] == pytest.approx(ms * GRAVITY * hx, rel=1e-12)
    assert f0 @ b.iso_pos[0, :, 1] == pytest.approx(0.0, abs=1e-9 * f0.sum())
    # mount 2 at (-x, -y) lifts off while braking (measured -967 N); the others stay loaded (>= 546 N)
    low = r.min_isolator_load[0]
    assert low[2] < -0.05 * f0[2]
    assert np.all(np.delete(low, 2) > 0.05 * np.delete(f0, 2))
    assert np.all(low < f0)


# ---------------------------------------------------------------------------------------------- tipping
def _narrow_scene(margin: np.ndarray, gravity_stiffness: bool = True):
    """Mounts 0.4 m apart, 1 m below the c.g. of a 2000 kg base: each case's vertical stiffness makes the
    mounts' rocking stiffness 4 kz b^2 equal ``margin`` times the weight's M g h."""
    base, half, h = 2000.0, 0.2, 1.0
    kz = np.asarray(margin) * base * GRAVITY * h / (4 * half**2)
    b = scene(
        n_cases=len(kz),
        mass=base,
        size=(1.2, 1.6, 0.3),
        span=(2 * half, 2 * half),
        height=h,
        k=(1e5, 1e5, 1e5),
        c=(1e3, 1e3, 1e3),
        duration=0.5,
        gravity_stiffness=gravity_stiffness,
    )
    b.iso_k[..., 2] = kz[:, None]
    return b


def test_mounts_too_narrow_under_a_high_cg_tip() -> None:
    # with the base free to translate, the rocking stiffness is 4 kz b^2 - M g h: the horizontal springs
    # only couple it to translation. Tips below margin 1, stands above it.
    b = _narrow_scene(np.array([0.95, 1.05]))
    r = simulate(b, "ltv", "reference", dt=1e-3)  # (the fixed-step guard trips on tipping: see below)
    assert list(r.status) == [TIPPING, OK]
    assert "statically unstable" in r.message[0] and r.message[1] == ""
    assert np.isnan(r.peak_displacement[0]).all() and np.isfinite(r.peak_displacement[1]).all()
    # the option: without the weights' rocking stiffness the narrow base stands
    loose = simulate(_narrow_scene(np.array([0.95]), gravity_stiffness=False), "lti", "exact", dt=1e-3)
    assert loose.status[0] == OK


NAN_WHEN_NOT_OK = {
    "peak_displacement",
    "peak_rotation",
    "peak_point_displacement",
    "peak_isolator_force",
    "min_isolator_load",
    "rms_displacement",
    "final_displacement",
    "settling_time",
    "point_settling_time",
    "peak_isolator_deflection",
    "max_isolator_load",
    "transmissibility",
    "peak_following_error",
    "ready_time",
    "point_ready_time",
}
"""The outputs SimulationResult's docstring says are NaN for a case that is not OK."""


@pytest.mark.parametrize("status", [UNSTABLE, TIPPING])
def test_a_case_that_is_not_ok_is_nan_exactly_where_the_result_says(status: int) -> None:
    if status == UNSTABLE:
        r = simulate(_stiff_scene(), "lti", "euler", dt=1e-3, auto_step=False)
    else:
        r = simulate(_narrow_scene(np.array([0.95])), "ltv", "rk4", dt=1e-3)
    assert r.status[0] == status
    for name in OUTPUT_FIELDS:
        value = np.asarray(getattr(r, name)[0], dtype=float)
        if name in NAN_WHEN_NOT_OK:
            assert np.isnan(value).all(), name
        else:  # dt, the move time, the preloads, the modal analysis; settled is False
            assert np.isfinite(value).all(), name
    assert not r.settled[0]
    assert set(r.to_dict(0)) == {"status", "message", *OUTPUT_FIELDS}


def test_tipping_case_reports_a_finite_step_without_warnings() -> None:
    b = _narrow_scene(np.array([0.95, 1.05]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        r = simulate(b, "ltv", "rk4", dt=1e-3)
    assert r.status[0] == TIPPING
    assert np.isfinite(r.dt).all()


# ------------------------------------------------------------------------------------------ mechanisms
def test_zero_horizontal_stiffness_gives_mechanism_modes() -> None:
    kz = 2e6
    stage = y_stage(mass=100.0, travel=0.2, v=0.5, a=5.0, home=(0.0, 0.0, 0.0))
    b = scene(mass=10_000.0, k=(0.0, 0.0, kz), c=(0.0, 0.0, 2e4), stages=[stage], duration=1.0)
    for integrator in ("rk4", "exact"):
        r = simulate(b, "lti", integrator, dt=1e-3)
        assert r.status[0] == OK, r.message[0]
        # x, y and yaw have nothing to hold them: three mechanisms at exactly 0 Hz
        assert r.mechanism[0].sum() == 3
        assert np.all(r.natural_frequency[0, r.mechanism[0]] == 0.0)
        assert np.all(r.damping_ratio[0, r.mechanism[0]] == 0.0)
        free = r.mode_energy[0][r.mechanism[0]][:, [0, 1, 5]].sum(axis=1)
        np.testing.assert_allclose(free, 1.0, atol=1e-9)
        f_z = np.sqrt(4 * kz / 10_100.0) / (2 * np.pi)
        assert np.any(np.isclose(r.natural_frequency[0], f_z, rtol=1e-9))
        # nothing holds the base along Y: it recoils by exactly m s / (M + m) (LTI: mass frozen at home)
        assert r.peak_displacement[0, 1] == pytest.approx(100.0 * 0.2 / 10_100.0, rel=1e-9)


# --------------------------------------------------------------------------------------------- refusals
def _base():
    return scene(stages=[y_stage()], duration=0.1)


def _with(**kw):
    return replace(_base(), **kw)


def _bad_inputs():
    b = _base()
    nan_mass = b.mass.copy()
    nan_mass[0] = np.nan
    neg_k = b.iso_k.copy()
    neg_k[0, 1, 2] = -1.0
    line = b.iso_pos.copy()
    line[0, :, 0] = 0.0  # all four mounts on the Y axis
    inertia = b.inertia.copy()
    inertia[0, 0, 0] = -inertia[0, 0, 0]
    asym = b.inertia.copy()
    asym[0, 0, 1] = 10.0
    return [
        ("nan mass", dict(mass=nan_mass), "mass"),
        ("negative stiffness", dict(iso_k=neg_k), "iso_k"),
        (
            "two isolators",
            dict(
                iso_pos=b.iso_pos[:, :2],
                iso_k=b.iso_k[:, :2],
                iso_c=b.iso_c[:, :2],
                iso_skyhook=b.iso_skyhook[:, :2],
            ),
            "iso_pos",
        ),
        ("collinear isolators", dict(iso_pos=line), "iso_pos"),
        ("non-SPD inertia", dict(inertia=inertia), "inertia"),
        ("asymmetric inertia", dict(inertia=asym), "inertia"),
        ("zero mass", dict(mass=np.zeros(1)), "mass"),
        ("negative damping", dict(iso_c=-b.iso_c), "iso_c"),
        ("infinite duration", dict(duration=np.array([np.inf])), "duration"),
    ]


@pytest.mark.parametrize(("what", "changes", "field"), _bad_inputs(), ids=[c[0] for c in _bad_inputs()])
def test_bad_scene_is_refused_naming_the_field(what: str, changes: dict, field: str) -> None:
    with pytest.raises(SceneError) as err:
        simulate(_with(**changes), "lti", "exact", dt=1e-3)
    assert err.value.field == field
    assert err.value.reason and field in str(err.value)


@pytest.mark.parametrize(
    ("fidelity", "integrator", "dt", "field"),
    [
        ("quadratic", "rk4", 1e-3, "fidelity"),
        ("ltv", "leapfrog", 1e-3, "integrator"),
        ("ltv", "exact", 1e-3, "integrator"),  # exact discretisation exists for the LTI level only
        ("nonlinear", "exact", 1e-3, "integrator"),
        ("lti", "rk4", 0.0, "dt"),
        ("lti", "rk4", np.nan, "dt"),
    ],
)
def test_bad_choice_is_refused_naming_the_field(
    fidelity: str, integrator: str, dt: float, field: str
) -> None:
    with pytest.raises(SceneError) as err:
        simulate(_base(), fidelity, integrator, dt=dt)
    assert err.value.field == field
