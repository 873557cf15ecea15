"""A block base's elastic modes from the scene (``machine.flexible``): closed forms, the scene path, a
study varying Young's modulus, and the refusal where the model does not exist."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from isolab.engine import simulate
from isolab.studies.inputs.parameters import available_paths, resolve
from isolab.studies.inputs.precision.base_flexibility import beam_shape, block_modes
from isolab.studies.inputs.scenes import build_batch
from isolab.studies.inputs.study import load_scene, scene_batch

EXAMPLE = "studies/examples/scriber-flexible-base.yaml"


def test_the_scriber_blocks_first_bending_mode_is_the_free_free_beams():
    """``f = (4.7300^2 / (2 pi L^2)) sqrt(E I / (rho A))`` for the 4.2 x 2.6 x 0.34 m granite block at
    50 GPa: 85.3 Hz, the order the article's machine has; the modal mass of a shape scaled to 1 at its
    ends is a quarter of the block's (the free-free shape is 2 at its ends and its mean square is 1)."""
    L, b, h, rho, E = 4.2, 2.6, 0.34, 2700.0, 50e9
    I_over_A = (b * h**3 / 12) / (b * h)
    expected = 4.7300**2 / (2 * np.pi * L**2) * np.sqrt(E * I_over_A / rho)
    freq, _, mass = block_modes(
        np.array([[b, L, h]]), np.array([rho]), np.zeros((1, 3)), np.array([E]), np.array([0.25])
    )
    assert expected == pytest.approx(85.26, abs=0.05)
    assert freq[0, 0] == pytest.approx(expected, rel=1e-4)
    assert freq[0, 1] == pytest.approx(expected * (L / b) ** 2, rel=1e-4)  # across the short side
    assert 60.0 < freq[0, 2] < 100.0  # the first torsion mode, same order
    block = rho * L * b * h
    assert mass[0, 0] == pytest.approx(block / 4, rel=0.02)
    assert beam_shape(np.array([0.0, 1.0])) == pytest.approx([2.0, 2.0], rel=1e-12)


def test_the_scene_gives_the_batch_its_modes_and_a_study_may_vary_youngs_modulus():
    scene = load_scene(EXAMPLE)
    batch, _ = scene_batch(scene)
    assert batch.n_base_modes == 3
    assert np.sort(batch.base_mode_frequency[0]) == pytest.approx([80.49, 85.26, 222.48], abs=0.05)
    path = "machine.flexible.young_modulus"
    assert path in available_paths(scene)
    assert resolve(path, scene).dimension == "pressure"
    varied = build_batch([scene], {path: np.array([25e9, 100e9])})
    ratio = varied.base_mode_frequency[1] / varied.base_mode_frequency[0]
    assert ratio == pytest.approx(np.full(3, 2.0), rel=1e-12)  # f ~ sqrt(E)


def test_the_flexible_scriber_runs_and_its_tool_sees_the_block_bend():
    """The Y stage's 2 g force, 0.3 m above the block's neutral plane, bends the block: the tool's peak
    changes by a measurable amount against the rigid block, at lti/exact and ltv/rk4."""
    scene = load_scene(EXAMPLE)
    rigid_data = yaml.safe_load(open(EXAMPLE))
    del rigid_data["machine"]["flexible"]
    rigid, _ = scene_batch(load_scene(rigid_data))
    flexible, names = scene_batch(scene)
    for fidelity, integrator in (("lti", "exact"), ("ltv", "rk4")):
        r = simulate(flexible, fidelity=fidelity, integrator=integrator, dt=5e-4)
        r0 = simulate(rigid, fidelity=fidelity, integrator=integrator, dt=5e-4)
        assert r.status[0] == 0, r.message[0]
        diff = np.abs(r.peak_point_displacement[0] - r0.peak_point_displacement[0]).max()
        assert 1e-7 < diff < 1e-4, (fidelity, diff)


def test_the_nonlinear_level_refuses_a_flexible_base_naming_the_input():
    batch, _ = scene_batch(load_scene(EXAMPLE))
    from isolab.engine.scene import SceneError

    with pytest.raises(SceneError, match="lti and ltv levels"):
        simulate(batch, fidelity="nonlinear", integrator="rk4")


def test_a_flexible_base_needs_a_block():
    data = yaml.safe_load(open("studies/examples/article-scriber.yaml"))
    data["machine"] = {"mass": 10000, "cg": [1.3, 2.1, 0.17], "inertia_diagonal": [1.5e4, 5.7e3, 2e4]}
    data["machine"]["flexible"] = {"young_modulus": "50 GPa"}
    with pytest.raises(Exception, match="machine.flexible"):
        load_scene(data)
