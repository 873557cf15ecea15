"""Stage motion profiles: closed forms, limits, continuity, exact end points, vectorisation, validation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import cumulative_trapezoid

from isolab.engine.profiles import (
    SCURVE_PIECES,
    TRAPEZOID_PIECES,
    Pieces,
    end_time,
    evaluate,
    scan,
    scurve,
    sequence,
    stack,
    trapezoid,
)

G = 19.6133  # 2 g, m/s^2
REL = 1e-12


def piece_end(p: Pieces) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position, velocity, acceleration at the end of every piece but the last, by the polynomial."""
    tau = np.diff(p.t, axis=-1)
    s, v, a, j = (x[..., :-1] for x in (p.s, p.v, p.a, p.j))
    return (
        s + v * tau + a * tau**2 / 2 + j * tau**3 / 6,
        v + a * tau + j * tau**2 / 2,
        a + j * tau,
    )


def assert_continuous(p: Pieces, time_resolution: bool = False) -> None:
    """Position and velocity at the end of each piece equal the next piece's start values to 1e-12.

    Breakpoints are absolute times, so a phase's duration is only known to the spacing of floats near
    its start time; with ``time_resolution`` the check allows what that spacing lets velocity and
    acceleration carry (matters when a phase is many orders of magnitude shorter than its start time).
    """
    s_end, v_end, a_end = piece_end(p)
    s_scale = np.abs(p.s).max(axis=-1, keepdims=True)
    v_scale = np.abs(np.concatenate([p.v, v_end], axis=-1)).max(axis=-1, keepdims=True)
    a_scale = np.abs(np.concatenate([p.a, a_end], axis=-1)).max(axis=-1, keepdims=True)
    dt = 4 * np.spacing(np.abs(p.t).max(axis=-1, keepdims=True)) if time_resolution else 0.0
    assert np.all(np.abs(s_end - p.s[..., 1:]) <= REL * s_scale + v_scale * dt)
    assert np.all(np.abs(v_end - p.v[..., 1:]) <= REL * v_scale + a_scale * dt)


def assert_well_formed(p: Pieces, k: int) -> None:
    for x in p:
        assert x.shape == p.t.shape and x.shape[-1] == k
        assert np.all(np.isfinite(x))
    assert np.all(np.diff(p.t, axis=-1) >= 0.0)
    assert np.all(p.v[..., -1] == 0.0) and np.all(p.a[..., -1] == 0.0) and np.all(p.j[..., -1] == 0.0)


def fine_grid(p: Pieces, n: int = 200_001) -> np.ndarray:
    """Uniform times over the motion and a little after, plus every breakpoint."""
    return np.union1d(np.linspace(p.t.min(), p.t.max() * 1.05 + 1e-3, n), p.t.ravel())


# --------------------------------------------------------------------------------------------------------
# trapezoid


def test_trapezoid_matches_closed_form():
    d, v, a = 3.0, 2.0, G
    p = trapezoid(d, v, a)
    assert_well_formed(p, TRAPEZOID_PIECES)
    t_acc = v / a
    np.testing.assert_allclose(p.t[0], [0.0, t_acc, d / v, d / v + v / a], rtol=1e-14)
    np.testing.assert_allclose(p.s[0], [0.0, v**2 / (2 * a), d - v**2 / (2 * a), d], rtol=1e-14)
    np.testing.assert_allclose(p.v[0], [0.0, v, v, 0.0], rtol=1e-14)
    np.testing.assert_array_equal(p.a[0], [a, 0.0, -a, 0.0])
    assert p.s[0, -1] == d
    assert end_time(p)[0] == pytest.approx(d / v + v / a, rel=1e-14)
    # mid-cruise and mid-deceleration by evaluation
    s, vel, acc = evaluate(p, [0.5 * t_acc, 0.75, d / v + 0.5 * t_acc])
    np.testing.assert_allclose(
        s[0],
        [a * (0.5 * t_acc) ** 2 / 2, v**2 / (2 * a) + v * (0.75 - t_acc), d - a * (0.5 * t_acc) ** 2 / 2],
        rtol=1e-13,
    )
    np.testing.assert_allclose(vel[0], [0.5 * v, v, 0.5 * v], rtol=1e-13)
    np.testing.assert_allclose(acc[0], [a, 0.0, -a])


