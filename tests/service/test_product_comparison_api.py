"""``isolab compare --catalogue`` and ``POST /comparisons`` with a catalogue: the same answer by the command
line and over REST, 422s naming the field, and a catalogue that fits nothing answered, not refused."""

from __future__ import annotations

import copy
import json
import re
from pathlib import Path
from typing import Any

import pytest
import yaml
from fastapi.testclient import TestClient
from typer.testing import CliRunner

from isolab.service.cli import app as cli_app
from tests.studies.test_sizing import CATALOGUE, SCENE


def test_cli_and_rest_compare_the_products_alike(http: TestClient, tmp_path: Path) -> None:
    scene_file, cat_file = tmp_path / "scene.yaml", tmp_path / "catalogue.yaml"
    scene_file.write_text(yaml.safe_dump(SCENE), encoding="utf-8")
    cat_file.write_text(yaml.safe_dump(CATALOGUE), encoding="utf-8")
    args = ["compare", str(scene_file), "--catalogue", str(cat_file), "--per-corner", "1,2"]
    r = CliRunner().invoke(cli_app, [*args, "--json"])
    assert r.exit_code == 0, r.output
    by_cli = json.loads(r.output)
    words = CliRunner().invoke(cli_app, args)
    assert words.exit_code == 0 and "recommended: pair" in words.output, words.output
    assert re.search(r"\n tiny +mount_0: load out of range", words.output), words.output
    answer = http.post("/comparisons", json={"scene": SCENE, "catalogue": CATALOGUE, "per_corner": [1, 2]})
    assert answer.status_code == 200, answer.text
    by_rest = answer.json()
    assert by_rest["recommendation"]["product"] == by_cli["recommendation"]["product"] == "pair"
    assert by_rest["catalogue"]["products"] == by_cli["catalogue"]["products"]
    assert by_rest["rows"] == by_cli["rows"]  # the same cases, the same engine: bit for bit
    # the generic comparison keeps its answer: no catalogue block, no product
    plain = http.post("/comparisons", json={"scene": SCENE, "simulation": {"duration": "1 s"}}).json()
    assert "catalogue" not in plain and "product" not in plain["recommendation"]
    assert plain["isolator_types"] == ["active", "air", "elastomer"]


def product_change(i: int, key: str, value: Any) -> dict[str, Any]:
    cat = copy.deepcopy(CATALOGUE)
    cat["products"][i][key] = value
    return {"catalogue": cat}


@pytest.mark.parametrize(
    ("change", "loc", "words"),
    [
        (
            product_change(3, "max_pressure", "-2 bar"),
            ["body", "catalogue", "products", 3, "max_pressure"],
            "",
        ),
        (product_change(3, "effective_area", 0), ["body", "catalogue", "products", 3, "effective_area"], ""),
        (
            product_change(1, "rated_load", {"min": "20 kN", "max": "5 kN"}),
            ["body", "catalogue", "products", 1, "rated_load", "max"],
            "must exceed min",
        ),
        ({"catalogue": "no-such"}, ["body", "catalogue"], "not a shipped catalogue"),
        ({"catalogue": "representative", "tune": True}, ["body", "tune"], "datasheet"),
        ({"catalogue": "representative", "cost_order": ["air"]}, ["body", "cost_order"], "prices"),
        ({"margin": 0.2}, ["body", "margin"], "give catalogue"),
        ({"catalogue": "representative", "margin": True}, ["body", "margin"], ""),
        ({"catalogue": "representative", "per_corner": [9]}, ["body", "per_corner", 0], ""),
    ],
)
def test_bad_catalogue_comparisons_are_422_naming_the_field(
    http: TestClient, change: dict, loc: list, words: str
) -> None:
    r = http.post("/comparisons", json={"scene": SCENE, **change})
    assert r.status_code == 422, r.text
    hits = [d for d in r.json()["detail"] if d["loc"] == loc]
    assert hits and words in hits[0]["msg"], r.json()


def test_unknown_product_in_the_scene_is_422_naming_the_model(http: TestClient) -> None:
    scene = copy.deepcopy(SCENE)
    scene["isolators"]["model"] = "fabreeka-plm-4O"
    r = http.post("/comparisons", json={"scene": scene, "simulation": {"duration": "1 s"}})
    assert r.status_code == 422, r.text
    msg = json.dumps(r.json()["detail"])
    assert "isolators.model" in msg and "fabreeka-plm-40" in msg  # the closest id


def test_a_catalogue_that_fits_nothing_is_answered(http: TestClient) -> None:
    cat = {**CATALOGUE, "products": [CATALOGUE["products"][0]]}
    r = http.post("/comparisons", json={"scene": SCENE, "catalogue": cat})
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["rows"] == {} and body["recommendation"]["isolator_type"] is None
    assert body["catalogue"]["products"][0]["verdict"] == "skipped"
    assert "rated range" in body["recommendation"]["reason"]
