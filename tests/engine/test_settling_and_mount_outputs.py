"""Per-point settling after each stage move, peak isolator deflection and largest isolator load."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
from scenes import mount, pieces_array, scene, trapezoid_pieces, vertical_stage

from isolab.engine import model, profiles, simulate
from isolab.engine.results import OK
from isolab.engine.scene import GRAVITY, SceneError, concat
from isolab.engine.validation import validate

BASE, PUSH = 1000.0, 10.0
"""Base mass and the mass of the stage that pushes it, kg."""


def heave_scene(w: float, zeta: float, stages: list[dict], duration: float, points=None):
    """Four identical mounts in the c.g. plane, symmetric about the c.g.: a vertical force through the
    c.g. excites pure heave at ``w`` rad/s with damping ratio ``zeta`` (1)."""
    kz, cz = mount((BASE + PUSH) / 4, w / (2 * np.pi), zeta)
    return scene(
        mass=BASE,
        size=(2.0, 2.0, 0.5),
        span=(0.4, 0.4),
        k=(kz / 4, kz / 4, kz),
        c=(cz / 4, cz / 4, cz),
        stages=stages,
        points=points or [(0.0, 0.0, 0.0), (0.2, -0.1, 0.3)],
        duration=duration,
    )


def z_move(distance: float, v: float, a: float, start: float = 0.0) -> dict:
    """A stage at the c.g. that moves vertically: only a vertical force through the c.g. on the base."""
    return {
        "mass": PUSH,
        "home": (0.0, 0.0, 0.0),
        "axis": (0.0, 0.0, 1.0),
        "pieces": trapezoid_pieces(distance, v, a, start),
    }


# --------------------------------------------------------------------------------- mounts: closed form
@pytest.mark.parametrize(
    ("fidelity", "integrator"),
    [
        ("lti", "exact"),
        ("lti", "rk4"),
        ("lti", "euler"),
        ("ltv", "rk4"),
        ("ltv", "reference"),
        ("nonlinear", "rk4"),
        ("nonlinear", "euler"),
    ],
)
def test_undamped_heave_step_gives_closed_form_deflection_and_largest_load(fidelity, integrator) -> None:
    # a stage accelerating upward at 1 m/s^2 pushes the base down with a step force m a through the c.g.:
    # z(t) = -(F / k) (1 - cos w t), peak 2 F / k at t = pi / w = 5 ms, a step of 0.1 ms
    w, dt, accel = np.pi / 0.005, 1e-4, 1.0
    b = heave_scene(w, 0.0, [vertical_stage(PUSH, accel)], duration=0.02)
    r = simulate(b, fidelity, integrator, dt=dt)
    assert r.status[0] == OK, r.message[0]
    kz = b.iso_k[0, 0, 2]
    peak_z = 2 * PUSH * accel / (4 * kz)  # each mount carries a quarter of the step force
    rtol = 2e-3 if integrator == "euler" else 1e-5
    np.testing.assert_allclose(r.peak_displacement[0, 2], peak_z, rtol=rtol)
    # pure heave: every mount deflects as the c.g. does, and an undamped mount's force is k times it
    np.testing.assert_allclose(r.peak_isolator_deflection[0, :, 2], r.peak_displacement[0, 2], rtol=1e-9)
    np.testing.assert_allclose(
        r.peak_isolator_deflection[0, :, 2], r.peak_isolator_force[0, :, 2] / kz, rtol=1e-9
    )
    np.testing.assert_allclose(r.peak_isolator_deflection[0, :, 2], peak_z, rtol=rtol)
    assert np.all(r.peak_isolator_deflection[0, :, :2] < 1e-9 * peak_z)
    # largest load: the preload (a quarter of every weight) plus the peak compression 2 m a / 4
    static = (BASE + PUSH) * GRAVITY / 4
    np.testing.assert_allclose(r.static_isolator_load[0], static, rtol=1e-12)
    np.testing.assert_allclose(r.max_isolator_load[0] - static, 2 * PUSH * accel / 4, rtol=rtol)
    np.testing.assert_allclose(r.max_isolator_load[0], static + r.peak_isolator_force[0, :, 2], rtol=1e-12)
    # the base only sinks: the smallest load is the preload (to the integrator's error)
    np.testing.assert_allclose(r.min_isolator_load[0] - static, 0.0, atol=rtol * PUSH * accel / 2)
    # a stage that accelerates for ever never comes to rest: no rest interval, settling time 0
    assert np.all(r.point_settling_time[0] == 0.0)


def test_sine_floor_deflection_is_relative_to_the_floor() -> None:
    # heave under a floor sine far above resonance: the base stays almost still, so the mount's stroke is
    # about the floor amplitude (the transmissibility says how little the base follows)
    w = 2 * np.pi * 5.0
    amp, f = 20e-6, 50.0
    b = heave_scene(w, 0.2, [], duration=2.0)
    b.floor_amp[:, 2] = amp
    b.floor_freq[:, 2] = f
    r = simulate(b, "lti", "exact", dt=1e-4)
    assert r.status[0] == OK, r.message[0]
    base = r.peak_displacement[0, 2]
    assert base < 0.5 * amp  # the start-up transient included
    # where the floor peaks (a sample, every 20 ms) the mount deflects at least amp - |base|
    defl = r.peak_isolator_deflection[0, :, 2]
    assert np.all(defl > amp - base - 1e-9) and np.all(defl < amp + base + 1e-9)


# ------------------------------------------------------------------------------- settling after moves
def heave_after_move(zeta: float, w: float, move: dict, t_end: float, tol: float, dt: float) -> float:
    """Closed-form settling time of pure heave after one vertical trapezoidal move: the 1-DOF response
    to the piecewise-constant force ``-m a(t)`` propagated exactly (matrix exponential) to the move's
    end, then the free damped motion sampled every ``dt`` s; the last sample outside ``tol``, s after
    the move's end."""
    p = move["pieces"]
    mt = BASE + PUSH
    A = np.array([[0.0, 1.0], [-(w**2), -2 * zeta * w]])
    x = np.zeros(2)
    for k in range(p.shape[1] - 1):
        h = p[0, k + 1] - p[0, k]
        force = -PUSH * p[3, k] / mt
        # x' = A x + (0, force): exact for a constant force
        Z = np.zeros((3, 3))
        Z[:2, :2] = A
        Z[1, 2] = force
        x = (scipy.linalg.expm(Z * h) @ np.array([x[0], x[1], 1.0]))[:2]
    t_move = p[0, -1]
    t = np.arange(int(np.ceil(t_move / dt)), int(round(t_end / dt)) + 1) * dt
    E = np.array([scipy.linalg.expm(A * (tk - t_move)) @ x for tk in t])
    out = np.flatnonzero(np.abs(E[:, 0]) > tol)
    return float(t[out[-1]] - t_move) if out.size else 0.0