def test_triangular_peak_velocity_is_sqrt_d_a():
    d, v, a = 0.1, 2.0, G  # v^2 / a = 0.204 m > d
    p = trapezoid(d, v, a, start=1.5, s0=-0.2)
    v_peak = math.sqrt(d * a)
    assert v_peak < v
    t_half = math.sqrt(d / a)
    np.testing.assert_allclose(p.t[0], [1.5, 1.5 + t_half, 1.5 + t_half, 1.5 + 2 * t_half], rtol=1e-14)
    assert p.v[0, 1] == pytest.approx(v_peak, rel=1e-14)
    _, vel, _ = evaluate(p, fine_grid(p))
    assert vel.max() == pytest.approx(v_peak, rel=1e-9)
    assert p.s[0, -1] == -0.2 + 0.1
    # at the threshold distance the triangle just touches v_max
    q = trapezoid(v**2 / a, v, a)
    assert q.v[0, 1] == pytest.approx(v, rel=1e-14)
    assert q.t[0, 2] - q.t[0, 1] == pytest.approx(0.0, abs=1e-15)


@pytest.mark.parametrize(
    "build", [lambda: trapezoid(0.0, 1.0, 2.0, 0.3, 0.7), lambda: scurve(0.0, 1.0, 2.0, 5.0, 0.3, 0.7)]
)
def test_zero_distance_stays_at_rest(build):
    p = build()
    np.testing.assert_array_equal(p.t, 0.3)
    np.testing.assert_array_equal(p.s, 0.7)
    for x in (p.v, p.a, p.j):
        np.testing.assert_array_equal(x, 0.0)


# --------------------------------------------------------------------------------------------------------
# S-curve


def measured_peaks(p: Pieces) -> tuple[float, float, float]:
    t = fine_grid(p)
    _, v, a = evaluate(p, t)
    return float(np.abs(v).max()), float(np.abs(a).max()), float(np.abs(p.j).max())


def test_scurve_all_seven_phases():
    d, v, a, j = 3.0, 2.0, G, 500.0
    p = scurve(d, v, a, j)
    assert_well_formed(p, SCURVE_PIECES)
    tj, tca = a / j, v / a - a / j
    durations = np.diff(p.t[0])
    np.testing.assert_allclose(durations, [tj, tca, tj, d / v - v / a - a / j, tj, tca, tj], rtol=1e-12)
    assert end_time(p)[0] == pytest.approx(d / v + v / a + a / j, rel=1e-14)
    v_pk, a_pk, j_pk = measured_peaks(p)
    assert v_pk == pytest.approx(v, rel=1e-12) and v_pk <= v * (1 + REL)
    assert a_pk == pytest.approx(a, rel=1e-12) and a_pk <= a * (1 + REL)
    assert j_pk == j
    assert p.s[0, -1] == d and p.v[0, -1] == 0.0
    assert_continuous(p)


def test_scurve_acceleration_limit_not_reached_when_v_j_below_a_squared():
    d, v, a, j = 3.0, 0.5, G, 500.0  # v j = 250 < a^2 = 385
    p = scurve(d, v, a, j)
    a_peak = math.sqrt(v * j)
    v_pk, a_pk, _ = measured_peaks(p)
    assert a_pk == pytest.approx(a_peak, rel=1e-9)
    assert v_pk == pytest.approx(v, rel=1e-12)
    np.testing.assert_array_equal(np.diff(p.t[0])[[1, 5]], 0.0)
    assert end_time(p)[0] == pytest.approx(d / v + 2 * math.sqrt(v / j), rel=1e-14)
    assert p.s[0, -1] == d


