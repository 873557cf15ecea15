"""The time-only terms the kernels keep in the workspace do not depend on the order of the calls."""

from __future__ import annotations

import numpy as np
import pytest
from scenes import scene, y_stage

from isolab.engine import model
from isolab.engine.kernels.cached_terms import stages_unchanged
from isolab.engine.kernels.dynamics import derivative
from isolab.engine.kernels.excitation import advance_pieces
from isolab.engine.kernels.params import FIDELITIES, NONLINEAR
from isolab.engine.kernels.structs import kernel_struct


def _batch():
    """Two cases, a stage riding on another, a sine floor and feedforward actuators on one case."""
    child = y_stage(mass=300.0, home=(-0.5, -0.8, 0.5), start=0.05)
    child["axis"] = (1.0, 0.0, 0.0)
    child["parent"] = 0
    b = scene(
        n_cases=2,
        stages=[y_stage(mass=1500.0, home=(0.0, -0.8, 0.3), start=0.021), child],
        height=0.3,
        floor_amp=(1e-4, 0.0, 2e-4),
        floor_freq=(7.0, 0.0, 11.0),
    )
    b.stage_mass[1] *= 1.3
    b.iso_ff_gain[1] = 0.8
    b.iso_ff_bandwidth[1] = 30.0
    return b


@pytest.mark.parametrize("fidelity", sorted(FIDELITIES))
def test_derivative_in_any_order_equals_a_fresh_evaluation(fidelity: str) -> None:
    b = _batch()
    level = FIDELITIES[fidelity]
    P = kernel_struct(model.params(b))
    W = kernel_struct(model.work(b))
    rng = np.random.default_rng(1)
    nx = 13 if level == NONLINEAR else 12
    times = rng.uniform(0.0, 2.0, 12)
    calls = [(c, t, rng.normal(scale=1e-4, size=nx)) for c in (0, 1) for t in times for _ in range(2)]
    calls += calls[::3]  # repeated times: the kept terms are used
    rng.shuffle(calls)
    for c, t, x in calls:
        if level == NONLINEAR:
            x[3:7] = [1.0, 1e-4, -2e-4, 3e-4]  # the integrators' stages see a quaternion off unit length
        idx = np.full(b.n_stages, -1, dtype=np.int64)
        advance_pieces(P, c, t, idx, 0.0)
        kept, fresh = np.zeros(nx), np.zeros(nx)
        assert derivative(P, c, level, t, x, idx, W, kept)
        assert derivative(P, c, level, t, x, idx, kernel_struct(model.work(b)), fresh)
        assert np.array_equal(kept, fresh), (c, t)


def test_the_terms_are_kept_only_for_the_same_stage_state_bit_for_bit() -> None:
    """The nonlinear RK4 step keeps the time-only terms where the stages' state is bit for bit the one they
    were evaluated from, for the same case and level (``cached_terms.stages_unchanged``); a zero of the
    other sign, another case or another level evaluates them again."""
    key = np.array([3.0, float(NONLINEAR), 0.25, 1.0, 2.0])
    sw = np.arange(18.0).reshape(2, 9) - 4.0
    assert stages_unchanged(3, NONLINEAR, key, sw.copy(), sw)
    moved = sw.copy()
    moved[1, 8] = np.nextafter(moved[1, 8], np.inf)
    assert not stages_unchanged(3, NONLINEAR, key, moved, sw)
    signed = sw.copy()
    signed[0, 4] = -0.0  # sw[0, 4] is +0.0
    assert not stages_unchanged(3, NONLINEAR, key, signed, sw)
    assert not stages_unchanged(2, NONLINEAR, key, sw.copy(), sw)
    assert not stages_unchanged(3, NONLINEAR - 1, key, sw.copy(), sw)
    nan = sw.copy()
    nan[0, 0] = np.nan
    assert not stages_unchanged(3, NONLINEAR, key, nan, nan.copy())
