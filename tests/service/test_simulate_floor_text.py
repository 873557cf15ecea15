"""``isolab simulate`` with a floor spectrum and criteria: the floor-induced velocity per point (its
worst band, the VC criterion it meets) and the criteria margins, in the JSON and the text alike."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from isolab.service.cli import app as cli_app
from isolab.studies.answers.floor_response import velocity_spectra
from isolab.studies.questions.floor import VC_LEVELS, vc_class

EXAMPLE = Path(__file__).resolve().parents[2] / "studies" / "examples" / "article-scriber.yaml"


def test_vc_class_is_the_strictest_met() -> None:
    assert vc_class(6.25e-6) == "VC-D"
    assert vc_class(6.26e-6) == "VC-C"
    assert vc_class(0.1e-6) == "VC-G"
    assert vc_class(51e-6) is None and vc_class(float("nan")) is None


@pytest.fixture(scope="module")
def outputs(tmp_path_factory: pytest.TempPathFactory) -> tuple[str, dict, dict]:
    d = yaml.safe_load(EXAMPLE.read_text())
    d["floor"] = {"spectrum": {"x": "VC-D", "y": "VC-D", "z": "VC-D"}, "coherence": "uncorrelated"}
    d["criteria"] = {"tool": {"velocity": "VC-A"}, "camera": {"velocity": "VC-C"}}
    d["simulation"] = {**d.get("simulation", {}), "duration": "1 s"}
    path = tmp_path_factory.mktemp("floor") / "scene.yaml"
    path.write_text(yaml.safe_dump(d))
    runner = CliRunner()
    text = runner.invoke(cli_app, ["simulate", str(path), "--fidelity", "lti", "--integrator", "exact"])
    assert text.exit_code == 0, text.output
    js = runner.invoke(
        cli_app, ["simulate", str(path), "--fidelity", "lti", "--integrator", "exact", "--json"]
    )
    assert js.exit_code == 0, js.output
    return text.output, json.loads(js.output), d


def test_json_floor_velocity_matches_the_spectra(outputs) -> None:
    _, out, d = outputs
    spectra = velocity_spectra(d, point="tool")
    (t,) = spectra["velocity"]
    v = spectra["velocity"][t]  # (3, 20) m/s, under the scene's (uncorrelated) floor
    for k, a in enumerate("xyz"):
        assert out["floor_point_velocity"]["tool"][a] == pytest.approx(v[k].max(), rel=1e-12)
    worst = max(out["floor_point_velocity"]["tool"].values())
    assert out["floor_vc_class"]["tool"] == vc_class(worst)
    assert out["criterion_margin"]["tool_velocity"] == pytest.approx(1 - worst / VC_LEVELS["VC-A"], rel=1e-12)
    cam = max(out["floor_point_velocity"]["camera"].values())
    assert out["criterion_margin"]["camera_velocity"] == pytest.approx(1 - cam / VC_LEVELS["VC-C"], rel=1e-12)
    assert out["meets_criteria"] == all(m >= 0 for m in out["criterion_margin"].values())
    assert out["meets_criteria"] is False  # a 12.5 um/s camera on air mounts over a VC-D floor: no
    assert np.isfinite(out["floor_point_velocity_band"]["tool"]["z"])


def test_text_prints_the_floor_and_the_margins(outputs) -> None:
    text, out, _ = outputs
    assert "floor-induced velocity (worst one-third-octave band, RMS)" in text
    z = out["floor_point_velocity"]["tool"]["z"] * 1e6
    assert f"z {z:.3g} um/s" in text
    assert f"meets {out['floor_vc_class']['tool']}" in text
    assert "criteria margins (NOT all met" in text
    margin = f"{out['criterion_margin']['camera_velocity']:+.3f}"
    assert re.search(rf"\n    camera_velocity +{re.escape(margin)}  NOT met\n", text), text
    # the label column is as wide as the longest label, here "peak displacement camera" and a space
    width = len("peak displacement camera") + 1
    assert "\n    " + "camera_velocity".ljust(width) + margin in text


def test_no_floor_no_floor_lines() -> None:
    r = CliRunner().invoke(
        cli_app, ["simulate", str(EXAMPLE), "--fidelity", "lti", "--integrator", "exact", "--json"]
    )
    assert r.exit_code == 0, r.output
    out = json.loads(r.output)
    assert "floor_point_velocity" not in out and "criterion_margin" not in out