def test_scurve_reduced_velocity_reaching_a_max():
    a, j, v = 10.0, 1000.0, 2.0  # full move needs v (v/a + a/j) = 0.42 m
    d = 0.2  # > 2 a^3 / j^2 = 0.002 m: a_max still reached
    p = scurve(d, v, a, j)
    v_pk, a_pk, _ = measured_peaks(p)
    assert v_pk < v
    assert v_pk**2 / a + v_pk * a / j == pytest.approx(d, rel=1e-9)
    assert p.v[0, 3] ** 2 / a + p.v[0, 3] * a / j == pytest.approx(d, rel=1e-13)
    assert a_pk == pytest.approx(a, rel=1e-12)
    durations = np.diff(p.t[0])
    assert durations[3] == 0.0
    assert end_time(p)[0] == pytest.approx(2 * (p.v[0, 3] / a + a / j), rel=1e-13)
    assert p.s[0, -1] == d and p.v[0, -1] == 0.0
    assert_continuous(p)


def test_scurve_reduced_velocity_below_a_max():
    a, j, v = 10.0, 1000.0, 2.0
    d = 0.001  # < 2 a^3 / j^2 = 0.002 m
    p = scurve(d, v, a, j)
    v_red = (d**2 * j / 4) ** (1 / 3)
    v_pk, a_pk, _ = measured_peaks(p)
    assert v_pk == pytest.approx(v_red, rel=1e-9)
    assert a_pk == pytest.approx(math.sqrt(v_red * j), rel=1e-9) and a_pk < a
    assert end_time(p)[0] == pytest.approx(4 * math.sqrt(v_red / j), rel=1e-13)
    np.testing.assert_array_equal(np.diff(p.t[0])[[1, 3, 5]], 0.0)
    assert p.s[0, -1] == d
    assert_continuous(p)


def test_scurve_regimes_meet_continuously():
    a, j, v = 10.0, 1000.0, 2.0
    d_a = 2 * a**3 / j**2  # boundary between reaching a_max or not
    d_v = v * (v / a + a / j)  # boundary between reaching v_max or not
    p = scurve([d_a * (1 - 1e-9), d_a * (1 + 1e-9), d_v * (1 - 1e-9), d_v * (1 + 1e-9)], v, a, j)
    np.testing.assert_allclose(p.v[0, 3], p.v[1, 3], rtol=1e-8)
    np.testing.assert_allclose(p.v[2, 3], p.v[3, 3], rtol=1e-8)
    np.testing.assert_allclose(end_time(p)[0], end_time(p)[1], rtol=1e-8)
    np.testing.assert_allclose(end_time(p)[2], end_time(p)[3], rtol=1e-8)
    assert p.v[1, 3] == pytest.approx(a * a / j, rel=1e-8)


@pytest.mark.parametrize(
    "build",
    [
        lambda: trapezoid(0.8, 1.5, G, start=0.1, s0=0.05),
        lambda: scurve(0.8, 1.5, G, 800.0, start=0.1, s0=0.05),
        lambda: scurve(0.002, 1.5, G, 800.0),
        lambda: sequence(
            [
                {"move": 0.3, "v_max": 1.0, "a_max": 5.0, "j_max": 200.0},
                {"dwell": 0.1},
                {"move": -0.5, "v_max": 0.8, "a_max": 4.0},
            ]
        ),
    ],
)
def test_integrated_acceleration_reproduces_velocity_and_position(build):
    p = build()
    t = np.linspace(p.t[0, 0], p.t[0, -1] + 0.2, 400_001)
    s, v, a = evaluate(p, t)
    v_int = v[0, 0] + cumulative_trapezoid(a[0], t, initial=0.0)
    s_int = s[0, 0] + cumulative_trapezoid(v[0], t, initial=0.0)
    v_peak = np.abs(v).max()
    travel = np.abs(s - s[0, 0]).max()
    # trapezoid rule over acceleration steps errs by dt * jump / 2 per step
    assert np.abs(v_int - v[0]).max() <= 1e-4 * v_peak
    assert np.abs(s_int - s[0]).max() <= 1e-6 * travel
    assert v[0, -1] == 0.0 and a[0, -1] == 0.0


