"""``isolab calibrate``: fit a scene to measured motion on this machine (no service needed)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from isolab.service.cli.input_errors import reported_input_errors


def _number(value: float, unit: str) -> str:
    return f"{value:.6g} {unit}".rstrip()


def calibrate_command(
    scene: Annotated[Path, typer.Argument(help="Scene file, YAML or JSON.", exists=True, dir_okay=False)],
    measurement: Annotated[
        Path,
        typer.Argument(
            help="Measurement: CSV with a header (time [s], cg.z.displacement [mm], ...) or netCDF.",
            exists=True,
            dir_okay=False,
        ),
    ],
    fit: Annotated[
        list[str],
        typer.Option(
            "--fit",
            help="PATH=LOWER:UPPER[@START], e.g. isolators.f_vertical=1:6 or "
            "stages.y.mass=800 kg:1.2 t; repeat it for each parameter.",
        ),
    ],
    out: Annotated[
        Path | None,
        typer.Option("-o", "--out", help="Write the calibrated scene (YAML) here.", dir_okay=False),
    ] = None,
    offset: Annotated[
        str | None,
        typer.Option(
            help="Bounds of the time offset, LOWER:UPPER in s (default +- a quarter of the record), "
            "or a single value to hold it fixed."
        ),
    ] = None,
    fidelity: Annotated[
        str | None, typer.Option(help="lti, ltv or nonlinear (default: the scene's).")
    ] = None,
    integrator: Annotated[str | None, typer.Option(help="euler, rk4, exact or reference.")] = None,
    dt: Annotated[str | None, typer.Option(help="Step, e.g. 1 ms (default: the scene's).")] = None,
    highpass: Annotated[
        str | None, typer.Option(help="High-pass corner of acceleration channels, Hz (default 0.5; 0: off).")
    ] = None,
    lowpass: Annotated[
        str | None,
        typer.Option(help="Low-pass corner of acceleration channels, Hz (default min(fs/5, 0.03/dt))."),
    ] = None,
    noise: Annotated[
        list[str] | None,
        typer.Option(
            "--noise",
            help="CHANNEL=NOISE, a sensor's noise (one sample's standard deviation), e.g. "
            "cg.z.displacement=0.01 mm; repeat it per channel (default: estimated from the record).",
        ),
    ] = None,
    starts: Annotated[
        int, typer.Option(help="Fits from the scene's values and STARTS - 1 Sobol' points in the bounds.")
    ] = 1,
    plot: Annotated[
        Path | None, typer.Option(help="Write measured against simulated traces to a PNG.")
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print the answer as JSON (SI units).")] = False,
) -> None:
    """Fit scene parameters (and the time offset) to a measurement; print fitted values +- 1 sigma and
    the misfit per channel before and after."""
    from isolab.studies.answers.calibration import calibrate, parse_fit, read_measurement
    from isolab.studies.inputs.study import load_scene

    with reported_input_errors():
        specs = [parse_fit(f) for f in fit]
        sc = load_scene(scene)
        meas = read_measurement(measurement)
        off = None
        if offset is not None:
            lo, sep, hi = offset.partition(":")
            off = {"lower": lo.strip(), "upper": hi.strip()} if sep else {"value": lo.strip()}
        sim = {
            k: v for k, v in (("fidelity", fidelity), ("integrator", integrator), ("dt", dt)) if v is not None
        }
        stated: dict[str, str] = {}
        for item in noise or []:
            name, sep, value = item.partition("=")
            if not sep:
                raise ValueError(f"--noise {item!r}: write CHANNEL=NOISE, e.g. cg.z.displacement=0.01 mm")
            stated[name.strip()] = value.strip()
        result = calibrate(
            sc,
            meas,
            specs,
            offset=off,
            simulation=sim or None,
            highpass=highpass,
            lowpass=lowpass,
            prefix=[],
            noise=stated or None,
            starts=starts,
            scene_text=scene.read_text(encoding="utf-8"),
        )
    answer = result.to_json()
    if out is not None:
        out.write_text(result.scene_yaml, encoding="utf-8")
    if plot is not None:
        from isolab.service.plots.calibration import calibration_notes, calibration_png

        plot.write_bytes(
            calibration_png(
                result.traces, f"{scene.name} against {measurement.name}", calibration_notes(answer)
            )
        )
    if as_json:
        answer.pop("scene", None)
        typer.echo(json.dumps(answer, indent=2))
        return
    from rich.console import Console
    from rich.table import Table

    sim = answer["simulation"]
    console = Console(width=140)
    console.print(
        f"{scene} against {measurement}: {len(meas.channels)} channel(s), {meas.time.size} samples; "
        f"{sim['fidelity']}/{sim['integrator']} at {sim['dt'] * 1e3:g} ms; "
        f"{answer['evaluations']['engine_calls']} engine batches, {answer['evaluations']['cases']} cases"
    )
    table = Table("parameter", "start", "fitted", "± 1 sigma", "unit", "")
    for p in [*answer["parameters"], answer["time_offset"]]:
        if p["determined"]:
            table.add_row(
                p["path"], f"{p['start']:.6g}", f"{p['value']:.6g}", f"{p['sigma']:.2g}", p["unit"], ""
            )
        else:
            table.add_row(p["path"], f"{p['start']:.6g}", "-", "-", p["unit"], p["reason"] or "")
    console.print(table)
    misfit = Table("channel", "unit", "RMS measured", "misfit before", "misfit after")
    for ch, m in zip(answer["channels"], meas.channels, strict=True):
        f = m.factor if m.unit else 1.0
        misfit.add_row(
            ch["name"] + (" (band-passed)" if ch["filtered"] else ""),
            ch["unit"],
            f"{ch['rms_measured'] / f:.4g}",
            f"{ch['rms_before'] / f:.4g}",
            f"{ch['rms_after'] / f:.4g}",
        )
    console.print(misfit)
    console.print(f"fit: {answer['goodness_of_fit']['verdict']}")
    if answer["starts"]["count"] > 1:
        st = answer["starts"]
        console.print(f"starts: {st['count']}, {st['agreeing']} ending within 3 sigma of the best")
    if out is not None:
        console.print(f"calibrated scene -> {out}")
    if plot is not None:
        console.print(f"plot -> {plot}")
