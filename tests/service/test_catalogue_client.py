"""The comparison of a catalogue's products through the Python client (``Client.compare_products`` and
``product_frame``), a CSV catalogue read as its YAML twin, and ``POST /catalogues/read`` (the page's
upload) answering the catalogue or a 422 naming the line or the field."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import pandas as pd
import pytest
import yaml
from fastapi.testclient import TestClient

from benchmarks.live_service import thread_server
from isolab.service.api.app import create_app
from isolab.service.client import Client, ClientError, catalogue_data, product_frame
from isolab.service.settings import Settings
from isolab.studies.inputs.catalogues import catalogue_from_csv, load_catalogue
from tests.shared_cluster import shared_scheduler
from tests.studies.test_sizing import CATALOGUE, QUARTER, SCENE

pytestmark = pytest.mark.slow  # a service of its own: `make test-fast` skips it

# CATALOGUE as a spreadsheet exports it: units in the header, a comment, a quoted cell, a blank row
HEADER = (
    "id,type,maker,series,rated_load.min [kN],rated_load.max [kN],f_vertical [Hz],f_horizontal [Hz],zeta,"
    "stroke [mm],effective_area [cm^2],price [EUR]"
)
CSV = f"""# the hand-made catalogue of tests/studies/test_sizing.py
{HEADER}
tiny,elastomer,Test,tiny,1,5,20,20,0.05,,,10
stiff,elastomer,Test,stiff,5,20,20,20,0.05,,,20
pair,air,Test,pair,2000 N,6,2,2,0.1,,100,22