# --------------------------------------------------------------------------------------------------------
# direction, evaluation, vectorisation


@pytest.mark.parametrize("j_max", [None, 300.0])
def test_negative_distance_mirrors_positive(j_max):
    build = trapezoid if j_max is None else (lambda d, v, a, **kw: scurve(d, v, a, j_max, **kw))
    fwd, back = build(0.37, 1.2, 7.0, s0=0.0), build(-0.37, 1.2, 7.0, s0=0.0)
    np.testing.assert_array_equal(back.t, fwd.t)
    for x, y in zip(back[1:], fwd[1:], strict=True):
        np.testing.assert_array_equal(x, -y)
    assert back.s[0, -1] == -0.37


def test_evaluate_takes_right_limit_and_holds_before_start():
    p = trapezoid(1.0, 1.0, 4.0, start=2.0, s0=0.5)  # accel ends at 2.25 s
    s, v, a = evaluate(p, [0.0, 2.0, 2.25, p.t[0, 2], p.t[0, 3], 100.0])
    np.testing.assert_allclose(s[0], [0.5, 0.5, 0.5 + 0.125, 1.5 - 0.125, 1.5, 1.5], rtol=1e-14)
    np.testing.assert_allclose(v[0], [0.0, 0.0, 1.0, 1.0, 0.0, 0.0], rtol=1e-14, atol=1e-15)
    np.testing.assert_array_equal(a[0], [0.0, 4.0, 0.0, -4.0, 0.0, 0.0])


def random_cases(n: int, seed: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)

    def logu(lo: float, hi: float) -> np.ndarray:
        return 10 ** rng.uniform(math.log10(lo), math.log10(hi), n)

    return {
        "distance": logu(1e-6, 10.0) * rng.choice([-1.0, 1.0], n),
        "v_max": logu(1e-3, 10.0),
        "a_max": logu(1e-2, 100.0),
        "j_max": logu(1e-1, 1e5),
        "start": rng.uniform(0.0, 5.0, n),
        "s0": rng.uniform(-1.0, 1.0, n),
    }


def test_vectorised_call_equals_per_case_calls():
    c = random_cases(1000, seed=7)
    ps = scurve(**c)
    pt = trapezoid(**{k: v for k, v in c.items() if k != "j_max"})
    assert ps.t.shape == (1000, SCURVE_PIECES) and pt.t.shape == (1000, TRAPEZOID_PIECES)
    for i in range(1000):
        one = {k: v[i] for k, v in c.items()}
        qs = scurve(**one)
        qt = trapezoid(**{k: v for k, v in one.items() if k != "j_max"})
        for x, y in zip(ps, qs, strict=True):
            np.testing.assert_array_equal(x[i], y[0])
        for x, y in zip(pt, qt, strict=True):
            np.testing.assert_array_equal(x[i], y[0])
    assert_continuous(ps, time_resolution=True)
    assert_continuous(pt, time_resolution=True)
    np.testing.assert_array_equal(ps.s[:, -1], c["s0"] + c["distance"])


def test_scalar_inputs_broadcast_against_arrays():
    p = trapezoid([0.1, 0.2, 0.3], 1.0, [2.0, 3.0, 4.0])
    assert p.t.shape == (3, TRAPEZOID_PIECES)
    np.testing.assert_allclose(p.v[:, 1], np.minimum(1.0, np.sqrt([0.2, 0.6, 1.2])), rtol=1e-14)


# --------------------------------------------------------------------------------------------------------
# sequences and scans


