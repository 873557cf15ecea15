"""``isolab size``: the isolators of a scene chosen from a catalogue (product, count, pressure, margins)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any

import typer

from isolab.service.cli.input_errors import reported_input_errors


def _per_mount_line(row: dict[str, Any]) -> str:
    """One mount of a sizing in words (kN, bar, mm, %)."""
    if row.get("product") is None:
        return f"  {row['mount']}: static load {row['static_load'] / 1e3:.3g} kN; {row.get('reason', '')}"
    parts = [
        f"  {row['mount']}: {row['count']} x {row['product']}",
        f"static load {row['static_load'] / 1e3:.3g} kN ({row['load_per_isolator'] / 1e3:.3g} kN each)",
        f"load margin {row['load_margin']:.0%}",
    ]
    if row.get("pressure") is not None:
        parts.append(f"pressure {row['pressure'] / 1e5:.3g} bar")
    if row.get("stroke_used") is not None:
        parts.append(
            f"stroke used {row['stroke_used']:.0%} ({row['peak_deflection'] * 1e3:.3g} of "
            f"{row['stroke'] * 1e3:.3g} mm)"
        )
    return ", ".join(parts)


def size_command(
    scene: Annotated[
        Path,
        typer.Argument(
            help="Scene file, YAML or JSON; or a study file (its scene, floor and criteria are used).",
            exists=True,
            dir_okay=False,
        ),
    ],
    catalogue: Annotated[
        str,
        typer.Option(help="Catalogue file (YAML or JSON), or the name of a shipped one."),
    ] = "representative",
    margin: Annotated[
        float,
        typer.Option(min=0.0, max=0.9, help="Load margin: each static load may change by this fraction."),
    ] = 0.10,
    per_corner: Annotated[
        str | None,
        typer.Option(
            help="Isolators a mount position may take, comma-separated (default: the scene's, or 1)."
        ),
    ] = None,
    duration: Annotated[
        str | None, typer.Option(help="Simulated time, e.g. 3 s (default: the scene's).")
    ] = None,
    max_cases: Annotated[int, typer.Option(min=1, max=64, help="Most candidate designs simulated.")] = 32,
    as_json: Annotated[bool, typer.Option("--json", help="Print the answer as JSON (SI units).")] = False,
) -> None:
    """Choose SCENE's isolators from a catalogue: for each mount position the product and count whose
    static load sits inside its rated range with the margin, meeting the scene's criteria, at the lowest
    cost; with the pressure, the stroke used and why each cheaper product fails."""

    from isolab.studies.answers.sizing import size
    from isolab.studies.inputs.catalogues import inline_catalogue_file, load_catalogue
    from isolab.studies.inputs.study import load_study, read_definition

    with reported_input_errors("catalogue: "):
        data, here = read_definition(scene)
        if "scene" in data or "scene_file" in data:  # a study file: its scene on its floor, with its criteria
            study_scene = load_study(scene).scene
            assert study_scene is not None  # a validated study always has its scene
            data = study_scene.model_dump(mode="json", by_alias=True, exclude_none=True)
        else:
            data = inline_catalogue_file(data, here)
        cat = load_catalogue(catalogue)
        answer = size(
            data,
            cat,
            margin=margin,
            per_corner=[int(n) for n in per_corner.split(",") if n.strip()] if per_corner else None,
            simulation={"duration": duration} if duration else None,
            max_cases=max_cases,
        )
    if as_json:
        typer.echo(json.dumps(answer, indent=2))
        return
    typer.echo(("sized: " if answer["feasible"] else "") + answer["summary"])
    for row in answer["mounts"]:
        typer.echo(_per_mount_line(row))
    for c in answer["candidates"]:
        if c["verdict"] != "chosen" and c["reason"]:
            typer.echo(f"  {c['product']}: {c['reason']}")
    typer.echo(f"{answer['cases_run']} candidate design(s) simulated")
