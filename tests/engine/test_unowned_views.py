"""The nonlinear level's RK4 step and observer read their arrays through views numba does not
reference-count (``engine.kernels.params.borrowed``): the views must be the arrays themselves, and the lean
step must compute what the general step computes (to the round-off of its contracted multiply-adds)."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit
from scenes import scene, y_stage

from isolab.engine import simulate
from isolab.engine.kernels.params import borrowed
from isolab.engine.results import OUTPUT_FIELDS

CONTRACTION_TOLERANCE = 1e-11
"""Largest difference the nonlinear RK4 driver's contracted multiply-adds may make to an output, relative
to that output's peak (they measure about 1e-15; RK4's own truncation error is orders larger)."""


@njit(cache=False)
def _write_through(a):
    v = borrowed(a)
    v[1, 2] = 7.5
    s = 0.0
    for i in range(v.shape[0]):
        for j in range(v.shape[1]):
            s += v[i, j]
    return s, v.shape[0], v.shape[1]


def test_a_borrowed_view_reads_and_writes_its_array() -> None:
    a = np.arange(12.0).reshape(3, 4)
    total, rows, cols = _write_through(a)
    assert a[1, 2] == 7.5
    assert (rows, cols) == (3, 4)
    assert total == a.sum()


@pytest.mark.parametrize(
    "move",
    [
        {},  # moving to the end
        {"travel": 0.05, "v": 0.5, "a": 5.0},  # at rest from about 0.14 s: the time-only terms are kept
    ],
)
def test_lean_nonlinear_step_equals_the_general_step(move: dict) -> None:
    """A recorded floor that moves only after the run's end sends a case through the general RK4 step (the
    recorded floor's path) with the same physics as no floor at all. The lean step (inlined into the
    driver, which contracts its multiply-adds; it keeps the time-only terms while the stages stand still,
    and its observer computes the mount forces in its mount loop) gives every output and history of the
    general step to ``CONTRACTION_TOLERANCE`` of that output's peak; at ``euler`` (no lean step) they are
    bit for bit equal."""
    stage = {"mass": 1500.0, "home": (0.0, -0.8, 0.3), "start": 0.02, **move}
    lean = scene(n_cases=2, stages=[y_stage(**stage)], duration=0.4)
    lean.iso_k[1] *= 1.7
    general = scene(n_cases=2, stages=[y_stage(**stage)], duration=0.4)
    general.iso_k[1] *= 1.7
    general.floor_t = np.array([0.0, 0.5, 1.0])  # zero up to 0.5 s (linear between samples), the run 0.4 s
    general.floor_disp = np.zeros((2, 3, 3))
    general.floor_disp[:, 2, 2] = 1e-3
    for integrator in ("rk4", "euler"):
        a = simulate(lean, "nonlinear", integrator, 1e-3, record=[1])
        b = simulate(general, "nonlinear", integrator, 1e-3, record=[1])
        assert np.all(np.isfinite(a.peak_displacement))
        assert np.abs(a.peak_displacement).max() > 1e-7  # the stage moves the base
        assert a.history is not None and b.history is not None
        pairs = [(name, getattr(a, name), getattr(b, name)) for name in OUTPUT_FIELDS]
        pairs += [(f"history {name}", values, b.history[name]) for name, values in a.history.items()]
        for name, x, y in pairs:
            if integrator == "euler":
                assert np.array_equal(x, y, equal_nan=True), (integrator, name)
            else:
                assert_within_peak(x, y, CONTRACTION_TOLERANCE, (integrator, name))


def assert_within_peak(x: np.ndarray, y: np.ndarray, rel: float, label: object) -> None:
    """``x`` equals ``y`` to ``rel`` of the largest finite ``|y|`` (floats; other kinds exactly), with the
    same entries finite."""
    x, y = np.asarray(x), np.asarray(y)
    if y.dtype.kind != "f":
        assert np.array_equal(x, y), label
        return
    finite = np.isfinite(y)
    assert np.array_equal(np.isfinite(x), finite), label
    assert np.array_equal(x[~finite], y[~finite], equal_nan=True), label
    scale = np.abs(y[finite]).max(initial=0.0)
    assert np.all(np.abs(x[finite] - y[finite]) <= rel * scale), (label, np.abs(x[finite] - y[finite]).max())


def test_a_case_steps_as_it_would_alone_beside_a_recorded_floor() -> None:
    """The lean step is chosen per case: a case without a recorded floor gives bit for bit what it gives in
    a batch with no recorded floor at all when another case of its batch has one (the lean step equals the
    general one only to round-off)."""
    stage = {"mass": 1500.0, "home": (0.0, -0.8, 0.3), "start": 0.02}
    mixed = scene(n_cases=3, stages=[y_stage(**stage)], duration=0.4)
    mixed.floor_t = np.array([0.0, 0.1, 0.4])
    mixed.floor_disp = np.zeros((3, 3, 3))
    mixed.floor_disp[1, 0, 1] = 1e-4  # the middle case's floor moves
    alone = scene(n_cases=3, stages=[y_stage(**stage)], duration=0.4)
    a = simulate(mixed, "nonlinear", "rk4", 1e-3)
    b = simulate(alone, "nonlinear", "rk4", 1e-3)
    assert not np.array_equal(a.peak_displacement[1], b.peak_displacement[1])  # the floor moved case 1
    for name in OUTPUT_FIELDS:
        for c in (0, 2):
            assert np.array_equal(getattr(a, name)[c], getattr(b, name)[c], equal_nan=True), (name, c)