def test_sequence_concatenates_moves_and_dwells():
    segs = [
        {"move": 0.4, "v_max": 1.0, "a_max": 5.0},
        {"dwell": 0.25},
        {"move": -0.1, "v_max": 0.5, "a_max": 2.0, "j_max": 50.0},
    ]
    p = sequence(segs, start=1.0, s0=0.2)
    assert_well_formed(p, (TRAPEZOID_PIECES - 1) + 1 + (SCURVE_PIECES - 1) + 1)
    first = trapezoid(0.4, 1.0, 5.0, start=1.0, s0=0.2)
    np.testing.assert_array_equal(p.t[0, :3], first.t[0, :3])
    # the dwell holds the first move's exact end point for 0.25 s
    assert p.t[0, 3] == first.t[0, -1] and p.s[0, 3] == 0.2 + 0.4 and p.v[0, 3] == 0.0
    second = scurve(-0.1, 0.5, 2.0, 50.0, start=first.t[0, -1] + 0.25, s0=0.2 + 0.4)
    np.testing.assert_array_equal(p.t[0, 4:], second.t[0])
    np.testing.assert_array_equal(p.s[0, 4:], second.s[0])
    assert p.s[0, -1] == (0.2 + 0.4) - 0.1
    assert end_time(p)[0] == second.t[0, -1]
    assert_continuous(p)
    s, v, _ = evaluate(p, [first.t[0, -1] + 0.1])
    assert s[0, 0] == 0.2 + 0.4 and v[0, 0] == 0.0


def test_sequence_piece_count_is_fixed_by_segments_not_values():
    segs = [
        {"move": np.array([0.0, 1e-5, 2.0]), "v_max": 1.0, "a_max": 3.0, "j_max": None},
        {"dwell": [0.0, 0.1, 0.0]},
    ]
    p = sequence(segs)
    assert p.t.shape == (3, TRAPEZOID_PIECES - 1 + 1 + 1)
    np.testing.assert_array_equal(p.s[:, -1], [0.0, 1e-5, 2.0])
    assert sequence([], s0=0.3).s.tolist() == [[0.3]]


@pytest.mark.parametrize("j_max", [None, 120.0])
def test_scan_returns_to_start(j_max):
    travel, v, a, dwell, repeats = 0.6, 0.5, 3.0, 0.2, 3
    p = scan(travel, v, a, j_max=j_max, dwell=dwell, repeats=repeats, start=0.5)
    k_move = TRAPEZOID_PIECES if j_max is None else SCURVE_PIECES
    assert_well_formed(p, repeats * (2 * (k_move - 1) + 2) + 1)
    assert p.s[0, -1] == 0.0
    move_time = (scurve(travel, v, a, j_max) if j_max else trapezoid(travel, v, a)).t[0, -1]
    assert end_time(p)[0] == pytest.approx(0.5 + repeats * 2 * (move_time + dwell), rel=1e-13)
    # mid-dwell positions alternate exactly between +travel and 0
    cycle = 2 * (move_time + dwell)
    t_mid = [0.5 + r * cycle + move_time + dwell / 2 for r in range(repeats)]
    t_mid += [0.5 + r * cycle + 2 * move_time + 1.5 * dwell for r in range(repeats)]
    s, vel, _ = evaluate(p, t_mid)
    np.testing.assert_allclose(s[0], [travel] * repeats + [0.0] * repeats, atol=1e-15)
    np.testing.assert_array_equal(vel[0], 0.0)
    assert_continuous(p)
    _, vel, acc = evaluate(p, fine_grid(p, 100_001))
    assert np.abs(vel).max() <= v * (1 + REL) and np.abs(acc).max() <= a * (1 + REL)


# --------------------------------------------------------------------------------------------------------
# stacking stages


