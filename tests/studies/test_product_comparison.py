"""A comparison on a catalogue's products: the products whose rated range fits are compared (the others
skipped with the reason), the count per corner changes the cost and not the dynamics, the recommendation is
the cheapest priced product that meets the criteria (else the largest margin), and it agrees with the
sizing; with tolerances, the probability of meeting them per product."""

from __future__ import annotations

import copy
from typing import Any

import pytest

from isolab.studies.answers.product_comparison import compare_products
from isolab.studies.answers.robustness import smallest_margin
from isolab.studies.answers.sizing import size
from isolab.studies.inputs.definitions import DefinitionError
from tests.studies.test_sizing import CATALOGUE, QUARTER, SCENE


def margins(row: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in row.items() if k.startswith("margin_")}


def test_products_out_of_range_are_skipped_and_the_cheapest_meeting_product_is_recommended() -> None:
    answer = compare_products(SCENE, CATALOGUE)
    block = {p["product"]: p for p in answer["catalogue"]["products"]}
    # 10.3 kN per mount: tiny (1-5 kN) and, one a corner, pair (2-6 kN) cannot carry it
    assert block["tiny"]["verdict"] == block["pair"]["verdict"] == "skipped"
    assert "rated 1 kN to 5 kN" in block["tiny"]["reason"]
    assert answer["isolator_types"] == ["stiff", "soft", "soft_dear"]
    assert answer["catalogue"]["static_load"]["mount_0"] == pytest.approx(QUARTER)
    # the 20 Hz elastomer transmits more of the stage's force than the 10.9 kN limit allows; 2 Hz does not
    rows = answer["rows"]
    assert rows["stiff"]["meets_criteria"] is False and rows["stiff"]["margin_isolators_max_force"] < 0
    assert rows["soft"]["meets_criteria"] is True
    rec = answer["recommendation"]
    assert (rec["product"], rec["isolator_type"], rec["basis"]) == ("soft", "air", "cost")
    assert rec["cost_order"] == ["stiff", "soft", "soft_dear"]  # by the cost of four: 80 < 200 < 320
    assert "stiff fails isolators_max_force" in rec["reason"] and "200 EUR" in rec["reason"]
    # the sizing chooses the same product at the same cost
    sized = size(SCENE, CATALOGUE)
    assert sized["design"]["product"] == "soft" and sized["design"]["cost"] == block["soft"]["cost"] == 200


def test_two_per_corner_change_the_cost_not_the_dynamics() -> None:
    answer = compare_products(SCENE, CATALOGUE, per_corner=[1, 2])
    pair = next(p for p in answer["catalogue"]["products"] if p["product"] == "pair")
    assert pair["counts"] == [2, 2, 2, 2] and pair["cost"] == 8 * 22
    assert pair["load_per_isolator"] == pytest.approx([QUARTER / 2] * 4)
    # p = F / A: half a quarter of the weight on 100 cm^2
    assert pair["pressure"] == pytest.approx([QUARTER / 2 / 100e-4] * 4)
    # the same 2 Hz, 10 % figures as soft: the same motion, margin for margin
    assert margins(answer["rows"]["pair"]) == pytest.approx(margins(answer["rows"]["soft"]), rel=1e-12)
    assert answer["recommendation"]["product"] == "pair"  # 176 EUR < 200 EUR


def test_unpriced_products_are_recommended_on_margin() -> None:
    cat = copy.deepcopy(CATALOGUE)
    for p in cat["products"]:
        p.pop("price")
    cat["products"][4]["zeta"] = 0.3  # soft_dear: more damping, a different margin from soft
    answer = compare_products(SCENE, cat)
    rows, crit = answer["rows"], [r["name"] for r in answer["requirements"]]
    meeting = [t for t in answer["isolator_types"] if rows[t]["meets_criteria"]]
    assert len(meeting) == 2
    best = max(meeting, key=lambda t: smallest_margin(rows[t], crit))
    rec = answer["recommendation"]
    assert rec["product"] == best and rec["basis"] == "margin", rec
    assert {p["cost"] for p in answer["catalogue"]["products"]} == {None}


def test_a_catalogue_nothing_of_which_fits_is_an_answer() -> None:
    cat = {**CATALOGUE, "products": [CATALOGUE["products"][0]]}  # tiny alone
    answer = compare_products(SCENE, cat)
    assert answer["rows"] == {} and answer["recommendation"]["product"] is None
    assert "no product of catalogue 'hand-made' carries" in answer["recommendation"]["reason"]
    assert answer["requirements"][0]["name"] == "isolators_max_force"


def test_types_pick_the_products_and_a_bad_catalogue_names_its_field() -> None:
    answer = compare_products(SCENE, CATALOGUE, isolator_types=["elastomer"])
    assert answer["isolator_types"] == ["stiff"]
    bad = copy.deepcopy(CATALOGUE)
    bad["products"][2]["effective_area"] = "0 cm^2"
    with pytest.raises(DefinitionError) as err:
        compare_products(SCENE, bad)
    assert err.value.details[0]["loc"] == ["body", "catalogue", "products", 2, "effective_area"]


def test_with_tolerances_each_product_has_its_probability() -> None:
    scene = copy.deepcopy(SCENE)
    # +-1 % of the block's weight is +-0.1 kN a mount: stiff (11.0 kN peak) always above the 10.9 kN limit,
    # soft (10.7 kN peak) always below it
    scene["tolerances"] = {"machine.block.density": {"distribution": "uniform", "within": "1 %"}}
    answer = compare_products(scene, CATALOGUE, samples=16, require=0.9)
    types = answer["robustness"]["types"]
    assert set(types) == {"stiff", "soft", "soft_dear"}
    assert types["stiff"]["nominal"]["probability"] == 0.0
    assert types["soft"]["nominal"]["probability"] == types["soft_dear"]["nominal"]["probability"] == 1.0
    rec = answer["recommendation"]
    assert rec["basis"] == "probability" and rec["product"] == "soft" and rec["require"] == 0.9


def test_a_product_that_would_hit_its_stops_is_not_recommended() -> None:
    """A product that meets every criterion but deflects more than its stroke is passed over for the next
    cheapest, with the deflection and the stroke in the reason, as the sizing passes it over."""
    first = compare_products(SCENE, CATALOGUE)
    deflection = first["rows"]["soft"]["peak_isolator_deflection_z"]
    assert deflection > 0
    cat = copy.deepcopy(CATALOGUE)
    soft = next(p for p in cat["products"] if p["id"] == "soft")
    soft["stroke"] = 0.5 * deflection  # m
    answer = compare_products(SCENE, cat)
    assert answer["rows"]["soft"]["meets_criteria"] is True  # the criteria alone would take it
    rec = answer["recommendation"]
    assert rec["product"] == "soft_dear", rec
    assert "soft (would hit its stops" in rec["reason"] and "200% of its" in rec["reason"]
    assert size(SCENE, cat)["design"]["product"] == "soft_dear"
