"""Commands that run on this machine without the HTTP service: ``simulate`` one scene, ``run`` a study."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Annotated

import numpy as np
import typer


def _labelled(values, labels) -> dict:
    return {name: float(v) for name, v in zip(labels, values, strict=True)}


def case_outputs(result, case: int, isolators: list[str], points: list[str]) -> dict:
    """One case's outputs keyed by quantity and by axis, isolator, point or mode (SI units)."""
    from isolab.studies import AXES, DOF_NAMES, ROTATIONS, STATUS_NAMES

    r = result
    ok = int(r.status[case]) == 0
    out = {
        "status": STATUS_NAMES[int(r.status[case])],
        "message": r.message[case],
        "dt": float(r.dt[case]),
        "natural_frequency": [float(f) for f in r.natural_frequency[case]],
        "damping_ratio": [float(z) for z in r.damping_ratio[case]],
        "mode_energy": [_labelled(e, DOF_NAMES) for e in r.mode_energy[case]],
        "mechanism": [bool(m) for m in r.mechanism[case]],
        "static_isolator_load": _labelled(r.static_isolator_load[case], isolators),
        "units": {
            "peak_displacement": "m",
            "peak_rotation": "rad",
            "peak_point_displacement": "m",
            "peak_isolator_force": "N",
            "min_isolator_load": "N",
            "static_isolator_load": "N",
            "rms_displacement": "m",
            "settling_time": "s",
            "natural_frequency": "Hz",
            "damping_ratio": "1",
            "transmissibility": "1",
            "dt": "s",
        },
    }
    if not ok:
        return out
    out.update(
        peak_displacement=_labelled(r.peak_displacement[case], AXES),
        peak_rotation=_labelled(r.peak_rotation[case], ROTATIONS),
        peak_point_displacement={
            p: _labelled(v, AXES) for p, v in zip(points, r.peak_point_displacement[case], strict=True)
        },
        peak_isolator_force={
            i: _labelled(v, AXES) for i, v in zip(isolators, r.peak_isolator_force[case], strict=True)
        },
        min_isolator_load=_labelled(r.min_isolator_load[case], isolators),
        liftoff={i: bool(v < 0) for i, v in zip(isolators, r.min_isolator_load[case], strict=True)},
        rms_displacement=_labelled(r.rms_displacement[case], AXES),
        final_displacement=_labelled(r.final_displacement[case], AXES + ROTATIONS),
        settling_time=float(r.settling_time[case]),
        settled=bool(r.settled[case]),
        transmissibility=_labelled(r.transmissibility[case], AXES),
    )
    return out


