"""One scene on each product of a catalogue, side by side, and the product to buy.

The comparison of :mod:`isolab.studies.answers.comparisons` runs a scene on the three generic isolator types;
given a catalogue it runs it on the catalogue's products instead. Each product stands at every mount position
of the scene with the fewest isolators side by side (of ``per_corner``) that carry the position's static
load inside its rated range with the load margin (:func:`isolab.studies.answers.sizing.product_candidates`,
as the sizing does); a product whose rated range the loads do not fit is skipped, with the reason. The others
run as one grid study over ``isolators.model`` and are judged on the scene's criteria, and, with a
``tolerances:`` block, on machines drawn from it (the probability of meeting every criterion, as the generic
comparison does).

The recommendation (:func:`recommend_product`): of the products that meet every criterion (with tolerances:
that reach the required probability), the cheapest where priced; where no priced product does, the
unpriced one with the largest smallest margin.
"""

from __future__ import annotations

import copy
import math
from typing import Any

from isolab.studies.answers import robustness
from isolab.studies.answers.comparisons import (
    comparison_study,
    comparison_table,
    failed_criteria,
    recommend,
    requirements,
    run_comparison,
)
from isolab.studies.answers.sizing import (
    Candidate,
    product_candidates,
    requested_catalogue,
    scene_loads,
)
from isolab.studies.inputs.catalogues import DEFAULT_LOAD_MARGIN, Catalogue
from isolab.studies.inputs.definitions import DefinitionError, detail
from isolab.studies.inputs.isolators import mount_labels
from isolab.studies.inputs.schema.scene_paths import ISOLATOR_MODEL
from isolab.studies.inputs.study import validate_scene
from isolab.studies.run.accuracy import resolved_study

PRODUCT_KEY = "product"
"""The case-table column (and parameter name) of the product each row stands on."""


def _product_rows(candidates: list[Candidate], compared: set[str]) -> list[dict[str, Any]]:
    """Every product of the catalogue: its count, load per isolator, load margin and pressure per mount,
    cost, and whether it was compared or skipped (with the reason)."""
    out = []
    for c in candidates:
        p = c.product
        out.append(
            {
                "product": p.id,
                "label": p.label(),
                "type": p.type,
                "counts": [f.count for f in c.fits],
                "load_per_isolator": [f.load if f.count is not None else None for f in c.fits],
                "load_margin": [f.margin for f in c.fits],
                "pressure": [f.pressure for f in c.fits],
                "unit_price": p.price,
                "cost": c.cost,
                "lead_time": p.lead_time,
                "stroke": p.stroke,
                "source": p.source,
                "verdict": "compared" if p.id in compared else "skipped",
                "reason": None if p.id in compared else c.reason,
            }
        )
    return out


def _cost_text(c: Candidate, currency: str) -> str:
    return f"{c.count} x {c.product.id}" + (
        f" for {c.cost:,.0f} {currency}" if c.cost is not None else " (no price)"
    )


def stroke_text(row: dict[str, Any], stroke: float | None) -> str | None:
    """Why a compared product cannot be bought, in words, when its peak vertical deflection (the row's
    ``peak_isolator_deflection_z``, m) is more than its ``stroke`` (m): the isolator would hit its stops.
    None when it stays inside, or either is unknown."""
    deflection = row.get("peak_isolator_deflection_z")
    if stroke is None or deflection is None or not math.isfinite(float(deflection)):
        return None
    if float(deflection) <= stroke:
        return None
    return (
        f"(would hit its stops: peak deflection {float(deflection) * 1e3:.3g} mm, "
        f"{float(deflection) / stroke:.0%} of its {stroke * 1e3:.3g} mm stroke)"
    )


