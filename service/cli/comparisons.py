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


CLI_WIDTH = 100
"""Characters a catalogue comparison's tables are laid out in (narrower terminals wrap the verdicts)."""
REASON_CHARACTERS = 150
"""Longest verdict of one product in the table; the whole reason is in ``--json``."""


def _span(values: list[float], scale: float) -> str:
    """The range of ``values`` (SI) times ``scale``: ``3.57-4.22``, one number when they agree, ``-``."""
    if not values:
        return "-"
    lo, hi = min(values) * scale, max(values) * scale
    return f"{lo:.3g}" if f"{lo:.3g}" == f"{hi:.3g}" else f"{lo:.3g}-{hi:.3g}"


def _short(text: str, limit: int = REASON_CHARACTERS) -> str:
    """``text`` on one line, cut at a word to at most ``limit`` characters (``...`` marks the cut)."""
    import textwrap

    return textwrap.shorten(" ".join(text.split()), width=limit, placeholder=" ...")


def _missing(value: Any) -> bool:
    """No value: None, NaN or pandas' NA."""
    import pandas as pd

    return value is None or bool(pd.isna(value))


def print_products(answer: dict[str, Any], title: str, width: int = CLI_WIDTH) -> None:
    """A catalogue comparison in ``width`` characters (less on a narrower terminal), one row per product,
    cheapest first: each criterion's margin (%); the isolators, cost, smallest load margin (%), pressure
    (bar), stroke used (%), criteria met and verdict; why each rejected product is rejected, wrapped and
    cut to :data:`REASON_CHARACTERS` (the whole reason is in ``--json``); and the recommendation."""
    import shutil
    import textwrap

    from rich import box
    from rich.console import Console
    from rich.table import Table
    from rich.text import Text

    from isolab.studies.answers.product_comparison import product_frame

    df = product_frame(answer)
    block = answer["catalogue"]
    console = Console(width=min(width, shutil.get_terminal_size((width, 24)).columns))
    reqs = answer.get("requirements") or []
    rows = answer["rows"]
    widest = max(len(str(t)) for t in df.index)

    def table(heading: str) -> Table:
        out = Table(
            title=Text(f"{title}: {heading}"),  # Text: brackets in a name are no markup
            box=box.SIMPLE_HEAD,
            padding=(0, 0, 0, 1),
            show_edge=False,
            title_justify="left",
        )
        out.add_column("product", no_wrap=True, min_width=widest)
        return out

    compared = [t for t in df.index if t in rows]
    if reqs and compared:
        margins = table("margin to each criterion [%]")
        for r in reqs:
            margins.add_column(Text(r["name"].replace("_", " ")), justify="right")
        for t in compared:
            values = [rows[t].get(f"margin_{r['name']}") for r in reqs]
            margins.add_row(Text(str(t)), *(Text(_cell(None if v is None else v * 100)) for v in values))
        console.print(margins)
    console.print()
    products = table(f"products of {block['name']}, load margin {block['margin']:.0%}, cheapest first")
    for head in ("isolators", f"cost\n[{block['currency']}]", "load\nmargin\n[%]", "pressure\n[bar]",
                 "stroke\nused\n[%]", "criteria\nmet"):  # fmt: skip
        products.add_column(Text(head), justify="right")
    products.add_column("verdict")
    rejected: list[tuple[str, str]] = []
    for t, line in df.iterrows():
        p = next(x for x in block["products"] if x["product"] == t)
        counts = p["counts"] if t in rows else []
        count = "-" if not counts else str(sum(counts))
        if len(set(counts)) > 1:
            count += f" ({line['per_mount']})"
        elif counts and counts[0] > 1:
            count += f" ({counts[0]}/mount)"
        if line["recommended"]:
            verdict = "RECOMMENDED"
        elif line["feasible"]:
            verdict = "meets all" if reqs else "fits"
        else:
            verdict = "rejected" if t in rows else "no fit"
            rejected.append((str(t), _short(str(line["why_not"]))))
        products.add_row(
            Text(str(t)),
            count,
            "-" if _missing(line["cost"]) else f"{line['cost']:,.0f}",
            _cell(line["load_margin"], 100.0),
            _span([x for x in p["pressure"] if x is not None] if counts else [], 1e-5),
            _cell(None if _missing(line["stroke_used"]) else line["stroke_used"], 100.0),
            "-" if _missing(line["criteria_met"]) else f"{line['criteria_met']} of {len(reqs)}",
            verdict,
        )
    console.print(products)
    if rejected:
        console.print()
        why = table("why not")
        why.add_column("reason", ratio=1)
        for t, reason in rejected:
            why.add_row(Text(t), Text(reason))
        console.print(why)
    rec = answer["recommendation"]
    pick = rec.get("product")
    # the cheaper products' failures are in the table above: the reason without them
    reason = rec["reason"].split(". Cheaper: ")[0] if pick else rec["reason"]
    text = f"recommended: {pick}. {reason}" if pick else f"no recommendation. {reason}"
    typer.echo(textwrap.fill(_short(text, 3 * console.width), width=console.width, break_on_hyphens=False))


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
    block = answer.get("catalogue")
    if block:
        print_products(answer, scene.name)
        return
    from rich.console import Console
    from rich.table import Table

    names = list(df.index)
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
    rec = answer["recommendation"]
    pick = rec.get("product") or rec["isolator_type"]
    head = f"recommended: {pick}" if pick else "no recommendation"
    typer.echo(f"{head}. {rec['reason']}")
