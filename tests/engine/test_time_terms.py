"""The time-only terms the kernels keep in the workspace do not depend on the order of the calls; the mass
matrix's Schur complement they keep is inverted to round-off and refused where it is not positive definite;
the nonlinear level's rotation matrix is orthogonal whatever its quaternion's length."""

from __future__ import annotations

import numpy as np
import pytest
from scenes import scene, y_stage

from isolab.engine import model
from isolab.engine.kernels.cached_terms import (
    CC_IMT,
    CC_IN,
    CC_MT,
    TC_JT,
    TC_SI,
    TC_SR,
    moving_terms,
    stages_unchanged,
    terms_at_rest,
    time_terms,
)
from isolab.engine.kernels.dynamics import derivative
from isolab.engine.kernels.excitation import advance_pieces
from isolab.engine.kernels.params import FIDELITIES, LTV, NONLINEAR
from isolab.engine.kernels.rotations import direction_matrix, quat_matrix
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


def _terms_at(P, W, c, level, t, n_stages):
    idx = np.full(n_stages, -1, dtype=np.int64)
    advance_pieces(P, c, t, idx, 0.0)
    assert time_terms(P, c, level, t, idx, W)
    return idx


@pytest.mark.parametrize("fidelity", ["ltv", "nonlinear"])
def test_the_schur_complement_is_inverted_to_round_off(fidelity: str) -> None:
    """The time-varying levels solve their mass matrix through the inverse of its Schur complement
    ``S = J - [SR]x^T [SR]x / m_tot``: ``S`` from the kept ``J`` and ``SR`` times the kept inverse is the
    identity to round-off, at rest and with the stages half-way through their moves."""
    b = _batch()
    P = kernel_struct(model.params(b))
    work = model.work(b)
    W = kernel_struct(work)
    for c in (0, 1):
        for t in (0.0, 0.4, 0.9, 1.7, 3.0):
            _terms_at(P, W, c, FIDELITIES[fidelity], t, b.n_stages)
            tc = work.tc
            sr = tc[TC_SR]
            X = np.array([[0.0, -sr[2], sr[1]], [sr[2], 0.0, -sr[0]], [-sr[1], sr[0], 0.0]])
            S = tc[TC_JT : TC_JT + 3] - X.T @ X / work.cc[CC_MT]
            inverse = tc[TC_SI : TC_SI + 3]
            assert np.allclose(inverse, inverse.T, rtol=0.0, atol=1e-15 * np.abs(inverse).max())
            assert np.abs(S @ inverse - np.eye(3)).max() < 1e-13, (c, t)


@pytest.mark.parametrize(
    "inertia, positive",
    [
        ((2.0, 3.0, 4.0), True),
        ((-2.0, 3.0, 4.0), False),  # the first leading minor
        ((2.0, -3.0, 4.0), False),  # the second
        ((2.0, 3.0, -4.0), False),  # the determinant
        ((2.0, 3.0, np.nan), False),
    ],
)
def test_a_schur_complement_not_positive_definite_is_refused(inertia, positive: bool) -> None:
    """Sylvester's criterion on the leading minors, as the Cholesky factor's pivots were: a mass matrix that
    is not positive definite fails its case instead of giving accelerations."""
    cc = np.zeros(25)
    cc[CC_MT], cc[CC_IMT] = 10.0, 0.1
    cc[CC_IN : CC_IN + 9] = np.diag(inertia).ravel()
    tc = np.zeros((20, 3))
    ok = moving_terms(LTV, 9.81, cc, np.zeros((0, 13)), np.zeros((0, 11)), np.zeros((0, 9)), tc)
    assert ok is positive
    if positive:
        assert np.allclose(tc[TC_SI : TC_SI + 3], np.diag(1.0 / np.array(inertia)), rtol=1e-15, atol=0.0)


def test_terms_are_kept_at_rest_only_where_they_hold_bit_for_bit() -> None:
    """Between moves the nonlinear RK4 step keeps the time-only terms without evaluating the stages
    (``cached_terms.terms_at_rest``): where it does, the terms evaluated afresh at the new time are the
    kept ones bit for bit; while a stage moves, under a floor sine or on another piece it evaluates them."""
    child = y_stage(mass=300.0, home=(-0.5, -0.8, 0.5), start=0.05)
    child["axis"] = (1.0, 0.0, 0.0)
    child["parent"] = 0
    b = scene(n_cases=2, stages=[y_stage(mass=1500.0, home=(0.0, -0.8, 0.3)), child], height=0.3)
    b.floor_amp[1] = (1e-4, 0.0, 0.0)
    b.floor_freq[1] = (7.0, 0.0, 0.0)
    P = kernel_struct(model.params(b))
    work = model.work(b)
    W = kernel_struct(work)
    end = float(np.max(b.prof_t[0]))  # every stage's last piece starts here: at rest from then on
    checked = 0
    for c, t0, t1, holds in (
        (0, end + 0.1, end + 0.37, True),  # both at rest on their last pieces
        (0, 0.3, 0.31, False),  # a stage moves
        (0, -0.01, end + 0.2, False),  # at rest before the profiles start, then on other pieces
        (1, end + 0.1, end + 0.37, False),  # a floor sine moves the floor's rows
    ):
        idx0 = _terms_at(P, W, c, NONLINEAR, t0, b.n_stages)
        idx1 = np.full(b.n_stages, -1, dtype=np.int64)
        advance_pieces(P, c, t1, idx1, 0.0)
        same = np.array_equal(idx0, idx1)
        assert terms_at_rest(c, NONLINEAR, idx1, work.key, work.cc, work.cs) is holds, (c, t0, t1)
        if holds:
            assert same
            fresh = model.work(b)
            _terms_at(P, kernel_struct(fresh), c, NONLINEAR, t1, b.n_stages)
            assert np.array_equal(work.tc, fresh.tc)
            checked += 1
    assert checked == 1


@pytest.mark.parametrize("e", [0.0, 1e-13, -3e-9, 2e-7, -0.3, 1.5])
def test_the_rotation_of_a_quaternion_off_unit_length_is_orthogonal(e: float) -> None:
    """The nonlinear level's accelerations turn by the rotation of the quaternion's direction: orthogonal to
    round-off, and that of the unit quaternion, whether the quaternion is off unit length by an RK4 stage's
    drift or by more."""
    rng = np.random.default_rng(7)
    worst = 0.0
    for _ in range(20):
        q = rng.normal(size=4)
        q *= np.sqrt(1.0 + e) / np.linalg.norm(q)
        R, unit = np.zeros((3, 3)), np.zeros((3, 3))
        direction_matrix(*q, R)
        quat_matrix(*(q / np.linalg.norm(q)), unit)
        worst = max(worst, np.abs(R.T @ R - np.eye(3)).max(), np.abs(R - unit).max())
    assert worst < 1e-15  # 4.5 units in the last place of 1
