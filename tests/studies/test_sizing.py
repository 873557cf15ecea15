"""Isolator catalogues and sizing: parsing and refusals, ``model:`` as the product's numbers (bit for bit),
and a sizing whose answer is known by hand on a symmetric base (every static load W/4)."""

from __future__ import annotations

import copy
import math
from typing import Any

import numpy as np
import pytest
from pydantic import ValidationError

from isolab.engine import simulate
from isolab.studies.answers.sizing import load_margin, size
from isolab.studies.inputs.catalogues import Catalogue, load_catalogue, shipped_catalogue
from isolab.studies.inputs.definitions import DefinitionError, check_definition, validation_details
from isolab.studies.inputs.study import scene_batch, validate_scene
from isolab.studies.units import STANDARD_GRAVITY

# A 2 m x 2 m x 0.4 m granite-like block (4000 kg) on four mounts 1.6 m apart, a 200 kg stage at the
# centre: by symmetry each mount carries a quarter of the weight.
SCENE: dict[str, Any] = {
    "machine": {"block": {"size": ["2 m", "2 m", "0.4 m"], "density": "2500 kg/m^3", "corner": [0, 0, 0]}},
    "isolators": {"layout": {"span_x": "1.6 m", "span_y": "1.6 m", "height": "0.3 m"}},
    "stages": [
        {
            "name": "y",
            "mass": "200 kg",
            "home": ["1 m", "1 m", "0.5 m"],
            "axis": [0, 1, 0],
            "profile": {"type": "trapezoid", "travel": "0.2 m", "velocity": "0.5 m/s", "acceleration": "1 g"},
        }
    ],
    "points": {"tool": ["1 m", "1 m", "0.5 m"]},
    "simulation": {"fidelity": "lti", "integrator": "exact", "dt": "2 ms", "duration": "2 s"},
    # a mount's largest total vertical load: its 10.3 kN share of the weight plus about 0.76 kN from the
    # 1 g stage move through 20 Hz mounts, 0.41 kN through 2 Hz mounts
    "criteria": {"isolators": {"max_force": "10.9 kN"}},
}
QUARTER = (4000.0 + 200.0) * STANDARD_GRAVITY / 4.0


def product(pid: str, kind: str, lo: str, hi: str, f: float, zeta: float, price: float, **more: Any) -> dict:
    return {
        "id": pid,
        "type": kind,
        "maker": "Test",
        "series": pid,
        "rated_load": {"min": lo, "max": hi},
        "f_vertical": f"{f} Hz",
        "f_horizontal": f"{f} Hz",
        "zeta": zeta,
        "price": price,
        **more,
    }


CATALOGUE: dict[str, Any] = {
    "name": "hand-made",
    "currency": "EUR",
    "products": [
        product("tiny", "elastomer", "1 kN", "5 kN", 20.0, 0.05, 10),  # cheapest: 10.3 kN is out of its range
        product("stiff", "elastomer", "5 kN", "20 kN", 20.0, 0.05, 20),  # fits, but 20 Hz misses max_force
        product("pair", "air", "2 kN", "6 kN", 2.0, 0.1, 22, effective_area="100 cm^2"),  # fits two a corner
        product("soft", "air", "5 kN", "20 kN", 2.0, 0.1, 50, stroke="20 mm", effective_area="200 cm^2"),
        product("soft_dear", "air", "5 kN", "20 kN", 2.0, 0.1, 80),
    ],
}


# ------------------------------------------------------------------------------------------- catalogue
def test_shipped_catalogue_names_its_sources_and_covers_every_type() -> None:
    cat = shipped_catalogue()
    assert {p.type for p in cat.products} == {"active", "air", "elastomer"}
    assert all(p.source and p.maker and p.series and p.note for p in cat.products)
    assert "representative" in (cat.description or "").lower()
    for p in cat.products:  # a mass or a force; every range ordered and within the maximum load
        assert 0 <= p.rated_load.min < p.rated_load.max <= (p.max_load or math.inf)


