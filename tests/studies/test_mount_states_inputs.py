"""Scene inputs for mounts with internal states: an air spring's orifice with ``model: zener`` and an
``elastomer`` ladder, built into the batch's relaxation branches; bad input refused naming the field."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
import yaml
from pydantic import ValidationError

from isolab.engine import mount_laws, simulate
from isolab.studies.inputs.study import scene_batch, validate_scene

EXAMPLE = Path(__file__).parents[2] / "studies" / "examples" / "article-scriber.yaml"
AIR = {"effective_area": "0.03 m^2", "volume": "20 l", "reservoir_volume": "40 l"}
ORIFICE = {"area": "2 mm^2", "length": "50 mm"}


def scriber(**blocks: object) -> dict:
    data = yaml.safe_load(EXAMPLE.read_text())
    data["isolators"].update(copy.deepcopy(blocks))
    return data


def test_an_orifice_with_model_zener_gives_the_static_spring_and_one_branch() -> None:
    equivalent, _ = scene_batch(validate_scene(scriber(air=dict(AIR, orifice=ORIFICE))))
    batch, _ = scene_batch(validate_scene(scriber(air=dict(AIR, orifice=dict(ORIFICE, model="zener")))))
    load = _loads()
    for j in range(4):
        k0, k1, tau = mount_laws.air_zener(
            load[0, j] / 0.03, 0.03, 0.02, 0.04, mount_laws.orifice_resistance(2e-6, 0.05)
        )
        assert batch.iso_k[0, j, 2] == pytest.approx(k0, rel=1e-12)
        assert batch.iso_c[0, j, 2] == 0.0
        assert batch.iso_branch_k[0, j, 2, 0] == pytest.approx(k1, rel=1e-12)
        assert batch.iso_branch_tau[0, j, 2, 0] == pytest.approx(tau, rel=1e-12)
    assert not batch.iso_branch_k[..., :2, :].any()
    assert not equivalent.has_mount_branches  # the default model stays the equivalent spring-damper
    assert np.array_equal(batch.iso_k[..., :2], equivalent.iso_k[..., :2])


def _loads() -> np.ndarray:
    plain, _ = scene_batch(validate_scene(scriber()))
    return plain.iso_k[..., 2] / (2 * np.pi * 3.5) ** 2 * plain.g  # the air preset's k = (W / g) (2 pi f)^2


def test_the_scriber_on_zener_air_mounts_runs_at_lti_and_agrees_with_its_equivalent() -> None:
    """The orifice's state against the spring-damper tuned at the mounts' vertical frequency: the peak
    displacements agree to 20 %; vertically the Zener mount sinks further, its static spring (spring and
    reservoir sharing their gas) being softer than the equivalent's at the tuned frequency."""
    zener, _ = scene_batch(validate_scene(scriber(air=dict(AIR, orifice=dict(ORIFICE, model="zener")))))
    equivalent, _ = scene_batch(validate_scene(scriber(air=dict(AIR, orifice=ORIFICE))))
    rz = simulate(zener, "lti", "exact", 1e-3)
    re = simulate(equivalent, "lti", "exact", 1e-3)
    assert rz.status[0] == 0, rz.message[0]
    np.testing.assert_allclose(rz.peak_displacement, re.peak_displacement, rtol=0.2, atol=1e-9)
    assert rz.peak_displacement[0, 2] > 1.05 * re.peak_displacement[0, 2]
    # the mounts' peak forces, the branch's spring counted: vertically 1.4 % above the equivalent's
    np.testing.assert_allclose(rz.peak_isolator_force, re.peak_isolator_force, rtol=0.05)


def test_an_elastomer_block_puts_its_ladder_on_every_own_axis() -> None:
    spec = {"loss_factor": 0.1, "stiffening": 1.16, "f_low": "5 Hz", "f_high": "50 Hz"}
    plain, _ = scene_batch(validate_scene(scriber(preset="elastomer")))
    batch, _ = scene_batch(validate_scene(scriber(preset="elastomer", elastomer=spec)))
    _, kb, tau = mount_laws.fit_ladder(0.1, 1.16, 5.0, 50.0, 3)
    live = kb > 0
    np.testing.assert_allclose(batch.iso_branch_k, plain.iso_k[..., None] * kb[live], rtol=1e-12)
    np.testing.assert_allclose(batch.iso_branch_tau[0, 0, 0], tau[live], rtol=1e-12)
    assert np.array_equal(batch.iso_k, plain.iso_k) and not batch.iso_c.any()
    explicit = {"ladder": [{"stiffness_ratio": 0.2, "relaxation_time": "10 ms"}]}
    one, _ = scene_batch(validate_scene(scriber(preset="elastomer", elastomer=explicit)))
    np.testing.assert_allclose(one.iso_branch_k[..., 0], 0.2 * plain.iso_k, rtol=1e-12)
    assert np.all(one.iso_branch_tau == 0.01)


