"""``isolab simulate`` on the article's scriber: modes named by their motion, the heave mode at the air
mounts' tuned 3.5 Hz, peaks per point, isolator and axis, in the same numbers as its JSON."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from isolab.service.cli import app as cli_app
from isolab.service.cli.local import heave_mode, mode_label

EXAMPLE = Path(__file__).resolve().parents[2] / "studies" / "examples" / "article-scriber.yaml"


@pytest.fixture(scope="module")
def outputs() -> tuple[str, dict]:
    runner = CliRunner()
    text = runner.invoke(cli_app, ["simulate", str(EXAMPLE)])
    assert text.exit_code == 0, text.output
    as_json = runner.invoke(cli_app, ["simulate", str(EXAMPLE), "--json"])
    assert as_json.exit_code == 0, as_json.output
    return text.output, json.loads(as_json.output)


def test_modes_are_named_by_motion() -> None:
    heave = np.array([0.0, 0.0, 1.0, 0.0, 0.0, 0.0])
    rocking = np.array([0.6, 0.0, 0.0, 0.0, 0.4, 0.0])
    assert mode_label(heave) == "heave (z)"
    assert mode_label(rocking) == "surge + roll (x+ry)"
    assert mode_label(np.array([0.0, 0.9, 0.0, 0.1, 0.0, 0.0])) == "sway (y)"  # 10 %: not named
    assert mode_label(np.full(6, np.nan)) == "?"
    assert heave_mode(np.array([rocking, heave, rocking, rocking, rocking, rocking])) == 1


def test_text_names_the_heave_mode_at_the_tuned_frequency(outputs: tuple[str, dict]) -> None:
    text, out = outputs
    m = re.search(r"heave mode\s+mode (\d) at ([\d.]+) Hz", text)
    assert m, text
    mode, f = int(m.group(1)), float(m.group(2))
    # the air mounts are tuned to 3.5 Hz vertically under their own load: each k_i = (2 pi f)^2 W_i / g, so
    # the stiffness sums to (2 pi f)^2 M and its centre lies under the c.g.: pure heave at f
    assert f == pytest.approx(3.5, abs=0.01)
    assert out["heave_mode"] == mode and out["natural_frequency"][mode - 1] == pytest.approx(3.5, rel=1e-3)
    assert re.search(rf"^\s+{mode}\s+3\.50 Hz\s+heave \(z\)\s+<- heave mode$", text, re.MULTILINE), text
    assert out["mode_name"][mode - 1] == "heave (z)"
    assert out["mode_energy"][mode - 1]["z"] > 0.9
    # every mode is listed with its motion
    assert len(re.findall(r"^\s+\d\s+[\d.]+ Hz\s+\w+", text, re.MULTILINE)) == 6


def test_text_gives_peaks_per_point_isolator_and_axis(outputs: tuple[str, dict]) -> None:
    text, out = outputs
    for point, peaks in out["peak_point_displacement"].items():
        line = re.search(rf"peak displacement {point}\s+x ([\d.]+) mm\s+y ([\d.]+) mm\s+z ([\d.]+) mm", text)
        assert line, text
        assert [float(v) for v in line.groups()] == pytest.approx([peaks[a] * 1e3 for a in "xyz"], abs=5e-4)
    for iso, force in out["peak_isolator_force"].items():
        line = re.search(rf"^\s+{iso}\s+x ([\d.]+) kN\s+y ([\d.]+) kN\s+z ([\d.]+) kN$", text, re.MULTILINE)
        assert line, text
        assert [float(v) for v in line.groups()] == pytest.approx([force[a] / 1e3 for a in "xyz"], abs=5e-3)
    low = min(out["min_isolator_load"].values())
    high = max(out["max_isolator_load"].values())
    m = re.search(r"min ([\d.]+) kN \((\w+)\), max ([\d.]+) kN \((\w+)\)", text)
    assert m, text
    assert float(m.group(1)) == pytest.approx(low / 1e3, abs=5e-3)
    assert float(m.group(3)) == pytest.approx(high / 1e3, abs=5e-3)
    # the total load swings about the preload by at most the dynamic force on that mount
    for iso, static in out["static_isolator_load"].items():
        fz = out["peak_isolator_force"][iso]["z"]
        assert static - fz - 1e-6 <= out["min_isolator_load"][iso] <= static
        assert static <= out["max_isolator_load"][iso] <= static + fz + 1e-6
    assert "peak isolator deflection" in text
    for iso, d in out["peak_isolator_deflection"].items():
        assert re.search(
            rf"^\s+{iso}\s+x {d['x'] * 1e3:.3f} mm\s+y {d['y'] * 1e3:.3f} mm", text, re.MULTILINE
        )
    assert re.search(r"point settling time\s+tool [\d.]+ s, camera [\d.]+ s", text), text
