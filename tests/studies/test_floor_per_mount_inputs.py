"""The floor under each mount as a scene input: per-mount spectra, a travelling wave, the coherence."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
import yaml
from pydantic import ValidationError

from isolab.engine import frequency
from isolab.studies.answers.floor_response import velocity_spectra
from isolab.studies.inputs.scenes import build_batch
from isolab.studies.inputs.schema import Scene, error_messages
from isolab.studies.inputs.study import load_scene
from isolab.studies.questions import floor

EXAMPLES = Path(floor.__file__).parents[1] / "examples"
VCD = {"x": "VC-D", "y": "VC-D", "z": "VC-D"}


def scriber(**floor_block) -> dict:
    d = yaml.safe_load((EXAMPLES / "article-scriber.yaml").read_text())
    d["floor"] = floor_block
    return d


def errors(data: dict) -> list[str]:
    with pytest.raises(ValidationError) as exc:
        Scene.model_validate(data)
    return error_messages(exc.value)


def bands(data: dict) -> np.ndarray:
    return frequency.batch_point_band_velocity(build_batch([load_scene(data)]))


def test_infinite_wave_speed_is_the_uniform_floor():
    uniform = bands(scriber(spectrum=VCD))
    # the units refuse an infinite number: 1e300 m/s is one to round-off; 1e12 m/s still shifts the
    # phase by w tau ~ 1e-9 rad, which shows where the tool's response is a difference of large terms
    for speed, rtol in (("1e300 m/s", 1e-13), ("1e12 m/s", 1e-8)):
        data = scriber(spectrum=VCD, wave={"speed": speed, "direction": [1, 1]})
        b = build_batch([load_scene(data)])
        assert b.has_mount_floor
        got = frequency.batch_point_band_velocity(b)
        assert np.allclose(got, uniform, rtol=rtol, atol=0.0), speed
    # a slow wave (300 m/s: 1.2 m of the 3.6 m span is 4 ms) changes the answer
    slow = bands(scriber(spectrum=VCD, wave={"speed": "300 m/s", "direction": [0, 1]}))
    assert not np.allclose(slow, uniform, rtol=1e-3)


def test_per_mount_spectra_identical_equal_the_uniform_floor_and_scale():
    uniform = bands(scriber(spectrum=VCD))
    same = bands(scriber(per_mount=[VCD] * 4))
    assert np.allclose(same, uniform, rtol=1e-10, atol=0.0)
    # one level lower (VC-E, half of VC-D) under every mount halves the answer
    quieter = {a: "VC-E" for a in "xyz"}
    half = bands(scriber(per_mount=[quieter] * 4))
    assert np.allclose(half, uniform * 3.12 / 6.25, rtol=1e-10)


def test_coherence_ordering_on_the_scriber():
    out = {
        c: bands(scriber(spectrum=VCD, coherence=c)) for c in ("correlated", "uncorrelated", "worst_phase")
    }
    tol = 1 + 1e-12
    assert (out["worst_phase"] * tol >= out["correlated"]).all()
    assert (out["worst_phase"] * tol >= out["uncorrelated"]).all()
    # uncorrelated mounts: the heave-dominated bands of the tool see less than the in-phase floor
    assert out["uncorrelated"][0, 0, 2].max() < out["correlated"][0, 0, 2].max()


def test_velocity_spectra_follow_the_coherence():
    corr = velocity_spectra(scriber(spectrum=VCD), point="tool")["worst"]
    worst = velocity_spectra(scriber(spectrum=VCD, coherence="worst_phase"), point="tool")["worst"]
    (t,) = corr
    assert worst[t][0] >= corr[t][0]


@pytest.mark.parametrize(
    ("block", "expected"),
    [
        ({"per_mount": [VCD] * 3}, "floor.per_mount: 3 spectra for 4 mounts"),
        ({"spectrum": VCD, "wave": {"speed": "0 m/s"}}, "floor.wave.speed"),
        ({"spectrum": VCD, "wave": {"speed": "-300 m/s"}}, "floor.wave.speed"),
        ({"spectrum": VCD, "wave": {"speed": "300 m/s", "direction": [0, 0]}}, "floor.wave.direction"),
        ({"spectrum": VCD, "per_mount": [VCD] * 4}, "floor.per_mount: give either spectrum"),
        ({"spectrum": VCD, "coherence": "partly"}, "floor.coherence"),
        ({"spectrum": VCD, "coherence": "uncorrelated", "wave": {"speed": 300}}, "floor.coherence"),
        (
            {"coherence": "uncorrelated", "sine": {"amplitude": [0, 0, 1e-6], "frequency": [0, 0, 5]}},
            "floor:",
        ),
    ],
)
def test_refusals_name_the_field(block, expected):
    msgs = errors(scriber(**block))
    assert any(expected in m for m in msgs), msgs


def test_study_floor_with_wrong_length_is_refused():
    from isolab.studies.inputs.study import Study

    sc = scriber(spectrum=VCD)
    study = {"name": "s", "scene": sc, "floor": {"per_mount": [VCD] * 5}}
    with pytest.raises(ValidationError) as exc:
        Study.model_validate(copy.deepcopy(study))
    assert any("floor.per_mount: 5 spectra for 4 mounts" in m for m in error_messages(exc.value))


def test_floor_cli_compares_coherences(tmp_path: Path):
    from typer.testing import CliRunner

    from isolab.service.cli import app

    scene = tmp_path / "scene.yaml"
    scene.write_text(yaml.safe_dump(scriber(spectrum=VCD)))
    out = tmp_path / "floor.png"
    args = ["floor", str(scene), "--point", "tool", "--types", "air", "-o", str(out)]
    r = CliRunner().invoke(app, [*args, "--coherence", "correlated,uncorrelated,worst_phase"])
    assert r.exit_code == 0, r.output
    for c in ("correlated", "uncorrelated", "worst_phase"):
        assert f"air, {c}: worst band" in r.output
    r = CliRunner().invoke(app, [*args, "--coherence", "partly"])
    assert r.exit_code == 2 and "--coherence: unknown ['partly']" in r.output


@pytest.mark.parametrize(
    ("floor_block", "where", "words"),
    [
        ({"per_mount": [VCD] * 3}, "floor.per_mount", "3 spectra for 4 mounts"),
        ({"spectrum": VCD, "wave": {"speed": "0 m/s"}}, "floor.wave.speed", "greater than 0"),
    ],
)
def test_the_service_answers_422_naming_the_field(tmp_path: Path, floor_block, where, words):
    from fastapi.testclient import TestClient

    from isolab.service.api.app import create_app
    from isolab.service.settings import Settings

    http = TestClient(create_app(Settings(data_dir=tmp_path)))
    body = {"scene": scriber(**floor_block), "isolator_types": ["air"], "point": "tool"}
    r = http.post("/comparisons/floor.png", json=body)
    assert r.status_code == 422, r.text
    text = r.text
    assert words in text and all(part in text for part in where.split(".")), text
    ok = http.post("/comparisons/floor.png", json={**body, "scene": scriber(per_mount=[VCD] * 4)})
    assert ok.status_code == 200, ok.text