def residual_amplitude(zeta: float, w: float, move: dict) -> float:
    """Amplitude of the free damped heave right after the move, m (same propagation as above)."""
    p = move["pieces"]
    A = np.array([[0.0, 1.0], [-(w**2), -2 * zeta * w]])
    x = np.zeros(2)
    for k in range(p.shape[1] - 1):
        Z = np.zeros((3, 3))
        Z[:2, :2] = A
        Z[1, 2] = -PUSH * p[3, k] / (BASE + PUSH)
        x = (scipy.linalg.expm(Z * (p[0, k + 1] - p[0, k])) @ np.array([x[0], x[1], 1.0]))[:2]
    wd = w * np.sqrt(1 - zeta**2)
    return float(np.hypot(x[0], (x[1] + zeta * w * x[0]) / wd))


@pytest.mark.parametrize(("fidelity", "integrator"), [("lti", "exact"), ("lti", "rk4"), ("ltv", "rk4")])
def test_settling_after_one_move_follows_the_decay_envelope(fidelity, integrator) -> None:
    zeta, w, dt = 0.02, 2 * np.pi * 25.0, 1e-3
    move = z_move(0.01, 0.1, 2.0, start=0.1)
    b = heave_scene(w, zeta, [move], duration=3.0)
    bounds, count = b.rest_intervals()
    assert count[0] == 1 and bounds[0, 0, 0] == move["pieces"][0, -1] and bounds[0, 0, 1] == np.inf
    amp = residual_amplitude(zeta, w, move)
    wd = w * np.sqrt(1 - zeta**2)
    times, cg_settling = [], []
    for tol in (amp / 40, amp / 20, amp / 10):
        b.point_settle_tol[:] = tol
        r = simulate(b, fidelity, integrator, dt=dt)
        assert r.status[0] == OK, r.message[0]
        ts = r.point_settling_time[0]
        # pure heave: both points move with the c.g.
        assert ts[0] == ts[1]
        exact = heave_after_move(zeta, w, move, 3.0, tol, dt)
        assert abs(ts[0] - exact) <= 2 * dt + 1e-12, (tol, ts[0], exact)
        # the envelope A exp(-zeta w t) reaches tol at ln(A / tol) / (zeta w); the last sample outside
        # lies on the last peak above tol: within half a damped period (and a step) before it
        envelope = np.log(amp / tol) / (zeta * w)
        assert envelope - np.pi / wd - dt <= ts[0] <= envelope + dt, (tol, ts[0], envelope)
        times.append(ts[0])
        cg_settling.append(r.settling_time[0])
    # a tighter tolerance takes longer: ln 2 / (zeta w) more for half the tolerance, to half a period
    assert times[0] > times[1] > times[2] > 0
    np.testing.assert_allclose(np.diff(times[::-1]), np.log(2) / (zeta * w), atol=np.pi / wd + 2 * dt)
    # the c.g.'s own settling (after the last move, to settle_tol) does not depend on the point tolerances
    assert len(set(cg_settling)) == 1