@pytest.mark.parametrize(
    ("blocks", "field"),
    [
        ({"elastomer": {"ladder": [{"stiffness_ratio": 0, "relaxation_time": "1 ms"}]}}, "stiffness_ratio"),
        ({"elastomer": {"ladder": [{"stiffness_ratio": -1, "relaxation_time": "1 ms"}]}}, "stiffness_ratio"),
        ({"elastomer": {"ladder": [{"stiffness_ratio": 1, "relaxation_time": 0}]}}, "relaxation_time"),
        ({"elastomer": {"loss_factor": 0.1}}, "elastomer"),
        ({"elastomer": {"loss_factor": 0.1, "stiffening": 1.1, "f_low": 20, "f_high": 5}}, "f_high"),
        ({"air": dict(AIR, orifice={"area": 0, "length": "5 mm", "model": "zener"})}, "area"),
        ({"air": dict(AIR, orifice=dict(ORIFICE, model="maxwell"))}, "model"),
    ],
)
def test_bad_mount_state_inputs_are_refused_naming_the_field(blocks: dict, field: str) -> None:
    with pytest.raises(ValidationError) as err:
        validate_scene(scriber(**blocks))
    assert field in str(err.value)


def test_the_accuracy_chooser_picks_among_the_pairs_that_model_the_states() -> None:
    """With mounts' states the truth is ltv/rk4 at the finest step (the nonlinear level and the reference
    integrator refuse them), and only lti/exact, lti/rk4 and ltv/rk4 are candidates, costed per state."""
    from isolab.studies.run.accuracy import choose_for_batch
    from isolab.studies.run.costs import step_cost

    batch, _ = scene_batch(validate_scene(scriber(air=dict(AIR, orifice=dict(ORIFICE, model="zener")))))
    choice = choose_for_batch(batch, 0.01, steps=(2e-4, 1e-3))
    assert (choice.fidelity, choice.integrator) in {("lti", "exact"), ("lti", "rk4"), ("ltv", "rk4")}
    assert "ltv/rk4" in choice.reason and "nonlinear" not in choice.reason
    assert {(row["fidelity"], row["integrator"]) for row in choice.pilot} <= {
        ("lti", "exact"),
        ("lti", "rk4"),
        ("ltv", "rk4"),
    }
    assert step_cost("lti", "rk4", 36) > step_cost("lti", "rk4", 4) > step_cost("lti", "rk4")


def test_mount_states_join_a_servo_stage_and_refuse_a_flexible_base_naming_the_field() -> None:
    """The extra linear states of one scene add up: a stage on a servo (2 states) on elastomer ladders (36
    states) runs at lti, the exact and RK4 integrators agreeing; a flexible base is refused beside them."""
    examples = EXAMPLE.parent
    spec = {"loss_factor": 0.1, "stiffening": 1.16, "f_low": "5 Hz", "f_high": "50 Hz"}
    servo = yaml.safe_load((examples / "scriber-servo.yaml").read_text())
    servo["isolators"] = {"preset": "elastomer", "elastomer": spec, "layout": servo["isolators"]["layout"]}
    servo["simulation"]["duration"] = "2.5 s"
    batch, _ = scene_batch(validate_scene(servo))
    assert batch.has_mount_branches and list(batch.servo_stages) == [0]
    exact = simulate(batch, "lti", "exact", 5e-4)
    rk4 = simulate(batch, "lti", "rk4", 1e-4)
    assert exact.status[0] == 0 and rk4.status[0] == 0, (exact.message, rk4.message)
    np.testing.assert_allclose(rk4.peak_displacement, exact.peak_displacement, rtol=1e-3)
    np.testing.assert_allclose(rk4.peak_following_error, exact.peak_following_error, rtol=1e-3)
    assert exact.peak_following_error[0] > 0.0
    flexible = yaml.safe_load((examples / "scriber-flexible-base.yaml").read_text())
    flexible["isolators"] = dict(servo["isolators"])
    both, _ = scene_batch(validate_scene(flexible))
    with pytest.raises(ValueError, match="iso_branch_k.*base_mode_frequency"):
        simulate(both, "lti", "exact", 5e-4)
