"""Study-file inputs of the active mounts' feedforward and of the preload choice, down to the batch."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
import yaml
from pydantic import ValidationError

from isolab.studies.inputs.isolators import PRESETS
from isolab.studies.inputs.scenes import build_batch
from isolab.studies.inputs.schema import Scene, Simulation

EXAMPLES = Path(__file__).resolve().parents[2] / "studies" / "examples"


def _scene(**iso) -> Scene:
    s = yaml.safe_load((EXAMPLES / "article-scriber.yaml").read_text())
    s["isolators"].update(iso)
    return Scene.model_validate(s)


def test_active_preset_feeds_forward_and_passive_presets_do_not() -> None:
    ff = PRESETS["active"].feedforward
    assert 0.9 <= ff.gain <= 1.0 and 10.0 <= ff.bandwidth < 100.0 and 1e3 <= ff.force_limit <= 1e4
    b = build_batch([_scene(preset="active")])
    np.testing.assert_array_equal(b.iso_ff_gain, np.full((1, 4), ff.gain))
    np.testing.assert_array_equal(b.iso_ff_bandwidth, np.full((1, 4), ff.bandwidth))
    np.testing.assert_array_equal(b.iso_ff_limit, np.full((1, 4), ff.force_limit))
    for preset in ("air", "elastomer"):
        assert PRESETS[preset].feedforward is None
        b = build_batch([_scene(preset=preset)])
        assert not b.has_feedforward
        assert np.all(b.iso_ff_limit == np.inf)


def test_group_feedforward_with_units_overrides_the_preset_and_gain_zero_turns_it_off() -> None:
    b = build_batch(
        [_scene(preset="active", feedforward={"gain": 1, "bandwidth": "0.2 kHz", "force_limit": "3 kN"})]
    )
    np.testing.assert_array_equal(b.iso_ff_gain[0], 1.0)
    np.testing.assert_array_equal(b.iso_ff_bandwidth[0], 200.0)
    np.testing.assert_array_equal(b.iso_ff_limit[0], 3000.0)
    b = build_batch([_scene(preset="active", feedforward={"gain": 0})])
    assert not b.has_feedforward
    # air mounts with actuators: a group feedforward applies whatever the preset
    b = build_batch([_scene(preset="air", feedforward={})])
    np.testing.assert_array_equal(b.iso_ff_gain[0], 1.0)
    assert np.all(b.iso_ff_limit == np.inf)


def test_the_active_preset_levels_the_weight_shift_unless_told_not_to() -> None:
    assert PRESETS["active"].feedforward.weight is True
    assert build_batch([_scene(preset="active")]).iso_ff_weight.all()
    b = build_batch([_scene(preset="active", feedforward={"weight": False})])
    assert not b.iso_ff_weight.any()


def test_tuning_sets_a_types_feedforward() -> None:
    b = build_batch(
        [_scene(preset="active", tuning={"active": {"feedforward": {"gain": 0.5, "bandwidth": "20 Hz"}}})]
    )
    np.testing.assert_array_equal(b.iso_ff_gain[0], 0.5)
    np.testing.assert_array_equal(b.iso_ff_bandwidth[0], 20.0)


@pytest.mark.parametrize(
    ("value", "field"),
    [
        ({"gain": -0.1}, "gain"),
        ({"gain": 2}, "gain"),
        ({"bandwidth": "0.1 Hz"}, "bandwidth"),
        ({"force_limit": "0 N"}, "force_limit"),
        ({"bandwidth": "5 m"}, "bandwidth"),
    ],
)
def test_bad_feedforward_is_refused_naming_the_field(value: dict, field: str) -> None:
    with pytest.raises(ValidationError) as err:
        _scene(preset="active", feedforward=value)
    assert field in str(err.value)


def test_preload_defaults_to_floor_and_base_reaches_the_batch_at_the_nonlinear_level_only() -> None:
    assert Simulation().preload == "floor"
    assert build_batch([_scene()]).preload_with_base is False
    sim = Simulation(fidelity="nonlinear", preload="base")
    assert build_batch([_scene()], simulation=sim).preload_with_base is True
    for bad in ({"fidelity": "ltv", "preload": "base"}, {"accuracy": "fast", "preload": "base"}):
        with pytest.raises(ValidationError, match="simulation.preload"):
            Simulation(**bad)
    with pytest.raises(ValidationError):
        Simulation(fidelity="nonlinear", preload="tilted")


def test_scenes_of_one_batch_must_agree_on_the_preload() -> None:
    a = copy.deepcopy(_scene())
    b = _scene()
    a.simulation = Simulation(fidelity="nonlinear", preload="base")
    b.simulation = Simulation(fidelity="nonlinear")
    with pytest.raises(ValueError, match="simulation.preload"):
        build_batch([a, b])


def test_a_listed_mount_takes_its_own_feedforward_then_its_presets_then_the_groups() -> None:
    s = yaml.safe_load((EXAMPLES / "article-scriber.yaml").read_text())
    pos = [[0.2, 0.3, -0.33], [2.4, 0.3, -0.33], [2.4, 3.9, -0.33], [0.2, 3.9, -0.33]]
    s["isolators"] = {
        "preset": "air",
        "feedforward": {"gain": 0.8},
        "list": [
            {"position": pos[0], "feedforward": {"gain": 0.5}},  # its own
            {"position": pos[1], "preset": "elastomer"},  # its own preset's: none
            {"position": pos[2], "preset": "active"},  # its own preset's
            {"position": pos[3]},  # the group's
        ],
    }
    b = build_batch([Scene.model_validate(s)])
    np.testing.assert_array_equal(b.iso_ff_gain[0], [0.5, 0.0, PRESETS["active"].feedforward.gain, 0.8])
    np.testing.assert_array_equal(b.iso_ff_limit[0, [0, 1, 3]], np.inf)
