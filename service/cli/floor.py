"""``isolab floor``: draw a point's floor-induced velocity spectrum per isolator type against the VC curves
(no service needed; nothing is integrated)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from isolab.service.cli.input_errors import reported_input_errors

ISOLATOR_TYPES = ("active", "air", "elastomer")


def floor_command(
    scene: Annotated[
        Path,
        typer.Argument(
            help="Scene file, YAML or JSON, with a floor spectrum (or a study file with its floor).",
            exists=True,
            dir_okay=False,
        ),
    ],
    point: Annotated[
        str | None, typer.Option(help="Point of interest to draw (default: the scene's first).")
    ] = None,
    types: Annotated[
        str, typer.Option("--types", help="Isolator types to compare, comma-separated.")
    ] = ",".join(ISOLATOR_TYPES),
    out: Annotated[Path, typer.Option("-o", "--out", help="Write the PNG here.", dir_okay=False)] = Path(
        "floor.png"
    ),
    coherence: Annotated[
        str | None,
        typer.Option(
            help="Coherence of the floor between mounts, replacing the scene's: correlated, uncorrelated, "
            "worst_phase, or several comma-separated to compare (the plot shows the first)."
        ),
    ] = None,
) -> None:
    """One-third-octave RMS velocity of a point per floor axis under the scene's floor.spectrum, one line
    per isolator type, against the VC-A .. VC-G curves; prints the worst band of each type."""

    from isolab.service.plots.studies import floor_velocity_png
    from isolab.studies.answers.floor_response import velocity_spectra
    from isolab.studies.inputs.schema.floor_motion import FLOOR_COHERENCE
    from isolab.studies.inputs.study import load_scene, load_study, read_definition

    chosen = [t.strip() for t in types.split(",") if t.strip()]
    unknown = [t for t in chosen if t not in ISOLATOR_TYPES]
    if unknown or not chosen:
        typer.echo(
            f"error: --types: unknown isolator type(s) {unknown}; choose from {', '.join(ISOLATOR_TYPES)}"
        )
        raise typer.Exit(code=2)
    coherences = [c.strip() for c in (coherence or "").split(",") if c.strip()]
    wrong = [c for c in coherences if c not in FLOOR_COHERENCE]
    if wrong:
        typer.echo(f"error: --coherence: unknown {wrong}; choose from {', '.join(FLOOR_COHERENCE)}")
        raise typer.Exit(code=2)
    with reported_input_errors():
        data, _ = read_definition(scene)
        if "scene" in data or "scene_file" in data:  # a study file: its scene on its own floor
            sc = load_study(scene).scene
        else:
            sc = load_scene(scene)
        if sc is None:  # a validated study always has its scene
            raise ValueError("scene: missing")
        runs: dict[str | None, dict] = {}
        if not coherences:
            runs[None] = velocity_spectra(sc, chosen, point)
        for c in coherences:
            if sc.floor is None:
                raise ValueError("floor: the scene has no floor spectrum")
            floor = sc.floor.model_copy(update={"coherence": c, "wave": None})
            runs[c] = velocity_spectra(sc.model_copy(update={"floor": floor}), chosen, point)
        spectra = next(iter(runs.values()))
    out.write_bytes(floor_velocity_png(spectra, f"{scene.name}: {spectra['point']} under the floor spectrum"))
    for coh, run in runs.items():
        for t, (v, f, axis) in run["worst"].items():
            label = t if coh is None else f"{t}, {coh}"
            if v == v:
                per_axis = ", ".join(
                    f"{a} {run['velocity'][t][k].max() * 1e6:.3g}" for k, a in enumerate(("x", "y", "z"))
                )
                typer.echo(
                    f"{label}: worst band {v * 1e6:.3g} um/s RMS at {f:.3g} Hz along {axis} ({per_axis})"
                )
            else:
                typer.echo(f"{label}: no steady state (the base tips over or is a mechanism)")
    typer.echo(f"plot -> {out}")
