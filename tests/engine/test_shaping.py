"""Input shaping: the shaped profile, the shapers' residual vibration and its insensitivity, and a shaped
move on a one-degree-of-freedom mount against the closed form."""

from __future__ import annotations

import numpy as np
import pytest
from scenes import pieces_array
from test_settling_and_mount_outputs import heave_scene, residual_amplitude

from isolab.engine import profiles, simulate
from isolab.engine.results import OK
from isolab.engine.scene import SceneError


def _residual(kind: str, f: float, zeta: float, r: np.ndarray) -> np.ndarray:
    """Residual vibration of a shaper tuned to ``f`` Hz and ``zeta`` on a mode of ``r f`` Hz, damping
    ``zeta``, relative to one unit impulse: ``|sum A_i e^(zeta w t_i) e^(i w_d t_i)| e^(-zeta w t_N)``."""
    t, a = profiles.shaper_impulses(kind, f, zeta)
    w = 2 * np.pi * f * np.asarray(r)[:, None]
    wd = w * np.sqrt(1 - zeta**2)
    s = (a * np.exp(zeta * w * t) * np.exp(1j * wd * t)).sum(axis=1)
    return np.abs(s) * np.exp(-zeta * w[:, 0] * t[0, -1])


def test_undamped_shapers_have_the_textbook_insensitivity_curves() -> None:
    r = np.linspace(0.5, 1.5, 201)
    # ZV: |cos(pi r / 2)|, ZVD: cos^2(pi r / 2), EI: |(1 + V)/2 cos(pi r) + (1 - V)/2|
    np.testing.assert_allclose(_residual("zv", 3.0, 0.0, r), np.abs(np.cos(np.pi * r / 2)), atol=1e-12)
    np.testing.assert_allclose(_residual("zvd", 3.0, 0.0, r), np.cos(np.pi * r / 2) ** 2, atol=1e-12)
    V = profiles.EI_TOLERANCE
    ei = _residual("ei", 3.0, 0.0, r)
    np.testing.assert_allclose(ei, np.abs((1 + V) / 2 * np.cos(np.pi * r) + (1 - V) / 2), atol=1e-12)
    # ZVD is the less sensitive: at a 20 % frequency error it leaves 9.5 % where ZV leaves 31 %
    at = np.isclose(r, 1.2)
    assert _residual("zvd", 3.0, 0.0, r)[at] == pytest.approx(0.0955, abs=1e-3)
    assert _residual("zv", 3.0, 0.0, r)[at] == pytest.approx(0.309, abs=1e-3)
    # EI holds 5 % over +-14 % of the frequency (its zeros at r = 1 -+ 0.141)
    band = (r >= 0.86) & (r <= 1.14)
    assert ei[band].max() <= V + 1e-12 and ei[np.isclose(r, 1.0)] == pytest.approx(V)


@pytest.mark.parametrize("zeta", [0.0, 0.05, 0.2])
def test_damped_zv_and_zvd_leave_no_residual_at_the_tuned_mode(zeta: float) -> None:
    one = np.array([1.0])
    assert _residual("zv", 4.0, zeta, one)[0] < 1e-14
    assert _residual("zvd", 4.0, zeta, one)[0] < 1e-14
    # ZVD's derivative in the frequency is zero too: a 1 % error leaves under 0.03 %
    assert _residual("zvd", 4.0, zeta, np.array([1.01]))[0] < 3e-4
    assert _residual("zv", 4.0, zeta, np.array([1.01]))[0] > 1e-2


def test_the_shaped_profile_is_the_convolution_and_costs_the_shaper_duration() -> None:
    p = profiles.scurve(0.5, 1.0, 10.0, 500.0, start=0.2)
    for kind, periods in (("zv", 0.5), ("zvd", 1.0), ("ei", 1.0)):
        t, a = profiles.shaper_impulses(kind, 2.0, 0.1)
        q = profiles.shape(p, t, a)
        assert q.n_pieces == p.n_pieces * profiles.SHAPER_IMPULSES
        assert np.all(np.diff(q.t, axis=1) >= 0)
        times = np.linspace(0.0, 2.5, 1001)
        s, v, acc = profiles.evaluate(q, times)
        ref = [sum(a[0, i] * profiles.evaluate(p, times - t[0, i])[k] for i in range(3)) for k in range(3)]
        np.testing.assert_allclose(s, ref[0], atol=1e-12)
        np.testing.assert_allclose(v, ref[1], atol=1e-10)
        np.testing.assert_allclose(acc, ref[2], atol=1e-8)
        # it ends at rest exactly where the profile ends, later by the shaper's duration
        assert q.s[0, -1] == p.s[0, -1] and q.v[0, -1] == 0.0 and q.a[0, -1] == 0.0
        damped_period = 1.0 / (2.0 * np.sqrt(1 - 0.1**2))
        assert profiles.shaped_move_time(p, q)[0] == pytest.approx(periods * damped_period, rel=1e-12)


def test_shaper_inputs_are_checked() -> None:
    with pytest.raises(SceneError, match="shaper.type"):
        profiles.shaper_impulses("zzv", 3.0, 0.0)
    with pytest.raises(SceneError, match="shaper.frequency"):
        profiles.shaper_impulses("zv", 0.0, 0.0)
    with pytest.raises(SceneError, match="shaper.damping"):
        profiles.shaper_impulses("zv", 3.0, 1.0)


@pytest.mark.parametrize("kind", ["zv", "zvd", "ei"])
def test_a_shaped_move_on_a_one_mode_mount_leaves_no_residual_vibration(kind: str) -> None:
    """Pure heave at 5 Hz, 5 % damping, shaken by a vertical trapezoidal move: the closed-form residual
    amplitude after the move (the 1-DOF response propagated exactly) is about zero with a ZV or ZVD shaper
    tuned to the mode, 5 % of the shaped single impulse's with EI; the engine (exact discretisation) sees
    the same: the shaped move settles to a thousandth of the unshaped residual at once."""
    w, zeta = 2 * np.pi * 5.0, 0.05
    base = profiles.trapezoid(0.01, 0.1, 2.0, start=0.1)
    t, a = profiles.shaper_impulses(kind, 5.0, zeta)
    shaped = profiles.shape(base, t, a)
    moves = [
        {"mass": 10.0, "home": (0.0, 0.0, 0.0), "axis": (0.0, 0.0, 1.0), "pieces": pieces_array(p)}
        for p in (base, shaped)
    ]
    unshaped_amp = residual_amplitude(zeta, w, moves[0])
    shaped_amp = residual_amplitude(zeta, w, moves[1])
    assert unshaped_amp > 1e-6
    if kind == "ei":
        assert shaped_amp < 0.06 * unshaped_amp
    else:
        assert shaped_amp < 1e-9 * unshaped_amp
    settle = []
    for move in moves:
        b = heave_scene(w, zeta, [move], duration=3.0)
        b.point_settle_tol[:] = unshaped_amp / 1000
        r = simulate(b, "lti", "exact", dt=1e-3)
        assert r.status[0] == OK
        settle.append(r.point_settling_time[0, 0])
    # unshaped: ln(1000) / (zeta w) = 4.4 s would be needed (more than the run); shaped: none
    assert settle[0] > 2.0
    if kind != "ei":
        assert settle[1] == 0.0
