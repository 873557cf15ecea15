"""The exact integrator's structured exponential and the linear output map agree with their dense and
general counterparts to round-off."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
from scenes import scene, trapezoid_pieces, y_stage

from isolab.engine import concat, model, simulate
from isolab.engine.integrators import exact
from isolab.engine.integrators.step_maps import top_rows
from isolab.engine.results import OUTPUT_FIELDS
from isolab.studies.inputs.study import load_scene, scene_batch

ARTICLE = Path(__file__).resolve().parents[2] / "studies" / "examples" / "article-scriber.yaml"


def _system(rng: np.random.Generator, f_max: float, zeta: float):
    """A random 6-DOF mass-spring-damper (a21, a22, minv) with modes up to about ``f_max`` Hz."""
    Q, _ = np.linalg.qr(rng.normal(size=(6, 6)))
    M = Q @ np.diag(rng.uniform(1e3, 1e4, 6)) @ Q.T
    w = 2 * np.pi * np.geomspace(f_max / 30, f_max, 6)
    R, _ = np.linalg.qr(rng.normal(size=(6, 6)))
    L = np.linalg.cholesky(M)
    K = L @ R @ np.diag(w**2) @ R.T @ L.T
    Cd = L @ R @ np.diag(2 * zeta * w) @ R.T @ L.T
    minv = np.linalg.inv(M)
    return -minv @ K, -minv @ Cd, minv


@pytest.mark.parametrize("deg", [0, 1, 2, 3])
@pytest.mark.parametrize("wh", [1e-3, 0.3, 3.0, 30.0, 300.0])
def test_structured_exponential_matches_scipy_expm(deg: int, wh: float) -> None:
    """From a tiny step to 300 rad per step on the fastest mode (the scaling-and-squaring branch), lightly
    and heavily damped. Compared in a balanced scaling (velocities per tau = min(h, 1/w), forcing blocks
    per their response), where every block of the map is of order one and scipy's ``expm`` of the
    balanced matrix is accurate to round-off: the difference is within 1e-12 of the largest entry."""
    rng = np.random.default_rng(deg + int(wh * 10))
    for zeta in (0.01, 0.7):
        a21, a22, minv = _system(rng, 100.0, zeta)
        w = 2 * np.pi * 100.0
        h = wh / w
        N = 12 + 6 * (deg + 1)
        out = np.zeros((N, 12))
        T, U = np.zeros((12, N)), np.zeros((12, N))
        top_rows(a21[None], a22[None], minv[None], 0, deg, h, out, T, U)
        tau = min(h, 1 / w)
        mu = np.abs(minv).max()
        scale = np.concatenate(
            [np.ones(6), np.full(6, 1 / tau)] + [np.full(6, 1 / (mu * tau**2 * h**r)) for r in range(deg + 1)]
        )
        Z = np.zeros((N, N))
        Z[:6, 6:12] = np.eye(6)
        Z[6:12, :6] = a21
        Z[6:12, 6:12] = a22
        Z[6:12, 12:18] = minv
        for q in range(deg):
            Z[12 + 6 * q : 18 + 6 * q, 18 + 6 * q : 24 + 6 * q] = np.eye(6)
        balanced = scipy.linalg.expm((Z * scale[None, :] / scale[:, None]) * h)[:12]
        got = out.T * scale[None, :] / scale[:12, None]
        assert np.abs(balanced).max() < 1e4  # the scaling does balance the map (slowest mode: 30x)
        assert np.abs(got - balanced).max() <= 1e-12 * np.abs(balanced).max(), (wh, zeta)
        # and unbalanced, the base's own 12 x 12 block to round-off
        ref = scipy.linalg.expm(Z * h)[:12, :12]
        assert np.abs(out.T[:, :12] - ref).max() <= 1e-12 * np.abs(ref).max()


def test_zero_step_is_the_identity() -> None:
    a21, a22, minv = _system(np.random.default_rng(1), 10.0, 0.1)
    out = np.full((30, 12), np.nan)
    top_rows(a21[None], a22[None], minv[None], 0, 2, 0.0, out, np.zeros((12, 30)), np.zeros((12, 30)))
    assert np.array_equal(out.T, np.eye(12, 30))


def test_split_step_maps_compose_to_the_full_step() -> None:
    """The map to a breakpoint inside a step followed by the map from it to the step's end is the full
    step's map: expm(Z (h - b)) expm(Z b) = expm(Z h), here through the prepared maps of the article."""
    b, _ = scene_batch(load_scene(ARTICLE))
    P = model.params(b)
    dt = np.array([1e-3])
    full, ev, sub_b, sub_a, deg, osc = exact.prepare(P, dt, b.duration)
    assert not osc and np.isfinite(ev[0, 0])
    Z, deg2, _ = exact.augmented(P)
    assert deg2 == deg
    N = Z.shape[-1]
    off = ev[0, 0] - np.floor(ev[0, 0] / dt[0]) * dt[0]
    E_b = scipy.linalg.expm(Z[0] * off)
    E_a = np.vstack([sub_a[0, 0].T, scipy.linalg.expm(Z[0] * (dt[0] - off))[12:]])
    composed = (E_a @ E_b)[:12]
    assert np.abs(composed - full[0].T).max() <= 1e-12 * np.abs(full[0]).max()
    assert full.shape == (1, N, 12)


