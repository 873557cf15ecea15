"""Study-file inputs of input shaping and of the balanced preload, down to the batch."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from pydantic import ValidationError

from isolab.engine import profiles
from isolab.studies.inputs.parameters import available_paths, resolve
from isolab.studies.inputs.scenes import build_batch
from isolab.studies.inputs.schema import Scene, Simulation
from isolab.studies.inputs.study import load_study

EXAMPLES = Path(__file__).resolve().parents[2] / "studies" / "examples"


def _scene_data(shaper: dict[str, Any] | None = None) -> dict[str, Any]:
    s = yaml.safe_load((EXAMPLES / "article-scriber.yaml").read_text())
    if shaper is not None:
        s["stages"][0]["profile"]["shaper"] = shaper
    return s


def test_a_shaped_scan_is_the_engine_shaping_of_the_unshaped_scan() -> None:
    plain = build_batch([Scene.model_validate(_scene_data())])
    shaped = build_batch(
        [Scene.model_validate(_scene_data({"type": "zvd", "frequency": "3.5 Hz", "damping": "10 %"}))]
    )
    y = profiles.Pieces(
        *(
            np.asarray(x)[:, 0, :]
            for x in (plain.prof_t, plain.prof_s, plain.prof_v, plain.prof_a, plain.prof_j)
        )
    )
    t, a = profiles.shaper_impulses("zvd", 3.5, 0.1)
    want = profiles.shape(y, t, a)
    K = want.n_pieces
    for got, w in zip(
        (shaped.prof_t, shaped.prof_s, shaped.prof_v, shaped.prof_a, shaped.prof_j), want, strict=True
    ):
        np.testing.assert_array_equal(np.asarray(got)[:, 0, :K], w)
    # the move lasts one damped period more (1 / (3.5 Hz sqrt(1 - 0.01)) = 0.287 s)
    assert shaped.last_move_end()[0] - plain.last_move_end()[0] == pytest.approx(1 / (3.5 * np.sqrt(0.99)))
    # the X stage, unshaped, keeps its own pieces
    n = plain.prof_t.shape[-1]
    np.testing.assert_array_equal(np.asarray(shaped.prof_t)[:, 1, :n], plain.prof_t[:, 1, :])


def test_a_bad_shaper_is_refused_naming_the_field() -> None:
    with pytest.raises(ValidationError, match="shaper.type"):
        Scene.model_validate(_scene_data({"type": "zz", "frequency": "3 Hz"}))
    with pytest.raises(ValidationError, match="shaper.frequency"):
        Scene.model_validate(_scene_data({"type": "zv", "frequency": "0 Hz"}))
    with pytest.raises(ValidationError, match="shaper.damping"):
        Scene.model_validate(_scene_data({"type": "zv", "frequency": "3 Hz", "damping": "100 %"}))


def test_a_study_varies_the_shaper_type_frequency_and_the_acceleration() -> None:
    scene = Scene.model_validate(_scene_data({"type": "zv", "frequency": "3.5 Hz", "damping": "10 %"}))
    paths = available_paths(scene)
    for key in ("type", "frequency", "damping"):
        assert f"stages.y.profile.shaper.{key}" in paths
    assert resolve("stages.y.profile.shaper.type", scene).choices == profiles.SHAPERS
    assert "stages.y.profile.shaper.frequency" not in available_paths(Scene.model_validate(_scene_data()))
    study = load_study(
        {
            "name": "shaping",
            "scene": _scene_data({"type": "zv", "frequency": "3.5 Hz", "damping": "10 %"}),
            "parameters": [
                {"path": "stages.y.profile.shaper.type", "values": ["zv", "zvd", "ei"]},
                {"path": "stages.y.profile.shaper.frequency", "values": ["3 Hz", "4 Hz"]},
                {"path": "stages.y.profile.acceleration", "values": ["1 g", "2 g"]},
            ],
            "design": {"type": "grid"},
        }
    )
    assert study.n_cases == 12
    b = study.batch(np.arange(12))
    ends = b.last_move_end()
    # every shaped end differs from the unshaped one by the shaper's duration: half or a whole period
    plain = build_batch([Scene.model_validate(_scene_data())]).last_move_end()[0]
    extra = ends - plain
    assert extra.min() > 0.0 and extra.max() > extra.min()


def test_the_balanced_preload_reaches_the_batch_and_is_a_nonlinear_choice() -> None:
    sim = Simulation.model_validate({"fidelity": "nonlinear", "integrator": "rk4", "preload": "balanced"})
    b = build_batch([Scene.model_validate(_scene_data())], simulation=sim)
    assert b.preload_balanced is True and b.preload_with_base is False
    with pytest.raises(ValidationError, match="simulation.preload"):
        Simulation.model_validate({"fidelity": "ltv", "preload": "balanced"})
    assert build_batch([Scene.model_validate(_scene_data())]).preload_balanced is False