def test_catalogue_reads_units_and_loads_given_as_mass() -> None:
    cat = load_catalogue(
        {"products": [product("p", "air", "500 kg", "2 t", 3.0, 0.1, 1, effective_area="300 cm^2")]}
    )
    p = cat.products[0]
    assert p.rated_load.min == pytest.approx(500 * STANDARD_GRAVITY)
    assert p.rated_load.max == pytest.approx(2000 * STANDARD_GRAVITY)
    assert p.pressure(6000.0) == pytest.approx(6000.0 / 0.03)  # p = F / A, Pa


@pytest.mark.parametrize(
    ("change", "loc", "text"),
    [
        ({"effective_area": "-100 cm^2"}, ("products", 0, "effective_area"), "greater than 0"),
        ({"max_pressure": "-2 bar"}, ("products", 0, "max_pressure"), "greater than 0"),
        ({"rated_load": {"min": "9 kN", "max": "5 kN"}}, ("products", 0, "rated_load", "max"), "must exceed"),
        ({"rated_load": None}, ("products", 0, "rated_load"), ""),
        ({"f_vertical": "200 Hz"}, ("products", 0, "f_vertical"), "between 0.5 Hz and 60 Hz"),
        ({"type": "magnetic"}, ("products", 0, "type"), "active"),
    ],
)
def test_catalogue_refusals_name_the_field(change: dict, loc: tuple, text: str) -> None:
    p = product("p", "air", "1 kN", "5 kN", 3.0, 0.1, 1)
    p.update(change)
    if change.get("rated_load", 0) is None:
        del p["rated_load"]  # a missing required field
    with pytest.raises(ValidationError) as err:
        Catalogue.model_validate({"products": [p]})
    e = validation_details(err.value, [])[0]  # the field's full path, as a 422 names it
    assert tuple(e["loc"])[: len(loc)] == loc, e
    assert text in e["msg"]


def test_repeated_product_id_is_refused() -> None:
    p = product("p", "air", "1 kN", "5 kN", 3.0, 0.1, 1)
    with pytest.raises(ValidationError, match=r"products\[1\]\.id: 'p' repeats products\[0\]"):
        Catalogue.model_validate({"products": [p, p]})


# ------------------------------------------------------------------------------------------------ model:
def test_model_scene_runs_bit_identically_to_the_products_numbers() -> None:
    by_model = copy.deepcopy(SCENE)
    by_model["isolators"].update(model="soft", catalogue=CATALOGUE)
    by_numbers = copy.deepcopy(SCENE)
    by_numbers["isolators"].update(preset="air", f_vertical="2 Hz", f_horizontal="2 Hz", zeta=0.1)
    results = []
    for s in (by_model, by_numbers):
        b, _ = scene_batch(validate_scene(s))
        results.append(simulate(b, fidelity="lti", integrator="exact", dt=0.002))
    for name in (
        "peak_isolator_force",
        "peak_point_displacement",
        "natural_frequency",
        "static_isolator_load",
    ):
        assert np.array_equal(getattr(results[0], name), getattr(results[1], name)), name
    assert np.allclose(results[0].static_isolator_load, QUARTER)


def test_scene_without_model_is_left_as_written() -> None:
    iso = validate_scene(SCENE).isolators
    assert iso.model is None and iso.f_vertical is None and iso.preset == "air"


def test_unknown_model_names_the_mount_and_the_closest_ids() -> None:
    s = copy.deepcopy(SCENE)
    s["isolators"] = {
        "catalogue": CATALOGUE,
        "list": [{"position": p, "model": "soft"} for p in ([0.2, 0.2, 0], [1.8, 0.2, 0], [1.8, 1.8, 0])],
    }
    s["isolators"]["list"][1]["model"] = "sofft"
    body = {"name": "x", "scene": s, "parameters": [], "design": {"type": "grid"}}
    with pytest.raises(DefinitionError) as err:
        check_definition(body)
    d = err.value.details[0]
    assert d["loc"] == ["body", "scene", "isolators", "list", 1, "model"], d
    assert "no product 'sofft'" in d["msg"] and "soft" in d["msg"]


def test_model_type_clashing_with_preset_is_refused() -> None:
    s = copy.deepcopy(SCENE)
    s["isolators"].update(model="stiff", preset="air", catalogue=CATALOGUE)
    with pytest.raises(ValidationError, match="product 'stiff' is elastomer"):
        validate_scene(s)