def simulate(
    scene: Annotated[Path, typer.Argument(help="Scene file, YAML or JSON.", exists=True, dir_okay=False)],
    as_json: Annotated[bool, typer.Option("--json", help="Print the outputs as JSON.")] = False,
    fidelity: Annotated[str | None, typer.Option(help="lti, ltv or nonlinear (default: scene's).")] = None,
    integrator: Annotated[str | None, typer.Option(help="euler, rk4, exact or reference.")] = None,
    dt: Annotated[float | None, typer.Option(help="Step, s (default: the scene's).")] = None,
    plot: Annotated[Path | None, typer.Option(help="Write c.g., rotation and force traces to a PNG.")] = None,
) -> None:
    """Simulate one scene and print its peaks, loads, natural frequencies and settling time."""
    from isolab.studies import SceneError
    from isolab.studies import simulate as run
    from isolab.studies.study import load_scene, scene_batch

    try:
        sc = load_scene(scene)
        batch, names = scene_batch(sc)
        sim = sc.simulation
        fid = fidelity or sim.fidelity
        integ = integrator or sim.integrator
        step = dt or sim.dt
        reason = None
        if sim.request is not None and not (fidelity and integrator and dt):
            # the scene asks for an accuracy: measure the cheapest model that meets it on this scene
            from isolab.studies.accuracy import choose
            from isolab.studies.study import Study

            choice = choose(Study.model_validate({"name": scene.stem, "scene": sc.model_dump(mode="json")}))
            fid, integ = fidelity or choice.fidelity, integrator or choice.integrator
            step, reason = dt or choice.dt, choice.reason
        if fid is None or integ is None or step is None:  # resolved above; a scene always has defaults
            raise ValueError("simulation: no fidelity, integrator and step to run with")
        t0 = time.perf_counter()
        result = run(batch, fid, integ, step, auto_step=sim.auto_step, record=[0] if plot else None)
        elapsed = time.perf_counter() - t0
    except (SceneError, ValueError) as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(code=2) from None
    out = {
        "scene": str(scene),
        "fidelity": fid,
        "integrator": integ,
        "dt": float(step),
        **({"accuracy": reason} if reason else {}),
        "duration": float(batch.duration[0]),  # type: ignore[index]  # set by scene_batch
        "isolators": names["isolators"],
        "points": names["points"],
        "stages": names["stages"],
        "wall_time": elapsed,
        **case_outputs(result, 0, names["isolators"], names["points"]),
    }
    if plot:
        from isolab.service.plots import case_png

        h = result.history
        assert h is not None  # recorded above
        n = int(h["n_samples"][0])
        plot.write_bytes(
            case_png(
                h["time"][0, :n],
                h["displacement"][0, :n],
                h["rotation"][0, :n],
                h["isolator_force"][0, :n],
                names["isolators"],
                title=f"{scene.name} ({fid}/{integ})",
            )
        )
        out["plot"] = str(plot)
    if as_json:
        typer.echo(json.dumps(out, indent=2))
        return
    typer.echo(f"{scene}: {out['status']} ({fid}/{integ}, dt {result.dt[0]:.3g} s, {elapsed:.2f} s wall)")
    if reason:
        typer.echo(f"  chosen for the accuracy asked: {reason}")
    if out["message"]:
        typer.echo(f"  {out['message']}")
    if out["status"] != "ok":
        return
    pd = out["peak_displacement"]
    pr = out["peak_rotation"]
    from isolab.studies import AXES, ROTATIONS

    typer.echo("  peak c.g. displacement  " + "  ".join(f"{a} {pd[a] * 1e3:.3f} mm" for a in AXES))
    typer.echo("  peak rotation           " + "  ".join(f"{a} {pr[a] * 1e3:.3f} mrad" for a in ROTATIONS))
    typer.echo("  natural frequencies     " + ", ".join(f"{f:.2f}" for f in out["natural_frequency"]) + " Hz")
    loads = ", ".join(f"{k} {v:.0f} N" for k, v in out["min_isolator_load"].items())
    typer.echo("  min isolator load       " + loads)
    st = "settled" if out["settled"] else "NOT settled (lower bound)"
    typer.echo(f"  settling time           {out['settling_time']:.3f} s ({st})")


def run_study_command(
    study: Annotated[Path, typer.Argument(help="Study file (YAML or JSON).", exists=True, dir_okay=False)],
    out: Annotated[Path, typer.Option("-o", "--out", help="Write the dataset to this netCDF file.")],
    workers: Annotated[int, typer.Option(min=1, help="Local Dask worker processes.")] = 2,
) -> None:
    """Run a study on a local Dask cluster with a progress bar and write its dataset."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from isolab.studies.runner import run_local

    with Progress(
        TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn()
    ) as bar:
        task = bar.add_task(study.name, total=None)

        def progress(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        t0 = time.perf_counter()
        try:
            ds = run_local(study, out, workers=workers, progress=progress)
        except ValueError as exc:
            typer.echo(f"error: {exc}", err=True)
            raise typer.Exit(code=2) from None
    wall = time.perf_counter() - t0
    n = int(ds.attrs.get("n_cases", 0)) or int(np.prod([ds.sizes[d] for d in ds.status.dims]))
    typer.echo(f"{n} cases in {wall:.1f} s ({n / wall:.1f} cases/s) -> {out}")
