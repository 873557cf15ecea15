"""``isolab compare``: one scene under each isolator type on this machine, with the recommended type."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import typer

from isolab.service.cli.input_errors import reported_input_errors

#: Columns shown besides the criteria margins: (column, label, scale, unit shown).
_SHOWN = (
    ("natural_frequency_1", "lowest natural frequency", 1.0, "Hz"),
    ("peak_displacement_y", "peak c.g. displacement y", 1e3, "mm"),
    ("peak_isolator_force_z", "peak isolator force z", 1e-3, "kN"),
    ("min_isolator_load_min", "smallest isolator load", 1e-3, "kN"),
    ("settling_time", "settling time", 1.0, "s"),
)


def _cell(value: Any, scale: float = 1.0, unit: str = "") -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    if isinstance(value, bool | np.bool_):
        return "yes" if value else "no"
    return f"{float(value) * scale:.4g} {unit}".rstrip()


def _probability(share: dict[str, Any] | None) -> str:
    if not share:
        return "-"
    lo, hi = share["interval"]
    return f"{share['probability']:.1%} ({lo:.1%}-{hi:.1%})"


def _fitted(product: dict[str, Any], currency: str) -> str:
    """A compared product of a catalogue comparison in words: count, load margin, pressure and cost."""
    margin = min(m for m in product["load_margin"] if m is not None)
    text = f"{sum(product['counts'])} isolators ({'/'.join(map(str, product['counts']))} per mount)"
    text += f", smallest load margin {margin:.0%}"
    pressures = [p for p in product["pressure"] if p is not None]
    if pressures:
        text += f", pressure {min(pressures) / 1e5:.3g}-{max(pressures) / 1e5:.3g} bar"
    return text + (f", {product['cost']:,.0f} {currency}" if product["cost"] is not None else ", no price")


def compare_command(
    scene: Annotated[
        Path,
        typer.Argument(
            help="Scene file, YAML or JSON; or a study file (its scene, floor and criteria are used).",
            exists=True,
            dir_okay=False,
        ),
    ],
    types: Annotated[
        str, typer.Option(help="Isolator types to compare, comma-separated.")
    ] = "active,air,elastomer",
    cost_order: Annotated[
        str | None,
        typer.Option(help="Types from the cheapest to the dearest (default elastomer,air,active)."),
    ] = None,
    duration: Annotated[
        str | None, typer.Option(help="Simulated time, e.g. 3 s (default: the scene's).")
    ] = None,
    tune: Annotated[
        bool,
        typer.Option(
            help="First tune each type's frequencies and damping to the criteria, within its range."
        ),
    ] = False,
    samples: Annotated[
        int, typer.Option(help="With tolerances in the scene: machines drawn from them per type.")
    ] = 200,
    require: Annotated[
        float,
        typer.Option(help="With tolerances: the probability of meeting every criterion a type must reach."),
    ] = 0.95,
    seed: Annotated[int, typer.Option(help="With tolerances: seed of the draws.")] = 0,
    catalogue: Annotated[
        str | None,
        typer.Option(
            help="Compare the products of this catalogue (a YAML or JSON file, or a shipped one's name) "
            "instead of the generic types; --types then picks the products' types."
        ),
    ] = None,
    margin: Annotated[
        float,
        typer.Option(
            min=0.0, max=0.9, help="With --catalogue: each static load may change by this fraction."
        ),
    ] = 0.10,
    per_corner: Annotated[
        str | None,
        typer.Option(help="With --catalogue: isolators a mount position may take, comma-separated."),
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print the answer as JSON (SI units).")] = False,
    csv: Annotated[
        Path | None, typer.Option(help="Write the table (one row per type, units in the header) here.")
    ] = None,
) -> None:
    """Run SCENE on each isolator type and print the side-by-side table: the scene's design criteria
    with each type's margin, the main outputs, and the recommended type (the cheapest that meets every
    criterion; with a tolerances block, the most probable type to meet them once built). With
    --catalogue, the rows are the catalogue's products that carry the scene's static loads, and the
    recommendation the cheapest priced product that meets every criterion."""

    from isolab.studies.answers.comparisons import compare, comparison_frame
    from isolab.studies.answers.product_comparison import compare_products
    from isolab.studies.inputs.catalogues import read_catalogue_file
    from isolab.studies.inputs.study import load_study, read_definition
    from isolab.studies.units import readable_unit

    with reported_input_errors():
        data, _ = read_definition(scene)
        if "scene" in data or "scene_file" in data:  # a study file: its scene on its floor, with its criteria
            study_scene = load_study(scene).scene
            assert study_scene is not None  # a validated study always has its scene
            data = study_scene.model_dump(mode="json", by_alias=True, exclude_none=True)
        kinds = [t.strip() for t in types.split(",") if t.strip()]
        if catalogue is not None and (tune or cost_order):
            raise ValueError("--catalogue compares products on their datasheet figures and prices: leave out "
                             "--tune and --cost-order")  # fmt: skip
        answer = (
            compare_products(
                data,
                read_catalogue_file(catalogue) if Path(catalogue).is_file() else catalogue,
                {"duration": duration} if duration else None,
                isolator_types=kinds,
                margin=margin,
                per_corner=[int(n) for n in per_corner.split(",") if n.strip()] if per_corner else None,
                samples=samples,
                require=require,
                seed=seed,
            )
            if catalogue is not None
            else compare(
                data,
                [t.strip() for t in types.split(",") if t.strip()],
                {"duration": duration} if duration else None,
                [t.strip() for t in cost_order.split(",") if t.strip()] if cost_order else None,
                tune=tune,
                samples=samples,
                require=require,
                seed=seed,
            )
        )
    if as_json:
        typer.echo(json.dumps(answer, indent=2))
        return
    df = comparison_frame(answer)
    if csv is not None:
        units = answer["units"]
        df.rename(columns={c: f"{c} [{units.get(c) or '1'}]" for c in df.columns}).to_csv(csv)
    from rich.console import Console
    from rich.table import Table

    names = list(df.index)
    block = answer.get("catalogue")
    table = Table(title=f"{scene.name}: " + (f"products of {block['name']}" if block else "isolator types"))
    table.add_column("")
    for t in names:
        table.add_column(t, justify="right")
    for req in answer.get("requirements", []):
        col = f"margin_{req['name']}"
        unit, one = readable_unit(req["unit"], [req["limit"]])
        limit = _cell(req["limit"], 1.0 / one, unit)
        label = req["name"] if req["name"] == "isolators_no_liftoff" else f"{req['name']} (limit {limit})"
        table.add_row(
            f"margin: {label}",
            *(_cell(None if df.at[t, col] is None else df.at[t, col] * 100, unit="%") for t in names),
        )
    if "meets_criteria" in df.columns:
        table.add_row("meets every criterion", *(_cell(df.at[t, "meets_criteria"]) for t in names))
    robust = answer.get("robustness") or {}
    for design in ("nominal", "tuned"):
        shares = {t: robust["types"][t].get(design) for t in names} if robust else {}
        if any(shares.values()):
            table.add_row(f"P(meets every criterion), {design}", *(_probability(shares[t]) for t in names))
    for col, label, scale, unit in _SHOWN:
        if col in df.columns:
            table.add_row(label, *(_cell(df.at[t, col], scale, unit) for t in names))
    Console().print(table)
    for t, found in (answer.get("tuning") or {}).items():
        v = found["values"]
        typer.echo(
            f"tuned {t}: f_vertical {v['f_vertical']:.2f} Hz, f_horizontal {v['f_horizontal']:.2f} Hz, "
            f"zeta {v['zeta']:.3f} ({found['evaluations']} cases)"
        )
    if robust:
        typer.echo(
            f"P: share of {robust['samples']} machines drawn independently from the tolerances (seed "
            f"{robust['seed']}) that meet every criterion, {robust['confidence']:.0%} Clopper-Pearson "
            "interval"
        )
    if block:
        for p in block["products"]:
            typer.echo(
                f"  {p['product']}: " + (_fitted(p, block["currency"]) if not p["reason"] else p["reason"])
            )
    rec = answer["recommendation"]
    pick = rec.get("product") or rec["isolator_type"]
    head = f"recommended: {pick}" if pick else "no recommendation"
    typer.echo(f"{head}. {rec['reason']}")
