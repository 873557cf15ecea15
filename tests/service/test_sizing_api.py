"""``isolab size`` and ``POST /sizings``: the same answer by the command line and over REST, and 422s naming
the field."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest
import yaml
from fastapi.testclient import TestClient
from typer.testing import CliRunner

from isolab.service.cli import app as cli_app
from tests.studies.test_sizing import CATALOGUE, QUARTER, SCENE


def test_cli_and_rest_size_the_same_scene_alike(http: TestClient, tmp_path: Path) -> None:
    scene_file, cat_file = tmp_path / "scene.yaml", tmp_path / "catalogue.yaml"
    scene_file.write_text(yaml.safe_dump(SCENE), encoding="utf-8")
    cat_file.write_text(yaml.safe_dump(CATALOGUE), encoding="utf-8")
    r = CliRunner().invoke(cli_app, ["size", str(scene_file), "--catalogue", str(cat_file), "--json"])
    assert r.exit_code == 0, r.output
    by_cli = json.loads(r.output)
    words = CliRunner().invoke(cli_app, ["size", str(scene_file), "--catalogue", str(cat_file)])
    assert words.exit_code == 0 and "4 x soft" in words.output and "bar" in words.output, words.output
    answer = http.post("/sizings", json={"scene": SCENE, "catalogue": CATALOGUE})
    assert answer.status_code == 200, answer.text
    by_rest = answer.json()
    assert by_cli["design"]["product"] == by_rest["design"]["product"] == "soft"
    assert [m["static_load"] for m in by_rest["mounts"]] == pytest.approx([QUARTER] * 4)
    assert by_cli["mounts"] == by_rest["mounts"]
    # the sized scene written to a file, with the catalogue beside it, loads and names its product
    sized = tmp_path / "sized.yaml"
    sized.write_text(
        yaml.safe_dump(
            {
                **by_rest["scene"],
                "isolators": {**by_rest["scene"]["isolators"], "catalogue": "catalogue.yaml"},
            }
        ),
        encoding="utf-8",
    )
    from isolab.studies.inputs.study import load_scene

    assert load_scene(sized).isolators.f_vertical == 2.0


@pytest.mark.parametrize(
    ("change", "loc"),
    [
        ({"max_cases": 65}, ["body", "max_cases"]),
        ({"margin": -0.1}, ["body", "margin"]),
        ({"per_corner": [0]}, ["body", "per_corner", 0]),
    ],
)
def test_sizing_request_limits_are_422_naming_the_field(http: TestClient, change: dict, loc: list) -> None:
    r = http.post("/sizings", json={"scene": SCENE, "catalogue": CATALOGUE, **change})
    assert r.status_code == 422, r.text
    assert any(d["loc"] == loc for d in r.json()["detail"]), r.json()


def test_sizing_bad_catalogue_and_no_feasible_product(http: TestClient) -> None:
    bad = copy.deepcopy(CATALOGUE)
    del bad["products"][1]["rated_load"]
    r = http.post("/sizings", json={"scene": SCENE, "catalogue": bad})
    assert r.status_code == 422, r.text
    assert any(d["loc"] == ["body", "catalogue", "products", 1, "rated_load"] for d in r.json()["detail"])
    r = http.post("/sizings", json={"scene": SCENE, "catalogue": "my-file.yaml"})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "catalogue"], r.text
    heavy = copy.deepcopy(SCENE)
    heavy["machine"]["block"]["density"] = "20000 kg/m^3"
    r = http.post("/sizings", json={"scene": heavy, "catalogue": CATALOGUE})
    assert r.status_code == 200, r.text
    assert r.json()["feasible"] is False and "no feasible product" in r.json()["summary"]