def test_linear_output_map_gives_the_general_observers_peaks() -> None:
    """A recorded case is observed by engine.kernels.peaks.observe, the others through the output map: the
    same case both ways gives the same peaks, loads, deflections, RMS and settling to round-off, at every
    linear level and method."""
    b, _ = scene_batch(load_scene(ARTICLE))
    b.duration[:] = 3.0
    pair = concat([b, b])
    for fidelity, integrator in (("lti", "exact"), ("lti", "rk4"), ("ltv", "rk4"), ("ltv", "euler")):
        r = simulate(pair, fidelity, integrator, dt=1e-3, record=[0])
        for name in (
            "peak_displacement",
            "peak_rotation",
            "peak_point_displacement",
            "peak_isolator_force",
            "min_isolator_load",
            "max_isolator_load",
            "peak_isolator_deflection",
            "rms_displacement",
            "settling_time",
            "point_settling_time",
        ):
            a = np.asarray(getattr(r, name))
            assert np.all(np.isfinite(a[0])), name
            np.testing.assert_allclose(
                a[1], a[0], rtol=1e-11, atol=1e-15, err_msg=f"{fidelity}/{integrator} {name}"
            )


def test_a_cases_results_do_not_depend_on_its_batch() -> None:
    """A case alone and beside a case under a sine floor motion (which takes the dense exponential and the
    general observer) and one on feedforward actuators (the general step) gives bit-identical results:
    every path is chosen per case, so a study's case equals the case run alone whatever chunk it runs in."""
    from tests.engine.scenes import scene, y_stage

    still = scene(stages=[y_stage()], duration=1.0)
    shaken = scene(stages=[y_stage()], duration=1.0, floor_amp=(0.0, 0.0, 1e-5), floor_freq=(0.0, 0.0, 7.0))
    fed = scene(stages=[y_stage()], duration=1.0)
    fed.iso_ff_gain[:] = 0.8
    fed.iso_ff_bandwidth[:] = 30.0
    for fidelity, integrator in (("lti", "exact"), ("ltv", "rk4")):
        alone = simulate(still, fidelity, integrator, dt=1e-3)
        mixed = simulate(concat([still, shaken, fed]), fidelity, integrator, dt=1e-3)
        assert mixed.peak_displacement[1, 2] > 0.5e-5  # the floor does shake the second case
        assert mixed.peak_displacement[2, 1] < 0.9 * mixed.peak_displacement[0, 1]  # the actuators do act
        for name in ("peak_displacement", "peak_point_displacement", "peak_isolator_force", "settling_time"):
            a, b = np.asarray(getattr(alone, name))[0], np.asarray(getattr(mixed, name))[0]
            assert np.array_equal(a, b), (fidelity, integrator, name)