def test_a_point_still_moving_at_the_end_reports_the_interval_length() -> None:
    zeta, w, dt = 0.005, 2 * np.pi * 25.0, 1e-3
    move = z_move(0.01, 0.1, 2.0, start=0.1)
    b = heave_scene(w, zeta, [move], duration=1.0)
    tol = residual_amplitude(zeta, w, move) / 100  # needs ln(100) / (zeta w) = 5.9 s
    b.point_settle_tol[:] = tol
    r = simulate(b, "lti", "exact", dt=dt, record=[0])
    t_move = move["pieces"][0, -1]
    assert abs(r.history["point_displacement"][0, -1, 0, 2]) > tol  # outside at the run's end
    np.testing.assert_allclose(r.point_settling_time[0], 1.0 - t_move, rtol=1e-12)


# ---------------------------------------------------------------------------- per-interval static targets
def out_rest_back(rest: float = 1.0) -> dict:
    """A 200 kg stage along +Y that moves 0.8 m off-centre, rests ``rest`` s and moves back home."""
    out = trapezoid_pieces(0.8, 0.8, 4.0, start=0.1)  # 0.1 .. 1.3 s, then at rest at 0.8 m
    back = trapezoid_pieces(-0.8, 0.8, 4.0, start=out[0, -1] + rest)
    back[1] += 0.8  # positions of the return are measured from where the first move ended
    pieces = np.concatenate([out, back], axis=1)
    return {"mass": 200.0, "home": (0.0, -0.4, 0.3), "axis": (0.0, 1.0, 0.0), "pieces": pieces}


def tilt_scene(n_cases: int = 1):
    k, c = mount(2600.0 / 4, 8.0, 0.3)  # 8 Hz, 30 % damping in every direction
    return scene(
        n_cases=n_cases,
        mass=2400.0,
        size=(1.6, 2.0, 0.3),
        span=(1.4, 1.8),
        k=(k, k, k),
        c=(c, c, c),
        stages=[out_rest_back()],
        points=[(0.0, 1.2, 0.2), (0.7, -1.0, 0.0)],
        duration=4.5,
    )


