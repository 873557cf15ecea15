"""Integrators against the adaptive reference: observed convergence orders, and the exact LTI step.

The orders are measured on a scene whose profile breakpoints all land on steps: dyadic step sizes
(1/128 s down to 1/2048 s) and breakpoints at multiples of 1/128 s, so every time involved is exact in
binary floating point.
"""

from __future__ import annotations

import numpy as np
import pytest
from scenes import pieces_array, scene, trapezoid_pieces

from isolab.engine import simulate
from isolab.engine.integrators import INTEGRATORS
from isolab.engine.profiles import scurve, trapezoid

H0 = 1 / 128  # coarsest step, s (7.8 ms)
LEVELS = 5  # H0 / 2^k for k = 0..4: 7.8 ms down to 0.49 ms
POINT = (1.3, 2.1, 0.2)  # a point of interest near a corner: sees translation and rotation


def _on_grid_scene():
    # a = 25.6 m/s^2 and v = 2 m/s: t_acc = 10/128 s, cruise 48/128 s, travel 0.90625 m
    stage = {
        "mass": 1000.0,
        "home": (0.4, -0.5, 0.3),
        "axis": (0.0, 1.0, 0.0),
        "pieces": trapezoid_pieces(0.90625, 2.0, 25.6),
    }
    assert np.all(np.mod(stage["pieces"][0], H0) == 0.0)
    # mounts below the c.g. so that translation and rocking couple; fastest mode 6.7 Hz (w H0 = 0.33)
    return scene(duration=0.75, stages=[stage], height=0.3, points=[POINT])


def _errors(fidelity: str, integrator: str) -> np.ndarray:
    """Largest point-displacement error against the reference on the common 1/128 s grid, per step size,
    relative to the peak point displacement."""
    b = _on_grid_scene()
    ref = simulate(b, fidelity, "reference", dt=H0, record=[0]).history["point_displacement"][0, :, 0]
    peak = np.abs(ref).max()
    errs = []
    for k in range(LEVELS):
        r = simulate(b, fidelity, integrator, dt=H0 / 2**k, auto_step=False, record=[0])
        assert r.status[0] == 0, r.message[0]
        p = r.history["point_displacement"][0, :: 2**k, 0]
        assert p.shape == ref.shape
        errs.append(np.abs(p - ref).max() / peak)
    return np.array(errs)


STEPPED = [name for name, m in INTEGRATORS.items() if m.order is not None]


def test_every_fixed_step_method_declares_an_order_and_a_step_matrix() -> None:
    assert sorted(STEPPED) == ["euler", "rk4"]
    for name in STEPPED:
        assert INTEGRATORS[name].guarded and INTEGRATORS[name].step_matrix is not None, name
    assert INTEGRATORS["exact"].exact and not INTEGRATORS["exact"].guarded
    assert INTEGRATORS["exact"].levels == ("lti",)


@pytest.mark.parametrize("fidelity", ["lti", "ltv", "nonlinear"])
@pytest.mark.parametrize("integrator", STEPPED)
def test_observed_order_is_the_declared_order(fidelity: str, integrator: str) -> None:
    errs = _errors(fidelity, integrator)
    orders = np.log2(errs[:-1] / errs[1:])
    # measured: euler 1.04, 1.02, 1.01, 1.00; rk4 4.01 at every halving, on all three levels
    declared = INTEGRATORS[integrator].order
    assert np.all(np.abs(orders - declared) < 0.15 * declared + 0.1), f"errors {errs}, orders {orders}"
    # and the errors are what a user meets at these steps (7.8 ms: euler 10 %, rk4 2e-5 of the peak)
    assert errs[-1] < (2e-2 if integrator == "euler" else 1e-8)


# ------------------------------------------------------------------------------------------- exact LTI
def _stage(mass, home, axis, pieces, parent=-1):
    return {"mass": mass, "home": home, "axis": axis, "pieces": pieces, "parent": parent}


PROFILES = {
    # start times off the grid of every step below, so breakpoints fall inside steps
    "trapezoid": [
        _stage(1000.0, (0.4, -0.5, 0.3), (0, 1, 0), pieces_array(trapezoid(0.9, 2.0, 20.0, start=0.011)))
    ],
    # jerk-limited: the forcing is cubic within a piece
    "scurve": [
        _stage(1000.0, (0.4, -0.5, 0.3), (0, 1, 0), pieces_array(scurve(0.9, 2.0, 20.0, 400.0, start=0.013)))
    ],
    # an X stage riding on a Y stage, both moving at once (Coriolis-free in LTI, but the weights' moments
    # and the forcing of the child follow both travels)
    "gantry": [
        _stage(1500.0, (0.0, -0.8, 0.3), (0, 1, 0), pieces_array(trapezoid(1.2, 1.5, 12.0, start=0.021))),
        _stage(
            300.0, (-0.5, -0.8, 0.5), (1, 0, 0), pieces_array(trapezoid(0.8, 1.0, 9.0, start=0.05)), parent=0
        ),
    ],
}


@pytest.mark.parametrize("dt", [7e-3, 3.3e-3, 1e-3])
@pytest.mark.parametrize("profile", sorted(PROFILES))
def test_exact_lti_matches_the_reference_at_any_step(profile: str, dt: float) -> None:
    b = scene(duration=1.2, stages=PROFILES[profile], height=0.3, points=[POINT])
    ref = simulate(b, "lti", "reference", dt=dt, record=[0])
    ex = simulate(b, "lti", "exact", dt=dt, record=[0])
    assert ref.status[0] == 0 and ex.status[0] == 0
    for key in ("displacement", "rotation", "point_displacement"):
        r, e = ref.history[key][0], ex.history[key][0]
        # measured at most 2.6e-10 (rotation): the reference's own tolerance, rtol 1e-10
        assert np.abs(e - r).max() <= 1e-9 * np.abs(r).max(), key
    np.testing.assert_allclose(ex.peak_displacement, ref.peak_displacement, rtol=1e-9)


def test_reference_accepts_a_breakpoint_a_rounding_error_before_a_sample() -> None:
    # trapezoid(0.9, 2, 20) ends at 0.1 + 0.35 + 0.1 = 0.5499999999999999 s, 1 ulp before the 1 ms sample:
    # the sample must not be asked of the interval that ends at the breakpoint (solve_ivp refuses it)
    pieces = pieces_array(trapezoid(0.9, 2.0, 20.0))
    assert 0.0 < 0.55 - pieces[0, -1] < 1e-12
    b = scene(duration=0.6, stages=[_stage(1000.0, (0.4, -0.5, 0.3), (0, 1, 0), pieces)], height=0.3)
    ref = simulate(b, "lti", "reference", dt=1e-3)
    ex = simulate(b, "lti", "exact", dt=1e-3)
    np.testing.assert_allclose(ref.peak_displacement, ex.peak_displacement, rtol=1e-9)