soft,air,Test,"soft",5,20,2,2,0.1,20,200,50
soft_dear,air,Test,soft_dear,5,20,2,2,0.1,,,80
"""


@pytest.fixture(scope="module")
def url(tmp_path_factory: pytest.TempPathFactory):
    with thread_server(
        create_app(Settings(data_dir=tmp_path_factory.mktemp("data"), scheduler_address=shared_scheduler(1)))
    ) as url:
        yield url


def test_a_csv_catalogue_reads_as_its_yaml_twin(tmp_path: Path) -> None:
    data = catalogue_from_csv(CSV, "hand-made")
    assert data["currency"] == "EUR" and data["name"] == "hand-made"
    assert load_catalogue(data) == load_catalogue(CATALOGUE)
    (tmp_path / "hand-made.csv").write_text(CSV, encoding="utf-8")
    assert catalogue_data(tmp_path / "hand-made.csv") == data  # the client reads the file by its ending
    with pytest.raises(ValueError, match=r"line 2, column 3: 'make' is no product field"):
        catalogue_from_csv("# a comment\nid,type,make\n")
    with pytest.raises(ValueError, match="line 3: 13 cells under a header of 12"):
        catalogue_from_csv(CSV.replace("tiny,elastomer,Test,tiny,1,5,20,20,0.05,,,10", "tiny" + ",1" * 12))
    with pytest.raises(ValueError, match="no product"):
        catalogue_from_csv(CSV.splitlines()[1])


def test_the_client_compares_a_catalogue_given_as_file_or_mapping(url: str, tmp_path: Path) -> None:
    cat_file = tmp_path / "catalogue.yaml"
    cat_file.write_text(yaml.safe_dump(CATALOGUE), encoding="utf-8")
    with Client(url) as api:
        answer = api.compare_products(SCENE, cat_file, per_corner=[1, 2])
        by_csv = api.compare_products(SCENE, catalogue_from_csv(CSV, "hand-made"), per_corner=[1, 2])
        one_a_corner = api.compare_products(SCENE, CATALOGUE, per_corner=[1])
        too_tight = api.compare_products(SCENE, CATALOGUE, margin=0.6, per_corner=[1, 2])
    assert answer["recommendation"]["product"] == "pair"  # 8 x 22 EUR: cheaper than 4 x 50 EUR of soft
    assert by_csv["rows"] == answer["rows"]
    df = product_frame(answer)
    assert list(df.index) == ["stiff", "pair", "soft", "soft_dear", "tiny"]  # by cost, the skipped last
    assert df["recommended"].tolist() == [False, True, False, False, False]
    assert df.at["pair", "count"] == 8 and df.at["pair", "per_mount"] == "2/2/2/2"
    assert df.at["pair", "cost"] == 176.0 and df.attrs["currency"] == "EUR"
    # pressure = load per isolator / effective area; load margin = max/F - 1 of the 6 kN rating
    assert df.at["pair", "pressure_min"] == pytest.approx(QUARTER / 2 / 100e-4)
    assert df.at["pair", "load_margin"] == pytest.approx(6000.0 / (QUARTER / 2) - 1.0)
    assert df.attrs["units"]["pressure_min"] == "Pa" and df.attrs["units"]["cost"] == "EUR"
    # why not, in words: the cheaper stiff pads miss the force limit, the tiny pads do not carry the load
    assert not df.at["stiff", "feasible"] and df.at["stiff", "why_not"].startswith(
        "fails isolators_max_force"
    )
    assert df.at["stiff", "criteria_met"] == 0 and df.at["pair", "criteria_met"] == 1
    assert "load out of range" in df.at["tiny", "why_not"] and df.at["tiny", "count"] is pd.NA
    assert df.at["pair", "feasible"] and pd.isna(df.at["pair", "why_not"])
    # stroke used: the peak vertical deflection over the 20 mm stroke of the only product that gives one
    deflection = answer["rows"]["soft"]["peak_isolator_deflection_z"]
    assert df.at["soft", "stroke_used"] == pytest.approx(deflection / 0.020) and 0 < deflection < 0.020
    assert df["stroke_used"].drop("soft").isna().all()
    # per_corner and margin reach the service: one a corner leaves pair out, a 60 % margin every product
    assert one_a_corner["recommendation"]["product"] == "soft"
    assert product_frame(one_a_corner).at["pair", "why_not"].startswith("mount_0: load out of range")
    assert too_tight["rows"] == {} and not product_frame(too_tight)["feasible"].any()


def test_the_client_refuses_a_missing_file_and_reports_the_services_field(url: str, tmp_path: Path) -> None:
    with Client(url) as api:
        with pytest.raises(FileNotFoundError, match="no-such.csv"):
            api.compare_products(SCENE, tmp_path / "no-such.csv")
        bad = copy.deepcopy(CATALOGUE)
        bad["products"][1]["rated_load"] = {"min": "20 kN", "max": "5 kN"}
        with pytest.raises(ClientError, match="catalogue.products.1.rated_load.max") as err:
            api.compare_products(SCENE, bad)
        assert err.value.status_code == 422
        with pytest.raises(ClientError, match="not a shipped catalogue"):
            api.compare_products(SCENE, "no-such-catalogue")


def test_an_uploaded_catalogue_is_read_or_refused_naming_the_line(http: TestClient) -> None:
    r = http.post("/catalogues/read", json={"text": CSV, "format": "csv", "name": "mine"})
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["products"] == ["tiny", "stiff", "pair", "soft", "soft_dear"]
    assert load_catalogue(body["catalogue"]) == load_catalogue({**CATALOGUE, "name": "mine"})
    text = yaml.safe_dump(CATALOGUE)
    assert http.post("/catalogues/read", json={"text": text}).json()["catalogue"]["name"] == "hand-made"
    refusals = [
        ({"text": "id,type,make\n", "format": "csv"}, ["body", "text"], "'make' is no product field"),
        ({"text": "products: [1, 2"}, ["body", "text"], "not valid YAML"),
        ({"text": "- a\n- b\n"}, ["body", "text"], "a mapping"),
        (
            {
                "text": CSV.replace("tiny,elastomer,Test,tiny,1,5", "tiny,elastomer,Test,tiny,6,5"),
                "format": "csv",
            },
            ["body", "text", "products", 0, "rated_load", "max"],
            "must exceed min",
        ),
        ({"text": CSV, "format": "xls"}, ["body", "format"], ""),
        # a few lines whose aliases expand to 10^9 values: refused before they are loaded
        (
            {
                "text": "a: &a [x, x, x, x, x, x, x, x, x, x]\n"
                + "".join(
                    f"{chr(98 + i)}: &{chr(98 + i)} [{', '.join(['*' + chr(97 + i)] * 10)}]\n"
                    for i in range(8)
                )
            },
            ["body", "text"],
            "aliases",
        ),
    ]
    for body, loc, words in refusals:
        r = http.post("/catalogues/read", json=body)
        assert r.status_code == 422, r.text
        hits = [d for d in r.json()["detail"] if d["loc"] == loc]
        assert hits and words in hits[0]["msg"], r.json()


def test_the_command_line_prints_the_products_in_100_columns(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from isolab.service.cli import app as cli_app

    scene_file, cat_file = tmp_path / "scene.yaml", tmp_path / "hand-made.csv"
    scene_file.write_text(yaml.safe_dump(SCENE), encoding="utf-8")
    cat_file.write_text(CSV, encoding="utf-8")
    args = ["compare", str(scene_file), "--catalogue", str(cat_file), "--per-corner", "1,2"]
    r = CliRunner().invoke(cli_app, args, env={"COLUMNS": "100"})
    assert r.exit_code == 0, r.output
    lines = r.output.splitlines()
    assert max(len(line) for line in lines) <= 100, r.output
    table = r.output[r.output.index("products of hand-made") : r.output.index("why not")]
    for unit in ("cost", "[EUR]", "pressure", "[bar]", "stroke", "used", "[%]"):  # units in the header
        assert unit in table, r.output
    row = {line.split()[0]: line.split() for line in table.splitlines()[1:] if line.strip()}
    assert row["pair"][1:5] == ["8", "(2/mount)", "176", "16.54"], r.output  # count, cost, load margin %
    assert row["pair"][5] == f"{QUARTER / 2 / 100e-4 / 1e5:.3g}" and row["pair"][-1] == "RECOMMENDED"
    by_json = CliRunner().invoke(cli_app, [*args, "--json"])
    assert by_json.exit_code == 0 and json.loads(by_json.output)["recommendation"]["product"] == "pair"
    deflection = json.loads(by_json.output)["rows"]["soft"]["peak_isolator_deflection_z"]
    assert row["soft"][5] == f"{100 * deflection / 0.020:.4g}", r.output  # stroke used of 20 mm, %
    assert row["stiff"][-1] == "rejected" and row["tiny"][-2:] == ["no", "fit"]
    why = r.output[r.output.index("why not") :]
    assert "stiff" in why and "fails isolators_max_force" in why
    assert "tiny" in why and "load out of range" in why  # the long reason wrapped in its column
    assert lines[-2].startswith("recommended: pair. 8 x pair for 176 EUR"), r.output