def recommend_product(
    rows: dict[str, dict[str, Any]],
    criteria: list[str],
    compared: list[Candidate],
    currency: str,
    judged: dict[str, robustness.Reliability] | None = None,
    require: float = robustness.DEFAULT_REQUIRE,
) -> dict[str, Any]:
    """The product to buy of those ``compared`` (their comparison ``rows``, product id -> column -> value):
    the cheapest priced product that meets every criterion, else the unpriced one with the largest smallest
    margin; with ``judged`` (the probability of meeting every criterion under the tolerances) a product
    must reach ``require`` instead of meeting them as drawn. A product whose peak deflection is more than
    its stroke (:func:`stroke_text`) is never recommended, however it meets the criteria.

    Answers ``product`` (None when there are no criteria or none qualifies), its ``isolator_type``, the
    ``cost_order`` the products were ranked in (priced by cost, then unpriced by margin), ``basis``
    (``cost``, ``margin`` or, with tolerances, ``probability``) and the ``reason`` in words.
    """
    priced = sorted((c for c in compared if c.cost is not None), key=lambda c: (c.cost, c.product.id))
    unpriced = sorted(
        (c for c in compared if c.cost is None),
        key=lambda c: (-robustness.smallest_margin(rows[c.product.id], criteria), c.product.id),
    )
    order = [c.product.id for c in priced + unpriced]
    over = {
        c.product.id: stroke_text(rows[c.product.id], c.product.stroke)
        for c in compared
        if stroke_text(rows[c.product.id], c.product.stroke) is not None
    }
    eligible = [t for t in order if t not in over]
    if judged is None:
        base = recommend(rows, criteria, eligible)
    else:
        base = robustness.recommend_on_probability(rows, criteria, judged, require, eligible)
    pick = base["isolator_type"]
    by_id = {c.product.id: c for c in compared}
    answer: dict[str, Any] = {
        "isolator_type": by_id[pick].product.type if pick is not None else None,
        "product": pick,
        "cost_order": order,
        "basis": "probability" if judged is not None else None,
    }
    if judged is not None:
        answer["require"] = float(require)

    def shown(pid: str) -> str:
        if pid in over:
            return f"{pid} {over[pid]}"
        if judged is not None:
            return f"{pid} {judged[pid].text()}"
        return f"{pid} {failed_criteria(rows[pid], criteria)}"

    if not criteria:
        answer["reason"] = base["reason"]
        return answer
    if pick is None:
        closest = max(order, key=lambda t: robustness.smallest_margin(rows[t], criteria), default=None)
        meets = "meets every criterion" + (f" with the required probability {require:.0%}" if judged else "")
        answer["reason"] = (
            f"no product of the catalogue {meets}: {'; '.join(shown(t) for t in order)}"
            + (
                f". Closest: {closest} (smallest margin "
                f"{robustness.smallest_margin(rows[closest], criteria):+.0%})"
                if closest is not None
                else ""
            )
            + "; relax the criteria, or tune or place the mounts differently"
        )
        return answer
    chosen = by_id[pick]
    weakest = min(criteria, key=lambda c: float(rows[pick].get(f"margin_{c}") or 0.0))
    margin = robustness.smallest_margin(rows[pick], criteria)
    how = (
        f"meets every criterion with the required probability {require:.0%} ({judged[pick].text()})"
        if judged is not None
        else f"meets every criterion (smallest margin {margin:+.0%} on {weakest})"
    )
    cheaper = [shown(t) for t in order[: order.index(pick)] if by_id[t].cost is not None]
    if chosen.cost is not None:
        answer["basis"] = answer["basis"] or "cost"
        answer["reason"] = f"{_cost_text(chosen, currency)} is the cheapest priced product that {how}" + (
            f". Cheaper: {'; '.join(cheaper)}" if cheaper else ""
        )
    else:
        answer["basis"] = answer["basis"] or "margin"
        answer["reason"] = (
            f"no priced product qualifies ({'; '.join(cheaper) or 'none is priced'}); of the unpriced, "
            f"{chosen.count} x {pick} {how}, the largest smallest margin"
        )
    return answer