@pytest.mark.parametrize("fidelity", ["lti", "ltv", "nonlinear"])
def test_a_point_settles_to_the_tilted_static_position_of_each_rest(fidelity) -> None:
    b = tilt_scene()
    bounds, count, target = model.rest_offsets(b, fidelity)
    assert count[0] == 2
    (t0, t1), (t2, t3) = bounds[0]
    stage = b.prof_t[0, 0]
    assert t0 == stage[3] and t1 == stage[4] and t2 == stage[-1] and t3 == np.inf
    np.testing.assert_allclose(t1 - t0, 1.0, rtol=1e-12)
    # parked 0.8 m off home along Y, the stage's weight pitches the base: the point 1.2 m ahead sinks
    d = b.points[0] - b.cg[0]
    static_z = target[0, 0, 3] * d[0, 1] - target[0, 0, 4] * d[0, 0] + target[0, 0, 2]
    kz = b.iso_k[0, 0, 2]
    pitch = 200.0 * GRAVITY * 0.8 / (4 * kz * 0.9**2)  # weight moment over the mounts' rocking stiffness
    assert target[0, 0, 3] == pytest.approx(-pitch, rel=0.03)
    tol = 2e-6
    assert abs(static_z) > 30 * tol  # far outside the tolerance of the home position
    np.testing.assert_allclose(target[0, 1], 0.0, atol=1e-12)  # back home: nothing left
    b.point_settle_tol[:] = tol
    integrator = "exact" if fidelity == "lti" else "rk4"
    r = simulate(b, fidelity, integrator, dt=1e-3, record=[0])
    assert r.status[0] == OK, r.message[0]
    ts = r.point_settling_time[0]
    # settles to the tilted position well within the 1 s rest: 0.3 damping at 8 Hz decays e-fold in 66 ms
    # (were the target 0, the value would be the rest's length, 1 s)
    assert np.all(np.isfinite(ts)) and np.all(ts > 0.05) and np.all(ts < 0.6), ts
    # measured against 0 instead, the point would still be "outside" at the end of the rest
    h = r.history
    time, z = h["time"][0], h["point_displacement"][0, :, 0, 2]
    during = (time >= t0) & (time <= t1)
    assert np.all(np.abs(z[during][-100:]) > 10 * tol)
    assert np.all(np.abs(z[during][-100:] - static_z) < tol)


def test_no_stage_motion_has_no_rest_interval_and_settles_at_once() -> None:
    b = heave_scene(2 * np.pi * 5, 0.05, [], duration=0.5)
    bounds, count = b.rest_intervals()
    assert count.tolist() == [0]
    b.floor_amp[:, 2] = 1e-5
    b.floor_freq[:, 2] = 7.0
    r = simulate(b, "lti", "rk4", dt=1e-3)
    assert r.status[0] == OK and np.all(r.point_settling_time[0] == 0.0)
    assert r.peak_displacement[0, 2] > 1e-6  # it does move


def test_rest_intervals_of_a_scan_with_dwells_and_moves_that_run_into_each_other() -> None:
    p = profiles.scan(0.5, 1.0, 5.0, dwell=0.25, repeats=2, start=0.2)
    b = scene(stages=[{"mass": 10.0, "home": (0, 0, 0), "axis": (0, 1, 0), "pieces": pieces_array(p)}])
    bounds, count = b.rest_intervals()
    ends = profiles.end_time(p)[0]
    # out, dwell, back, dwell (x2): four rests, the dwells of 0.25 s, and the last (whose dwell ends the
    # profile) runs on to the end of the run
    assert count[0] == 4
    np.testing.assert_allclose(bounds[0, :3, 1] - bounds[0, :3, 0], 0.25, rtol=1e-9)
    np.testing.assert_allclose(bounds[0, 3, 0], ends - 0.25, rtol=1e-12)
    assert bounds[0, 3, 1] == np.inf
    # no dwell: the moves run into each other, one rest after the last
    p = profiles.scan(0.5, 1.0, 5.0, dwell=0.0, repeats=2)
    b = scene(stages=[{"mass": 10.0, "home": (0, 0, 0), "axis": (0, 1, 0), "pieces": pieces_array(p)}])
    bounds, count = b.rest_intervals()
    assert count[0] == 1 and bounds[0, 0, 0] == profiles.end_time(p)[0]


