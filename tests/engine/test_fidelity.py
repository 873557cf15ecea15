"""The three fidelity levels against each other: they agree as the stage's effect vanishes, and differ
measurably on a soft-mount machine with a long, heavy stroke."""

from __future__ import annotations

import numpy as np
import pytest
from scenes import mount, scene, y_stage

from isolab.engine import GRAVITY, simulate

M = 10_000.0
M_STAGE = 1000.0
LEVELS = ("lti", "ltv", "nonlinear")


def _soft_scene(scale: float, height: float):
    """1 Hz, 10 % damped mounts under a 10 t base; a 1000 kg stage doing a 3 m, 2 m/s, 2 g move.

    ``scale`` multiplies the stage's mass and its travel, speed and acceleration (same timing): the
    forcing falls as scale^2, the stage-dependent terms (mass matrix, rotation) by a further factor.
    """
    load = (M + scale * M_STAGE) / 4
    k, c = mount(load, 1.0, 0.1)
    stage = y_stage(
        mass=scale * M_STAGE, travel=3.0 * scale, v=2.0 * scale, a=2 * GRAVITY * scale, home=(0.0, -1.5, 0.3)
    )
    return scene(
        mass=M,
        k=(k, k, k),
        c=(c, c, c),
        height=height,
        stages=[stage],
        duration=2.0,
        points=[(1.3, 2.1, 0.2)],
    )


def _peaks(scale: float, height: float) -> dict[str, np.ndarray]:
    b = _soft_scene(scale, height)
    out = {}
    for level in LEVELS:
        r = simulate(b, level, "rk4", dt=1e-3)
        assert r.status[0] == 0, r.message[0]
        out[level] = np.concatenate(
            [r.peak_displacement[0], r.peak_rotation[0], r.peak_point_displacement[0, 0]]
        )
    return out


def _rel_diff(p: dict[str, np.ndarray], a: str, b: str) -> float:
    """Largest relative difference of two levels' peaks over the outputs that move (the stage moves in
    the Y-Z plane through x = 0, so x, roll and yaw stay exactly zero)."""
    moving = np.maximum(np.abs(p[a]), np.abs(p[b])) > 0.0
    return float(np.max(np.abs(p[a] - p[b])[moving] / np.abs(p[b])[moving]))


@pytest.mark.parametrize("height", [0.0, 0.4])
def test_levels_agree_as_the_stage_vanishes(height: float) -> None:
    pairs = (("lti", "ltv"), ("nonlinear", "ltv"), ("lti", "nonlinear"))
    coarse, fine = _peaks(1e-2, height), _peaks(1e-3, height)
    for pair in pairs:
        d_coarse, d_fine = _rel_diff(coarse, *pair), _rel_diff(fine, *pair)
        # the levels differ by terms one order higher in the stage's mass, travel or rotation, so the
        # relative difference falls at least linearly with the scale: x10 per decade (measured x10.1 for
        # lti against the others, x10.2 and x79 for nonlinear against ltv); 8 allows for the approach to
        # the asymptote. (Below 1e-3 nonlinear against ltv meets a floor of ~2e-8: the nonlinear level's
        # (R - I) d loses ~1e-16 m to rounding whatever the rotation.)
        assert d_coarse / d_fine > 8.0, f"{pair}: {d_coarse:.3g} -> {d_fine:.3g}"
        # at scale 1e-3 (1 kg moving 3 mm) the levels agree to 0.2 % (measured at most 1.8e-3: heave)
        assert d_fine < 2e-3, f"{pair}: {d_fine:.3g}"


def test_levels_differ_measurably_on_soft_mounts_with_a_long_stroke() -> None:
    # measured (mounts 0.4 m below the c.g.): heave peak lti -94 % against ltv, nonlinear +21 % against
    # ltv; pitch within 0.1 %, Y within 0.4 %
    p = _peaks(1.0, 0.4)
    z, rx = 2, 3
    assert abs(p["lti"][z] - p["ltv"][z]) > 0.5 * p["ltv"][z]
    assert abs(p["nonlinear"][z] - p["ltv"][z]) > 0.1 * p["ltv"][z]
    # the large effects are on heave; the main motions agree to a percent
    for level in ("lti", "nonlinear"):
        assert p[level][1] == pytest.approx(p["ltv"][1], rel=1e-2)
        assert p[level][rx] == pytest.approx(p["ltv"][rx], rel=1e-2)
    # on a 1 Hz mount the base pitches by tens of milliradians: what makes the levels differ
    assert p["ltv"][rx] > 0.01
