"""The reference integrator's sampling in one kernel call per segment gives the outputs the Python loop
over the samples gave, bit for bit: the same observers on the same states, the quaternion normalised by
its norm summed in order (what ``np.linalg.norm`` gives to within round-off: its BLAS dot may sum in
another order on another CPU)."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from isolab.engine import simulate
from isolab.engine.integrators import reference
from isolab.engine.kernels.params import NONLINEAR
from isolab.engine.results import SimulationResult
from isolab.engine.scene import SceneBatch
from tests.engine.scenes import scene, y_stage


def _normalised_in_order(y: np.ndarray) -> None:
    """The quaternion ``y[3:7]`` divided by ``sqrt(q0 q0 + q1 q1 + q2 q2 + q3 q3)`` summed left to right."""
    y[3:7] /= math.sqrt(((y[3] * y[3] + y[4] * y[4]) + y[5] * y[5]) + y[6] * y[6])


def test_the_quaternion_is_normalised_as_numpy_does_it() -> None:
    rng = np.random.default_rng(7)
    for scale in (1e-9, 1e-5, 1e-2, 1.0):
        states = rng.standard_normal((20_000, 13)) * scale
        states[:, 3] += 1.0
        got = states.copy()
        for y in got:
            reference.normalise_quaternion(y)
        want = states.copy()
        for y in want:
            _normalised_in_order(y)
        assert np.array_equal(got, want)
        assert np.abs(np.einsum("ci,ci->c", got[:, 3:7], got[:, 3:7]) - 1.0).max() <= 4 * np.finfo(float).eps
        norms = np.linalg.norm(states[:, 3:7], axis=1)
        np.testing.assert_allclose(got[:, 3:7], states[:, 3:7] / norms[:, None], rtol=4 * np.finfo(float).eps)


def _python_loop(made: dict[int, tuple]) -> Callable[..., int]:
    """``observe_samples`` as a Python loop over the samples: ``watch`` of each column (``made``: the
    arguments each :class:`ReferenceCase` was built from, by its id)."""

    def loop(case: reference.ReferenceCase, times: np.ndarray, states: np.ndarray, step: int) -> int:
        P, W, O, c, level, _ = made[id(case)]
        for j in range(times.size):
            y = states[:, j].copy()
            if level == NONLINEAR:
                _normalised_in_order(y)
            if not reference.watch(P, c, level, times[j], y, W, O, step + j):
                return j
        return times.size

    return loop


def _recording(made: dict[int, tuple]) -> Callable[..., reference.ReferenceCase]:
    """``reference_case`` that keeps the arguments of each case it builds in ``made``."""
    build = reference.reference_case

    def record(*args: object) -> reference.ReferenceCase:
        case = build(*args)
        made[id(case)] = args
        return case

    return record


def _shaken() -> SceneBatch:
    """Two cases: a stage's move on a high c.g. and an offset point, the second on a moving floor."""
    return scene(
        n_cases=2,
        height=0.5,
        stages=[y_stage(travel=1.0, v=1.0, start=0.05)],
        points=[(0.8, 1.2, 0.4)],
        duration=0.6,
        floor_amp=(1e-6, 0.0, 2e-6),
        floor_freq=(7.0, 0.0, 11.0),
    )


def _outputs(r: SimulationResult) -> dict[str, np.ndarray]:
    out = {k: np.asarray(v) for k, v in vars(r).items() if k not in ("history", "message")}
    out |= {f"history.{k}": np.asarray(v) for k, v in (r.history or {}).items()}
    return out


@pytest.mark.parametrize("level", ["lti", "ltv", "nonlinear"])
def test_sampling_in_one_kernel_equals_the_python_loop(level: str, monkeypatch: pytest.MonkeyPatch) -> None:
    b = _shaken()
    got = simulate(b, level, "reference", dt=2e-3, record=[0, 1])
    made: dict[int, tuple] = {}
    monkeypatch.setattr(reference, "reference_case", _recording(made))
    monkeypatch.setattr(reference, "observe_samples", _python_loop(made))
    want = simulate(b, level, "reference", dt=2e-3, record=[0, 1])
    assert list(got.status) == [0, 0]
    g, w = _outputs(got), _outputs(want)
    for name in w:
        assert np.array_equal(g[name], w[name], equal_nan=g[name].dtype.kind == "f"), name
