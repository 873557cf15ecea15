"""Active mounts with feedforward: the stages' inertial wrench fed to the mounts' actuators.

The actuators push on the base with ``gain`` times the opposite of the stages' reaction (``sum m a_rel``
and ``sum m rho x a_rel``), shared over the feedforward mounts by least norm, low-passed at a corner
frequency and clipped per mount and axis. Checked here: gain 0 is the model without feedforward, bit for
bit; full gain at a wide bandwidth cancels the stage-induced motion of the c.g.; the force limit caps the
actuator force, and the base then moves by the share of the stages' force the actuators cannot take.
"""

from __future__ import annotations

import numpy as np
import pytest
from scenes import mount, scene, y_stage

from isolab.engine import GRAVITY, model, simulate
from isolab.engine.kernels.excitation import advance_pieces, stage_state
from isolab.engine.kernels.feedforward import feedforward_forces
from isolab.engine.kernels.structs import kernel_struct
from isolab.engine.scene import SceneError

M, M_STAGE, A_STAGE = 10_000.0, 1000.0, 2 * GRAVITY
RUNS = [
    ("lti", "exact"),
    ("lti", "rk4"),
    ("ltv", "euler"),
    ("ltv", "rk4"),
    ("nonlinear", "rk4"),
]
OUTPUTS = (
    "peak_displacement",
    "peak_rotation",
    "peak_point_displacement",
    "peak_isolator_force",
    "min_isolator_load",
    "rms_displacement",
    "settling_time",
    "point_settling_time",
)


def _scene(gain: float, bandwidth: float = 1e4, limit: float = np.inf, home=(0.0, -1.5, 0.0), **kw):
    """3 Hz, 10 % damped mounts in the c.g. plane under a 10 t base; a 1 t stage moving 3 m along Y at
    2 m/s and 2 g, by default on a line through the c.g. (its inertial force has no moment there)."""
    k, c = mount((M + M_STAGE) / 4, 3.0, 0.1)
    b = scene(mass=M, k=(k, k, k), c=(c, c, c), stages=[y_stage(home=home)], points=[(1.0, 2.0, 0.3)], **kw)
    b.iso_ff_gain[:] = gain
    b.iso_ff_bandwidth[:] = bandwidth
    b.iso_ff_limit[:] = limit
    return b


@pytest.mark.parametrize(("fidelity", "integrator"), RUNS)
def test_gain_zero_is_the_model_without_feedforward(fidelity: str, integrator: str) -> None:
    plain = simulate(_scene(0.0, home=(0.2, -1.5, 0.3)), fidelity, integrator, dt=1e-3)
    # gain 0 with any bandwidth and limit: not a bit changes
    off = simulate(
        _scene(0.0, bandwidth=30.0, limit=10.0, home=(0.2, -1.5, 0.3)), fidelity, integrator, dt=1e-3
    )
    # a gain of 1e-300 runs every line of the feedforward path (filter, distribution, clipping, the
    # exact integrator's ramp) and adds forces far below any number's last bit
    tiny = simulate(_scene(1e-300, bandwidth=30.0, home=(0.2, -1.5, 0.3)), fidelity, integrator, dt=1e-3)
    assert plain.status[0] == 0
    for name in OUTPUTS:
        a, b, t = getattr(plain, name), getattr(off, name), getattr(tiny, name)
        np.testing.assert_array_equal(a, b, err_msg=name)
        np.testing.assert_allclose(t, a, rtol=1e-12, atol=1e-250, err_msg=name)


@pytest.mark.parametrize(("fidelity", "integrator"), RUNS)
def test_full_gain_at_wide_bandwidth_cancels_the_stage_induced_motion(fidelity: str, integrator: str) -> None:
    # A 10 kHz corner lags the stage's force by 16 us: the residual impulse at each of the four
    # acceleration steps is m a / wc, which moves the base by about (w_n / wc) of the stage's own effect
    # (3e-4: a 3000-fold reduction). The step is 0.1 ms so that the fixed-step methods resolve the
    # filter's transient after each step (measured reductions at 1 ms: 170x exact, 520x RK4, 86x Euler).
    off = simulate(_scene(0.0), fidelity, integrator, dt=1e-4)
    on = simulate(_scene(1.0), fidelity, integrator, dt=1e-4)
    assert off.status[0] == 0 and on.status[0] == 0
    y_off, y_on = off.peak_displacement[0, 1], on.peak_displacement[0, 1]
    assert y_off > 5e-3  # millimetres of Y motion without feedforward (measured 7.5 mm)
    assert y_on < y_off / 100, f"{y_off:.3g} -> {y_on:.3g}"


@pytest.mark.parametrize(("fidelity", "integrator"), [("lti", "exact"), ("ltv", "rk4"), ("nonlinear", "rk4")])
def test_without_gravity_full_feedforward_holds_the_base_still_in_every_axis(fidelity, integrator) -> None:
    # no weights: the stages act on the base only through their inertial wrench, here with a moment (the
    # stage runs 0.3 m above and 0.2 m beside the c.g.); fed forward whole, every motion of the base
    # vanishes with it, rotations too
    kw = {"home": (0.2, -1.5, 0.3), "g": 0.0}
    off = simulate(_scene(0.0, **kw), fidelity, integrator, dt=1e-4)
    on = simulate(_scene(1.0, **kw), fidelity, integrator, dt=1e-4)
    for name in ("peak_displacement", "peak_rotation"):
        a, b = getattr(off, name)[0], getattr(on, name)[0]
        assert np.all(b < a.max() / 100), f"{name}: {a} -> {b}"