def test_stack_pads_shorter_stages_with_rest_pieces():
    x = trapezoid([0.3, 0.5], 1.0, 4.0)
    y = scurve(-0.2, 0.8, 3.0, 100.0, s0=0.1)  # one case, repeated
    p = stack([x, y])
    assert p.t.shape == (2, 2, SCURVE_PIECES)
    np.testing.assert_array_equal(p.t[:, 0, 4:], np.repeat(x.t[:, -1:], 4, axis=1))
    np.testing.assert_array_equal(p.s[:, 0, 4:], np.repeat(x.s[:, -1:], 4, axis=1))
    np.testing.assert_array_equal(p.v[:, 0, 3:], 0.0)
    np.testing.assert_array_equal(end_time(p)[:, 0], x.t[:, -1])
    t = np.linspace(0.0, 3.0, 301)
    s_stack, v_stack, _ = evaluate(p, t)
    assert s_stack.shape == (2, 2, 301)
    np.testing.assert_array_equal(s_stack[:, 0], evaluate(x, t)[0])
    np.testing.assert_array_equal(v_stack[1, 1], evaluate(y, t)[1][0])
    assert s_stack[1, 0, -1] == 0.5 and s_stack[0, 1, -1] == pytest.approx(-0.1, abs=1e-16)


# --------------------------------------------------------------------------------------------------------
# validation


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: trapezoid(1.0, 1.0, 0.0), r"^a_max: must be positive and finite, got 0"),
        (lambda: trapezoid(1.0, -2.0, 1.0), r"^v_max: must be positive and finite, got -2"),
        (lambda: trapezoid(1.0, [1.0, np.inf], 1.0), r"^v_max: must be positive and finite, got inf"),
        (lambda: trapezoid(np.nan, 1.0, 1.0), r"^distance: must be finite"),
        (lambda: trapezoid([1.0, 2.0], [1.0, 2.0, 3.0], 1.0), r"^v_max: has 3 values"),
        (lambda: scurve(1.0, 1.0, 1.0, 0.0), r"^j_max: must be positive and finite, got 0"),
        (lambda: scurve(1.0, 1.0, 1.0, np.nan), r"^j_max: must be positive and finite, got nan"),
        (lambda: scan(1.0, 1.0, 1.0, dwell=-0.1), r"^dwell: must be non-negative"),
        (lambda: scan(1.0, 1.0, 1.0, repeats=0), r"^repeats: must be an integer >= 1, got 0"),
        (lambda: scan(1.0, 1.0, 1.0, repeats=1.5), r"^repeats: must be an integer"),
        (lambda: scan(1.0, 1.0, 1.0, j_max=-1.0), r"^j_max: must be positive"),
        (lambda: sequence([{"dwell": -1.0}]), r"^segments\[0\]\.dwell: must be non-negative"),
        (
            lambda: sequence([{"dwell": 1.0}, {"move": 1.0, "v_max": 1.0}]),
            r"^segments\[1\]\.a_max: is required",
        ),
        (
            lambda: sequence([{"move": 1.0, "v_max": 1.0, "a_max": 0.0}]),
            r"^segments\[0\]\.a_max: must be positive",
        ),
        (lambda: sequence([{"move": 1.0, "dwell": 1.0}]), r"^segments\[0\]: must have exactly one"),
        (
            lambda: sequence([{"move": 1.0, "v_max": 1.0, "a_max": 1.0, "vmax": 2.0}]),
            r"^segments\[0\]: unknown keys",
        ),
        (lambda: trapezoid("fast", 1.0, 1.0), r"^distance: must be a number"),
        (lambda: evaluate(trapezoid(1.0, 1.0, 1.0), [np.nan]), r"^t: must be finite"),
    ],
)
def test_bad_input_names_the_argument(call, message):
    with pytest.raises(ValueError, match=message):
        call()


# --------------------------------------------------------------------------------------------------------
# properties over wide ranges

distances = st.floats(1e-6, 10.0).flatmap(lambda d: st.sampled_from([d, -d]))
speeds = st.floats(1e-3, 10.0)
accels = st.floats(1e-2, 100.0)
jerks = st.floats(1e-1, 1e5)
offsets = st.floats(-2.0, 2.0)