def test_two_stages_rest_only_when_both_do() -> None:
    a = trapezoid_pieces(0.3, 0.5, 3.0, start=0.0)  # 0 .. 0.767 s
    c = trapezoid_pieces(0.2, 0.5, 3.0, start=0.5)  # 0.5 .. 1.158 s: overlaps the first move
    d = trapezoid_pieces(0.2, 0.5, 3.0, start=2.0)
    b = scene(
        stages=[
            {"mass": 10.0, "home": (0, 0, 0), "axis": (0, 1, 0), "pieces": a},
            {"mass": 10.0, "home": (0, 0, 0), "axis": (1, 0, 0), "pieces": np.concatenate([c, d], 1)},
        ]
    )
    b.prof_s[0, 1, 4:] += 0.2
    bounds, count = b.rest_intervals()
    assert count[0] == 2
    np.testing.assert_allclose(bounds[0, 0], [c[0, -1], 2.0])
    np.testing.assert_allclose(bounds[0, 1], [d[0, -1], np.inf])


# ----------------------------------------------------------------------------------- levels, integrators
def test_integrators_and_levels_agree() -> None:
    b = tilt_scene()
    b.point_settle_tol[:] = 2e-6
    ref = simulate(b, "lti", "exact", dt=1e-3)
    for fid, integ in (("lti", "rk4"), ("lti", "reference")):
        r = simulate(b, fid, integ, dt=1e-3)
        for name in ("peak_isolator_deflection", "max_isolator_load"):
            np.testing.assert_allclose(
                getattr(r, name), getattr(ref, name), rtol=1e-2, err_msg=f"{integ} {name}"
            )
        np.testing.assert_allclose(r.point_settling_time, ref.point_settling_time, atol=2e-3)
    # the levels differ by what the frozen mass misses: a few percent here
    for fid in ("ltv", "nonlinear"):
        r = simulate(b, fid, "rk4", dt=1e-3)
        np.testing.assert_allclose(r.peak_isolator_deflection, ref.peak_isolator_deflection, rtol=0.05)
        np.testing.assert_allclose(r.max_isolator_load, ref.max_isolator_load, rtol=1e-2)
        np.testing.assert_allclose(r.point_settling_time, ref.point_settling_time, rtol=0.1, atol=5e-3)
    ltv, nl = simulate(b, "ltv", "rk4", dt=1e-3), simulate(b, "nonlinear", "rk4", dt=1e-3)
    np.testing.assert_allclose(nl.peak_isolator_deflection, ltv.peak_isolator_deflection, rtol=1e-2)
    np.testing.assert_allclose(nl.point_settling_time, ltv.point_settling_time, atol=2e-3)


# ----------------------------------------------------------------------------------------- scene input
def test_point_settle_tol_defaults_to_settle_tol_and_travels_with_the_cases() -> None:
    b = tilt_scene(n_cases=2)
    b.settle_tol[:] = [3e-6, 4e-6]
    b.point_settle_tol = None
    b.__post_init__()
    np.testing.assert_array_equal(b.point_settle_tol, [[3e-6, 3e-6], [4e-6, 4e-6]])
    b.point_settle_tol = np.array([[1e-6, 2e-6], [3e-6, 4e-6]])
    both = concat([b, b.take([1])])
    np.testing.assert_array_equal(both.point_settle_tol, [[1e-6, 2e-6], [3e-6, 4e-6], [3e-6, 4e-6]])
    validate(both)


@pytest.mark.parametrize(
    ("value", "reason"),
    [(np.zeros((1, 2)), "must be positive"), (np.ones((1, 3)), "shape"), (np.ones(1), "shape")],
)
def test_bad_point_settle_tol_is_refused_naming_the_field(value, reason) -> None:
    b = tilt_scene()
    b.point_settle_tol = value
    with pytest.raises(SceneError, match=f"point_settle_tol: .*{reason}"):
        validate(b)