def test_catalogue_path_is_not_read_by_validation() -> None:
    s = copy.deepcopy(SCENE)
    s["isolators"].update(model="soft", catalogue="/etc/passwd")
    with pytest.raises(ValidationError, match="not a shipped catalogue"):
        validate_scene(s)


# ------------------------------------------------------------------------------------------------ sizing
def test_load_margin_is_the_change_either_way_the_range_allows() -> None:
    p = load_catalogue(CATALOGUE).product("soft")  # 5 .. 20 kN
    assert load_margin(10e3, p) == pytest.approx(0.5)  # down to 5 kN: -50 %, up to 20 kN: +100 %
    assert load_margin(19e3, p) == pytest.approx(20 / 19 - 1)
    assert load_margin(4e3, p) < 0


def test_sizing_picks_the_cheapest_product_passing_load_and_criteria() -> None:
    a = size(SCENE, CATALOGUE)
    assert a["feasible"], a["summary"]
    assert a["design"]["product"] == "soft" and a["design"]["isolators"] == 4
    assert a["design"]["cost"] == pytest.approx(4 * 50)
    verdicts = {c["product"]: c for c in a["candidates"]}
    assert "load out of range" in verdicts["tiny"]["reason"]
    assert "load out of range" in verdicts["pair"]["reason"]  # 10.3 kN on one 6 kN mount
    assert "isolators_max_force missed by" in verdicts["stiff"]["reason"]
    assert verdicts["stiff"]["margins"]["isolators_max_force"] < 0
    assert verdicts["soft"]["margins"]["isolators_max_force"] > 0
    for m in a["mounts"]:
        assert m["static_load"] == pytest.approx(QUARTER)
        assert m["count"] == 1 and m["load_per_isolator"] == pytest.approx(QUARTER)
        assert m["load_margin"] == pytest.approx(min(20e3 / QUARTER - 1, 1 - 5e3 / QUARTER))
        assert m["pressure"] == pytest.approx(QUARTER / 0.02)  # p = F / A
        assert 0 < m["stroke_used"] == pytest.approx(m["peak_deflection"] / 0.02)
        reasons = {c["product"]: c["reason"] for c in m["cheaper"]}
        assert set(reasons) == {"tiny", "stiff", "pair"}
        assert "outside the rated 1 kN to 5 kN" in reasons["tiny"]
    # the sized scene stands on the product and runs as it did
    sized = validate_scene(a["scene"])
    assert sized.isolators.model == "soft" and sized.isolators.f_vertical == 2.0


def test_two_per_corner_makes_a_smaller_product_the_cheapest() -> None:
    a = size(SCENE, CATALOGUE, per_corner=[1, 2])
    assert a["design"]["product"] == "pair" and a["design"]["isolators"] == 8
    assert a["design"]["cost"] == pytest.approx(8 * 22)
    for m in a["mounts"]:
        assert m["count"] == 2 and m["load_per_isolator"] == pytest.approx(QUARTER / 2)
        assert m["pressure"] == pytest.approx(QUARTER / 2 / 0.01)


def test_a_load_outside_every_range_is_answered_in_words() -> None:
    heavy = copy.deepcopy(SCENE)
    heavy["machine"]["block"]["density"] = "20000 kg/m^3"  # 32 t: 80 kN a mount
    a = size(heavy, CATALOGUE)
    assert not a["feasible"] and a["design"] is None and a["scene"] is None
    assert a["summary"].startswith("no feasible product")
    for m in a["mounts"]:
        assert "no product of the catalogue carries" in m["reason"]
    assert a["cases_run"] == 0


def test_sizing_refuses_bad_input_naming_the_field() -> None:
    bad = copy.deepcopy(CATALOGUE)
    bad["products"][0]["effective_area"] = "-1 m^2"
    with pytest.raises(DefinitionError) as err:
        size(SCENE, bad)
    assert err.value.details[0]["loc"] == ["body", "catalogue", "products", 0, "effective_area"]
    scene = copy.deepcopy(SCENE)
    scene["machine"]["block"]["density"] = "-1 kg/m^3"
    with pytest.raises(DefinitionError) as err:
        size(scene, CATALOGUE)
    assert err.value.details[0]["loc"][:3] == ["body", "scene", "machine"]