def check_limits(p: Pieces, v_max: float, a_max: float, j_max: float | None) -> None:
    """Bounds at every breakpoint (velocity and acceleration are monotone within each piece here).

    Values at piece ends are computed over durations known to the float spacing of the start times.
    """
    _, v_end, a_end = piece_end(p)
    dt = 4 * np.spacing(np.abs(p.t).max())
    assert np.abs(p.v).max() <= v_max * (1 + REL)
    assert np.abs(p.a).max() <= a_max * (1 + REL)
    assert np.abs(v_end).max() <= v_max * (1 + REL) + a_max * dt
    assert np.abs(a_end).max() <= a_max * (1 + REL) + (0.0 if j_max is None else j_max * dt)
    if j_max is not None:
        assert np.abs(p.j).max() <= j_max


@settings(max_examples=300, deadline=None)
@given(distances, speeds, accels, offsets, offsets)
def test_trapezoid_properties(d, v, a, start, s0):
    p = trapezoid(d, v, a, start=start, s0=s0)
    assert_well_formed(p, TRAPEZOID_PIECES)
    assert_continuous(p, time_resolution=True)
    check_limits(p, v, a, None)
    assert p.s[0, -1] == s0 + d
    # time-optimal shape: either v_max is reached or there is no cruise
    v_pk = np.abs(p.v).max()
    assert v_pk == pytest.approx(v, rel=1e-12) or p.t[0, 2] == p.t[0, 1]


@settings(max_examples=300, deadline=None)
@given(distances, speeds, accels, jerks, offsets, offsets)
def test_scurve_properties(d, v, a, j, start, s0):
    p = scurve(d, v, a, j, start=start, s0=s0)
    assert_well_formed(p, SCURVE_PIECES)
    assert_continuous(p, time_resolution=True)
    check_limits(p, v, a, j)
    assert p.s[0, -1] == s0 + d
    # the motion is monotone towards the target
    s_all = np.concatenate([p.s, piece_end(p)[0]], axis=-1)
    assert np.all(np.sign(d) * (s_all - s0) >= -REL * (abs(d) + abs(s0)))
    # time-optimal shape: v_max reached or no cruise; a_max reached or no constant-acceleration phase
    dur = np.diff(p.t[0])
    v_pk, a_pk = np.abs(p.v).max(), np.abs(p.a).max()
    assert v_pk == pytest.approx(v, rel=1e-9) or dur[3] == 0.0
    assert a_pk == pytest.approx(a, rel=1e-12) or (dur[1] == 0.0 and dur[5] == 0.0)
    # closed forms of each regime
    dist, duration = abs(d), end_time(p)[0] - start
    if dur[3] > 0.0:  # cruise at v_max
        t_acc = v / a + a / j if v * j >= a * a else 2 * math.sqrt(v / j)
        assert duration == pytest.approx(dist / v + t_acc, rel=1e-9)
    elif dist >= 2 * a**3 / j**2:  # reduced velocity, a_max reached
        v_pk = abs(p.v[0, 3])
        assert v_pk**2 / a + v_pk * a / j == pytest.approx(dist, rel=1e-9)
        assert duration == pytest.approx(2 * (v_pk / a + a / j), rel=1e-9)
    else:  # reduced velocity, a_max not reached
        v_red = (dist**2 * j / 4) ** (1 / 3)
        assert abs(p.v[0, 3]) == pytest.approx(v_red, rel=1e-9)
        assert duration == pytest.approx(4 * math.sqrt(v_red / j), rel=1e-9)


@settings(max_examples=50, deadline=None)
@given(
    st.floats(1e-4, 2.0), speeds, accels, st.one_of(st.none(), jerks), st.floats(0.0, 1.0), st.integers(1, 4)
)
def test_scan_properties(travel, v, a, j, dwell, repeats):
    p = scan(travel, v, a, j_max=j, dwell=dwell, repeats=repeats)
    assert_continuous(p, time_resolution=True)
    check_limits(p, v, a, j)
    assert p.s[0, -1] == 0.0
    assert np.all(p.s >= -REL * travel) and np.all(p.s <= travel * (1 + REL))