def compare_products(
    scene: Any,
    catalogue: Catalogue | str | dict[str, Any] | None,
    simulation: Any = None,
    *,
    isolator_types: list[str] | None = None,
    margin: float = DEFAULT_LOAD_MARGIN,
    per_corner: list[int] | None = None,
    samples: int | None = None,
    require: float | None = None,
    seed: int = 0,
) -> dict[str, Any]:
    """Run ``scene`` on each product of ``catalogue`` (of ``isolator_types``, default every type) whose
    rated range carries the scene's static loads with ``margin`` (``per_corner``: the counts a position may
    take), side by side as :func:`~isolab.studies.answers.comparisons.comparison_table` (one row per product
    id), with the product to buy (:func:`recommend_product`) and ``catalogue``: every product's count,
    load per isolator (N), load margin (1), pressure (Pa), cost, and the reason a skipped one does not fit.
    With a ``tolerances:`` block, ``robustness`` as in :func:`~isolab.studies.answers.comparisons.compare`.
    A catalogue none of whose products fits is an answer (no rows, no recommendation, the reasons), not
    an error.

    Raises:
        DefinitionError: bad input, naming the field (``body.catalogue...``, ``body.scene...``).
    """
    cat = requested_catalogue(catalogue)
    base, counts, loads = scene_loads(scene, per_corner)
    base.setdefault("isolators", {})["catalogue"] = cat.model_dump(mode="json", exclude_none=True)
    kinds = set(isolator_types or ("active", "air", "elastomer"))
    candidates = [c for c in product_candidates(cat, loads, margin, counts) if c.product.type in kinds]
    if not candidates:
        raise DefinitionError(
            [detail(["body", "isolator_types"], f"no product of catalogue {cat.name!r} is of these types")]
        )
    fitting = [c for c in candidates if c.feasible]
    scene_model = validate_scene(base)
    robust = bool(scene_model.tolerances)
    if robust:
        samples, require = robustness.robust_request(samples, require)
    labels = mount_labels(len(loads))
    block = {
        "name": cat.name,
        "currency": cat.currency,
        "margin": margin,
        "per_corner": counts,
        "static_load": dict(zip(labels, map(float, loads), strict=True)),
        "products": _product_rows(candidates, {c.product.id for c in fitting}),
    }
    if not fitting:
        return _nothing_fits(cat, scene_model, block)
    study = resolved_study(
        comparison_study(base, [c.product.id for c in fitting], simulation, path=ISOLATOR_MODEL)
    )
    try:
        table = run_comparison(study)
    except ValueError as err:
        raise DefinitionError([detail(["body", "scene"], str(err))]) from None
    answer = comparison_table(table, study, key=PRODUCT_KEY)
    answer["catalogue"] = block
    judged_names = study.criteria.names() if study.criteria is not None else []
    judged = None
    if robust:
        assert samples is not None and require is not None
        nominal = copy.deepcopy(base)
        sim = study.simulation.model_dump(mode="json")
        try:
            answer = robustness.robustness_answer(
                answer, nominal, None, sim, judged_names, samples, require, seed, choice="model"
            )
        except DefinitionError:
            raise
        except ValueError as err:
            raise DefinitionError([detail(["body", "scene"], str(err))]) from None
        judged = {
            t: robustness.Reliability.from_dict(t, "nominal", r["nominal"])
            for t, r in answer["robustness"]["types"].items()
        }
    answer["recommendation"] = recommend_product(
        answer["rows"], judged_names, fitting, cat.currency, judged, require or robustness.DEFAULT_REQUIRE
    )
    return answer


def _nothing_fits(cat: Catalogue, scene: Any, block: dict[str, Any]) -> dict[str, Any]:
    """The answer when no product's rated range carries the scene's loads: nothing run, the reasons."""
    loads = ", ".join(f"{m} {w / 1e3:.3g} kN" for m, w in block["static_load"].items())
    why = "; ".join(f"{p['product']}: {p['reason']}" for p in block["products"])
    counts = " or ".join(map(str, block["per_corner"]))
    return {
        "isolator_types": [],
        "columns": [],
        "units": {},
        "rows": {},
        "best": {},
        "criteria": {},
        "requirements": requirements(scene.criteria),
        "recommendation": {
            "isolator_type": None,
            "product": None,
            "cost_order": [],
            "reason": f"no product of catalogue {cat.name!r} carries the static loads ({loads}) inside its "
            f"rated range with a {block['margin']:.0%} margin on {counts} isolator(s) per mount: {why}",
        },
        "simulation": scene.simulation.model_dump(mode="json"),
        "catalogue": block,
    }