def _actuator_forces(b, times: np.ndarray) -> np.ndarray:
    """The actuator forces (T, n, 3), N, at ``times`` (s), from the engine's own kernel."""
    P, W = model.params(b), model.work(b)
    KP, KW = kernel_struct(P), kernel_struct(W)
    idx = np.full(b.n_stages, -1, dtype=np.int64)
    out = []
    for t in times:
        advance_pieces(KP, 0, t, idx, 0.0)
        stage_state(KP, 0, t, idx, W.rho, W.vr, W.ar, W.jr)
        feedforward_forces(KP, 0, t, idx, KW)
        out.append(np.array(W.Fa))
    return np.array(out)


def test_force_limit_caps_the_actuators_and_the_base_moves_by_the_rest() -> None:
    limit = 2000.0  # N per mount and axis, against m a / 4 = 4.9 kN wanted in Y
    t = np.linspace(0.0, 2.0, 4001)
    free = _actuator_forces(_scene(1.0), t)
    capped = _actuator_forces(_scene(1.0, limit=limit), t)
    # unlimited: each of the four mounts takes a quarter of the stage's force, in Y only (no moment)
    assert np.abs(free[..., 1]).max() == pytest.approx(M_STAGE * A_STAGE / 4, rel=1e-3)
    assert np.abs(free[..., [0, 2]]).max() < 1e-9 * M_STAGE * A_STAGE
    # limited: never past the limit, and at it while the stage accelerates
    assert np.abs(capped).max() == pytest.approx(limit, rel=1e-12)
    assert np.abs(capped).max() <= limit
    # the base (LTI: linear in the force) moves as under the share of the stage's force the actuators
    # cannot take: 1 - 4 L / (m a) of its motion without feedforward (to the filter's 16 us lag)
    share = 1 - 4 * limit / (M_STAGE * A_STAGE)
    off = simulate(_scene(0.0), "lti", "exact", dt=1e-4).peak_displacement[0, 1]
    lim = simulate(_scene(1.0, limit=limit), "lti", "exact", dt=1e-4).peak_displacement[0, 1]
    full = simulate(_scene(1.0), "lti", "exact", dt=1e-4).peak_displacement[0, 1]
    assert lim == pytest.approx(share * off, rel=5e-3)
    assert lim > 100 * full


def test_exact_integrator_holds_the_filtered_force_to_second_order() -> None:
    # at a realistic 50 Hz corner (w_c h = 0.31 at 1 ms) the exact integrator's first-order hold of the
    # actuator force against RK4 at 0.1 ms (converged): the peaks agree to a few per mille
    b = _scene(0.95, bandwidth=50.0, limit=4000.0, home=(0.2, -1.5, 0.3))
    ref = simulate(b, "lti", "rk4", dt=1e-4)
    ex = simulate(b, "lti", "exact", dt=1e-3)
    np.testing.assert_allclose(ex.peak_displacement[0, 1:], ref.peak_displacement[0, 1:], rtol=5e-3)
    np.testing.assert_allclose(ex.peak_rotation[0], ref.peak_rotation[0], rtol=5e-3)


@pytest.mark.parametrize(
    ("field", "value", "reason"),
    [
        ("iso_ff_gain", -0.5, "negative"),
        ("iso_ff_bandwidth", 0.0, "positive"),
        ("iso_ff_limit", 0.0, "positive"),
        ("iso_ff_limit", np.nan, "+inf"),
    ],
)
def test_bad_feedforward_is_refused_naming_the_field(field: str, value: float, reason: str) -> None:
    b = _scene(1.0)
    getattr(b, field)[0, 2] = value
    with pytest.raises(SceneError) as err:
        simulate(b, "lti", "exact", dt=1e-3)
    assert err.value.field == field and reason in err.value.reason


@pytest.mark.parametrize(("fidelity", "integrator"), [("lti", "exact"), ("ltv", "rk4"), ("nonlinear", "rk4")])
def test_feeding_the_weight_shift_forward_too_holds_the_base_level(fidelity: str, integrator: str) -> None:
    # the stage runs 0.3 m above and 0.2 m beside the c.g.: its travel pitches the base by its weight
    # moment, which the inertial feedforward leaves to the mounts; with ``iso_ff_weight`` the actuators
    # take that too, and the base neither pitches during the move nor stays tilted after it
    kw = {"home": (0.2, -1.5, 0.3)}
    inertial = _scene(1.0, **kw)
    both = _scene(1.0, **kw)
    both.iso_ff_weight[:] = True
    a = simulate(inertial, fidelity, integrator, dt=1e-4)
    b = simulate(both, fidelity, integrator, dt=1e-4)
    assert a.peak_rotation[0, 0] > 1e-3  # a milliradian of pitch from the weight (measured 2.3 mrad)
    assert b.peak_rotation[0, 0] < a.peak_rotation[0, 0] / 100
    # at rest the actuators hold the weight shift: the static offset the settling is measured to is level
    assert np.abs(b.final_displacement[0]).max() < 1e-12
    assert b.settled[0]
