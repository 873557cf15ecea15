"""Floor spectra: VC curves, parsing of the scene's floor.spectrum, band conversions, the stored outputs,
the plot route and the CLI."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
import yaml
from fastapi.testclient import TestClient
from pydantic import ValidationError
from typer.testing import CliRunner

from isolab.engine import frequency
from isolab.studies.answers.comparisons import comparison_study, run_comparison
from isolab.studies.answers.floor_response import velocity_spectra
from isolab.studies.inputs.definitions import DefinitionError
from isolab.studies.inputs.parameters import scene_dict
from isolab.studies.inputs.scenes import build_batch
from isolab.studies.inputs.schema import Scene, error_messages
from isolab.studies.inputs.study import load_scene
from isolab.studies.questions import floor

EXAMPLES = Path(floor.__file__).parents[1] / "examples"


def scriber(spectrum: dict | None = None) -> dict:
    d = yaml.safe_load((EXAMPLES / "article-scriber.yaml").read_text())
    if spectrum is not None:
        d["floor"] = {"spectrum": spectrum}
    return d


def errors(data: dict) -> list[str]:
    with pytest.raises(ValidationError) as exc:
        Scene.model_validate(data)
    return error_messages(exc.value)


# ------------------------------------------------------------------------------------------- VC curves
def test_vc_names_and_levels():
    assert list(floor.VC_LEVELS) == ["VC-A", "VC-B", "VC-C", "VC-D", "VC-E", "VC-F", "VC-G"]
    um = {k: v * 1e6 for k, v in floor.VC_LEVELS.items()}
    assert um == pytest.approx(
        {"VC-A": 50, "VC-B": 25, "VC-C": 12.5, "VC-D": 6.25, "VC-E": 3.12, "VC-F": 1.56, "VC-G": 0.78}
    )
    assert floor.vc_level("vc-d") == 6.25e-6
    with pytest.raises(ValueError, match="unknown VC level 'VC-H'"):
        floor.vc_level("VC-H")
    assert floor.VC_RANGE == (1.0, 80.0)


def test_band_numbers_of_nominal_centres():
    assert [floor.band_number(f) for f in frequency.NOMINAL_CENTRES] == list(range(20))
    assert floor.band_number(10 ** (15 / 10)) == 15
    assert floor.band_number(100.0) == 20  # a band past 80 Hz: usable to interpolate
    with pytest.raises(ValueError, match="5.6 Hz: not the centre of a one-third-octave band"):
        floor.band_number(5.6)


# ------------------------------------------------------------------------------------------ conversions
def test_band_levels_interpolate_log_log_and_are_zero_outside():
    v = floor.bands_to_levels({4.0: 20e-6, 8.0: 10e-6})
    n4, n8 = 6, 9
    assert v[n4] == 20e-6 and v[n8] == 10e-6
    # a straight line on log-log axes: each third of an octave divides by 2^(1/3)
    assert v[n4 + 1] == pytest.approx(20e-6 * 2 ** (-1 / 3), rel=1e-12)
    assert v[n4 + 2] == pytest.approx(20e-6 * 2 ** (-2 / 3), rel=1e-12)
    assert np.all(v[:n4] == 0) and np.all(v[n8 + 1 :] == 0)
    # anchors beyond 80 Hz still shape the 63 and 80 Hz bands
    w = floor.bands_to_levels({50.0: 4e-6, 100.0: 1e-6})
    assert w[17] == 4e-6 and w[19] == pytest.approx(4e-6 * 0.25 ** (2 / 3), rel=1e-12)


def test_flat_velocity_psd_gives_band_rms():
    """A flat velocity PSD S gives sqrt(S x band width) per band; the same motion as a displacement PSD
    S / (2 pi f)^2 gives the same bands."""
    S = 1e-12  # (m/s)^2/Hz
    f = np.geomspace(0.5, 120.0, 400)
    v = floor.psd_to_levels(f, np.full_like(f, S), "velocity")
    expect = np.sqrt(S * (frequency.BAND_UPPER - frequency.BAND_LOWER))
    assert v == pytest.approx(expect, rel=1e-9)
    x = floor.psd_to_levels(f, S / (2 * np.pi * f) ** 2, "displacement")
    assert x == pytest.approx(expect, rel=1e-5)  # power law between points: exact up to the quadrature
    # only part of the 1 Hz band is covered when the PSD starts inside it
    part = floor.psd_to_levels([1.0, 100.0], [S, S], "velocity")
    assert part[0] == pytest.approx(np.sqrt(S * (frequency.BAND_UPPER[0] - 1.0)), rel=1e-9)


# ---------------------------------------------------------------------------------------------- schema
def test_spectrum_forms_parse_and_build_the_batch():
    spec = {
        "x": "VC-D",
        "y": {"bands": {"4 Hz": "20 um/s", "8 Hz": "10 um/s"}},
        "z": {"psd": {"frequency": ["1 Hz", "100 Hz"], "velocity": ["1e-12 m^2/s^2/Hz"] * 2}},
    }
    scene = load_scene(scriber(spec))
    b = build_batch([scene])
    V = b.floor_band_velocity[0]
    assert np.all(V[0] == 6.25e-6)
    assert V[1, 6] == pytest.approx(20e-6) and V[1, 9] == pytest.approx(10e-6) and V[1, 5] == 0.0
    assert V[2, 10] == pytest.approx(np.sqrt(1e-12 * (frequency.BAND_UPPER[10] - frequency.BAND_LOWER[10])))
    # the stored (SI, JSON) form reads back to the same scene
    again = build_batch([load_scene(scene_dict(scene))])
    assert np.array_equal(again.floor_band_velocity, b.floor_band_velocity)
    # a scene without a spectrum: all zero; an axis left out: zero
    assert not build_batch([load_scene(scriber())]).floor_band_velocity.any()
    assert not build_batch([load_scene(scriber({"z": "VC-A"}))]).floor_band_velocity[0, :2].any()


@pytest.mark.parametrize(
    ("axis_value", "message"),
    [
        ("VC-H", "floor.spectrum.z: unknown VC level 'VC-H'"),
        ({"bands": {"5.6 Hz": "1 um/s"}}, "floor.spectrum.z: bands: band 5.6 Hz: not the centre"),
        ({"bands": {"8 Hz": "1 m/s"}}, "floor.spectrum.z: bands.8 Hz: must lie between 0 m/s and 0.1 m/s"),
        ({"bands": {"8 Hz": "2 mm"}}, "floor.spectrum.z: bands.8 Hz: expected a velocity"),
        ({"psd": {"frequency": [1, 2], "velocity": [1e-12]}}, "floor.spectrum.z: psd: 1 PSD values for 2"),
        ({"psd": {"frequency": [2, 1], "velocity": [1e-12] * 2}}, "floor.spectrum.z: psd.frequency: must"),
        (
            {"psd": {"frequency": [1, 2], "displacement": ["1 m/s"] * 2}},
            "floor.spectrum.z: psd.displacement.0",
        ),
        ({"psd": {"frequency": [1, 2]}}, "floor.spectrum.z: psd: give either displacement"),
        (3.0, "floor.spectrum.z: give a VC level"),
    ],
)
def test_spectrum_errors_name_the_field(axis_value, message):
    msgs = errors(scriber({"z": axis_value}))
    assert any(m.startswith(message) for m in msgs), msgs


def test_floor_block_combinations():
    assert any("give at least one of x, y, z" in m for m in errors(scriber({})))
    d = scriber({"z": "VC-D"})
    d["floor"]["sine"] = {"amplitude": ["0 m", "0 m", "1 um"], "frequency": ["0 Hz", "0 Hz", "10 Hz"]}
    b = build_batch([load_scene(d)])  # a sine for the time integration and a spectrum alongside
    assert b.floor_amp[0, 2] == 1e-6 and b.floor_band_velocity[0, 2, 0] == 6.25e-6
    d["floor"]["recorded"] = {"dt": 0.01, "displacement": {"z": [0.0, 1e-6]}}
    assert any("give either sine or recorded, not both" in m for m in errors(d))


# -------------------------------------------------------------------------------------- study outputs
@pytest.fixture(scope="module")
def vcd_comparison():
    study = comparison_study(scriber({"x": "VC-D", "y": "VC-D", "z": "VC-D"}), ["active", "air", "elastomer"])
    return study, run_comparison(study)


def test_case_table_and_spectra_agree(vcd_comparison):
    study, table = vcd_comparison
    assert "floor_point_velocity_tool" in table.default and table.units["floor_point_velocity_tool"] == "m/s"
    spectra = velocity_spectra(study.scene, ["active", "air", "elastomer"], "tool")
    for i, t in enumerate(table.data["isolator_type"]):
        worst, centre, axis = spectra["worst"][str(t)]
        assert table.data["floor_point_velocity_tool"][i] == pytest.approx(worst, rel=1e-12)
        assert table.data[f"floor_point_velocity_band_tool_{axis}"][i] == pytest.approx(centre)
    v = dict(zip(table.data["isolator_type"], table.data["floor_point_velocity_tool"], strict=True))
    # each type's worst band sits at its own resonance: softer mounts amplify less of the floor's motion
    assert v["active"] < v["air"] < v["elastomer"]
    # every worst band is above the floor's own level (amplified at a resonance inside the bands)
    assert min(v.values()) > floor.VC_LEVELS["VC-D"]


def test_velocity_spectra_errors_name_the_field():
    with pytest.raises(DefinitionError) as exc:
        velocity_spectra(scriber({"z": "VC-D"}), ["air"], "nozzle")
    assert exc.value.details[0]["loc"] == ["body", "point"]
    with pytest.raises(DefinitionError) as exc:
        velocity_spectra(scriber(), ["air"], "tool")
    assert exc.value.details[0]["loc"] == ["body", "scene", "floor"]


# ------------------------------------------------------------------------------------------ route, CLI
@pytest.fixture(scope="module")
def http(tmp_path_factory: pytest.TempPathFactory):
    from isolab.service.api.app import create_app
    from isolab.service.settings import Settings

    return TestClient(create_app(Settings(data_dir=tmp_path_factory.mktemp("data"))))  # no cluster needed


def test_floor_png_route(http: TestClient):
    body = {"scene": scriber({"z": "VC-C"}), "isolator_types": ["air", "elastomer"], "point": "camera"}
    r = http.post("/comparisons/floor.png", json=body)
    assert r.status_code == 200, r.text
    assert r.headers["content-type"] == "image/png" and r.content[:8] == b"\x89PNG\r\n\x1a\n"
    bad = copy.deepcopy(body)
    bad["point"] = "nozzle"
    r = http.post("/comparisons/floor.png", json=bad)
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "point"]
    assert "nozzle" in r.json()["detail"][0]["msg"]
    bad = copy.deepcopy(body)
    bad["scene"]["floor"]["spectrum"]["z"] = "VC-H"
    r = http.post("/comparisons/floor.png", json=bad)
    assert r.status_code == 422
    assert r.json()["detail"][0]["loc"] == ["body", "scene", "floor", "spectrum", "z"]


def test_floor_cli(tmp_path: Path):
    from isolab.service.cli import app

    scene = tmp_path / "scene.yaml"
    scene.write_text(yaml.safe_dump(scriber({"z": "VC-D"})))
    out = tmp_path / "floor.png"
    r = CliRunner().invoke(
        app, ["floor", str(scene), "--point", "tool", "--types", "air,elastomer", "-o", str(out)]
    )
    assert r.exit_code == 0, r.output
    assert out.read_bytes()[:4] == b"\x89PNG" and "air: worst band" in r.output
    r = CliRunner().invoke(app, ["floor", str(scene), "--point", "nozzle", "-o", str(out)])
    assert r.exit_code == 2 and "point: no point of interest named 'nozzle'" in r.output