PRODUCT_UNITS: dict[str, str] = {
    "count": "1",
    "unit_price": "currency",
    "cost": "currency",
    "pressure_min": "Pa",
    "pressure_max": "Pa",
    "load_margin": "1",
    "peak_deflection": "m",
    "stroke": "m",
    "stroke_used": "1",
    "criteria_met": "1",
}
"""The unit of each numeric column of :func:`product_frame` (``currency``: the catalogue's)."""


def _product_line(
    p: dict[str, Any], row: dict[str, Any] | None, criteria: list[str], pick: str | None
) -> dict[str, Any]:
    """One product of a catalogue comparison as a line of :func:`product_frame`."""
    compared = row is not None
    pressures = [x for x in p["pressure"] if x is not None] if compared else []
    margins = [m for m in p["load_margin"] if m is not None]
    deflection = None
    stroke = p.get("stroke")
    met: list[str] = []
    feasible = False
    why_not = p["reason"]
    if row is not None:
        deflection = row.get("peak_isolator_deflection_z")
        met = [c for c in criteria if row.get(f"margin_{c}") is not None and row[f"margin_{c}"] >= 0.0]
        feasible = bool(row.get("meets_criteria")) if criteria else row.get("status") == "ok"
        why_not = None if feasible else failed_criteria(row, criteria)
        stops = stroke_text(row, stroke)
        if stops is not None:
            feasible = False
            why_not = stops[1:-1] if why_not is None else f"{why_not}; {stops[1:-1]}"
    return {
        "type": p["type"],
        "count": sum(p["counts"]) if compared else None,
        "per_mount": "/".join(map(str, p["counts"])) if compared else None,
        "unit_price": p["unit_price"],
        "cost": p["cost"],
        "feasible": feasible,
        "why_not": why_not,
        "pressure_min": min(pressures) if pressures else None,
        "pressure_max": max(pressures) if pressures else None,
        "load_margin": min(margins) if margins else None,
        "peak_deflection": deflection,
        "stroke": stroke,
        "stroke_used": deflection / stroke if deflection is not None and stroke else None,
        "criteria_met": len(met) if compared and criteria else None,
        "recommended": p["product"] == pick,
    }


def product_frame(answer: dict[str, Any]) -> Any:
    """A catalogue comparison's answer (:func:`compare_products`, or the JSON of ``POST /comparisons`` with a
    catalogue) as a pandas DataFrame, one row per product of the catalogue (index ``product``), cheapest
    first (unpriced, then skipped, after): ``type``; ``count`` (isolators in all) and ``per_mount``;
    ``unit_price`` and ``cost`` (the catalogue's currency); ``feasible`` (compared and meets every
    criterion) and ``why_not`` in words (the load out of range, or the criteria missed by how much);
    ``pressure_min`` and ``pressure_max`` over the mounts (Pa); ``load_margin``, the smallest (1);
    ``peak_deflection`` (m), ``stroke`` (m) and ``stroke_used`` (1); ``criteria_met`` (of
    ``len(attrs["requirements"])``); ``recommended``. ``attrs`` carries ``recommendation``,
    ``requirements``, ``units`` (column -> unit), ``currency``, ``catalogue`` (its name) and ``margin``.

    Raises:
        KeyError: an answer without a catalogue block (a comparison of the generic types).
    """
    import pandas as pd

    block = answer["catalogue"]
    criteria = [r["name"] for r in answer.get("requirements") or []]
    pick = answer["recommendation"].get("product")
    lines = {
        p["product"]: _product_line(p, answer["rows"].get(p["product"]), criteria, pick)
        for p in block["products"]
    }
    order = sorted(
        lines,
        key=lambda t: (lines[t]["count"] is None, lines[t]["cost"] is None, lines[t]["cost"] or 0.0),
    )
    df = pd.DataFrame([lines[t] for t in order], index=pd.Index(order, name="product"))
    df = df.astype({"count": "Int64", "criteria_met": "Int64"})
    df.attrs.update(
        recommendation=answer["recommendation"],
        requirements=answer.get("requirements") or [],
        units={c: block["currency"] if u == "currency" else u for c, u in PRODUCT_UNITS.items()},
        currency=block["currency"],
        catalogue=block["name"],
        margin=block["margin"],
    )
    return df