@pytest.mark.parametrize("deg", [0, 1, 2, 3])
def test_carried_forced_response_matches_the_full_product(deg: int) -> None:
    """The lean whole step, ``x <- Phi x + R_0`` with the piece's forced response carried by its Taylor
    shift (``exact.lean_rows``, ``exact.free_step``), gives what the product with the forcing's
    columns and the forcing's own shift give, to 1e-12 of the state's peak, over 2,000 steps of a piece."""
    rng = np.random.default_rng(7 + deg)
    a21, a22, minv = _system(rng, 20.0, 0.05)
    h = 1e-3
    N = 12 + 6 * (deg + 1)
    ET = np.zeros((N, 12))
    top_rows(a21[None], a22[None], minv[None], 0, deg, h, ET, np.zeros((12, N)), np.zeros((12, N)))
    z = np.zeros(N)
    z[12:] = rng.normal(size=N - 12) * np.repeat(1e3 * 10.0 ** -np.arange(deg + 1), 6)
    x = z[:12].copy()
    L = np.zeros(exact.LEAN_SCRATCH)
    exact.lean_rows(ET, z[12:].copy(), deg, L)
    peak = err = 0.0
    for _ in range(2000):
        z[:12] = ET.T @ z
        exact._shift(z[12:], deg, h)
        exact.free_step(L, x, deg, h)
        peak = max(peak, np.abs(z[:12]).max())
        err = max(err, np.abs(x - z[:12]).max())
    assert peak > 0.0
    assert err <= 1e-12 * peak


def test_lean_exact_step_equals_the_recomputed_forcing_to_round_off() -> None:
    """A recorded floor of zeros (the same physics as no floor) sends every step of ``lti``/``exact``
    through the general step, which builds the forcing anew from the stage kinematics at every step; the
    lean step carries the piece's forced response instead. Every output, peaks, loads, settling times and
    the recorded histories, agrees within 1e-12 of that output's largest magnitude: trapezoid and S-curve
    stages, a case observed through the output map and a recorded one."""
    for pieces in (trapezoid_pieces(0.6, 1.5, 12.0, start=0.0137), None):
        stages = [y_stage(mass=1500.0, home=(0.0, -0.8, 0.3), start=0.0211)]
        if pieces is None:  # jerk-limited: a cubic forcing inside each piece
            b, _ = scene_batch(load_scene(ARTICLE))
            b.duration[:] = 1.5
            lean, general = concat([b, b]), concat([b, b])
        else:
            stages.append(
                {"mass": 400.0, "home": (0.3, -0.8, 0.5), "axis": (1, 0, 0), "pieces": pieces, "parent": 0}
            )
            lean = scene(n_cases=2, stages=stages, duration=1.0, points=[(0.2, 0.3, 0.4)])
            general = scene(n_cases=2, stages=stages, duration=1.0, points=[(0.2, 0.3, 0.4)])
            lean.iso_k[1] *= 1.7
            general.iso_k[1] *= 1.7
        general.floor_t = np.array([0.0, 0.2, 2.0])
        general.floor_disp = np.zeros((2, 3, 3))
        a = simulate(lean, "lti", "exact", 1e-3, record=[1])
        g = simulate(general, "lti", "exact", 1e-3, record=[1])
        assert np.abs(a.peak_displacement).max() > 1e-7  # the stages move the base
        for name in OUTPUT_FIELDS:
            x, y = np.asarray(getattr(a, name), dtype=float), np.asarray(getattr(g, name), dtype=float)
            assert np.array_equal(np.isfinite(x), np.isfinite(y)), name
            scale = np.abs(np.where(np.isfinite(y), y, 0.0)).max(axis=0, initial=0.0)
            diff = np.abs(np.where(np.isfinite(y), x - y, 0.0)).max(axis=0, initial=0.0)
            assert np.all(diff <= 1e-12 * scale), name
        assert a.history is not None and g.history is not None
        for name, values in a.history.items():
            ref = g.history[name]
            assert np.abs(values - ref).max() <= 1e-12 * np.abs(ref).max(), name
