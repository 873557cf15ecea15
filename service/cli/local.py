"""Commands that run on this machine without the HTTP service: ``simulate`` one scene, ``run`` a study."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, NoReturn

import numpy as np
import typer

if TYPE_CHECKING:
    from isolab.studies.inputs.study import Study


def _labelled(values, labels) -> dict:
    return {name: float(v) for name, v in zip(labels, values, strict=True)}


def mode_label(energy: np.ndarray) -> str:
    """A mode named by its dominant motion and the degrees of freedom that carry it, from its kinetic-energy
    shares over x, y, z, rx, ry, rz (:func:`isolab.studies.answers.history.mode_name`): ``heave (z)``,
    ``pitch + sway (rx+y)``; ``?`` when the shares are not numbers."""
    from isolab.studies import DOF_NAMES
    from isolab.studies.answers.history import COUPLED_SHARE, mode_name

    name = mode_name(energy)
    if not name:
        return "?"
    e = np.asarray(energy, dtype=np.float64).reshape(-1)
    order = np.argsort(-e)
    dofs = [DOF_NAMES[order[0]]]
    if e[order[1]] >= COUPLED_SHARE * e.sum():
        dofs.append(DOF_NAMES[order[1]])
    return f"{name} ({'+'.join(dofs)})"


def heave_mode(mode_energy: np.ndarray) -> int:
    """Index (0-based) of the mode with the largest vertical (z) kinetic-energy share: the heave mode."""
    from isolab.studies import DOF_NAMES

    e = np.nan_to_num(np.asarray(mode_energy, dtype=np.float64), nan=-1.0)
    return int(np.argmax(e[:, DOF_NAMES.index("z")]))


UNITS_STATED = (
    "peak_displacement",
    "peak_rotation",
    "peak_point_displacement",
    "peak_isolator_force",
    "min_isolator_load",
    "max_isolator_load",
    "peak_isolator_deflection",
    "static_isolator_load",
    "rms_displacement",
    "settling_time",
    "point_settling_time",
    "peak_following_error",
    "move_time",
    "ready_time",
    "point_ready_time",
    "natural_frequency",
    "damping_ratio",
    "transmissibility",
    "dt",
)
"""The outputs whose SI unit (the output catalogue's, :data:`isolab.studies.OUTPUTS`) the JSON of
``simulate`` states under ``units``, in order."""


def case_outputs(
    result, case: int, isolators: list[str], points: list[str], stages: list[str] | None = None
) -> dict:
    """One case's outputs keyed by quantity and by axis, isolator, point, stage or mode (SI units)."""
    from isolab.studies import AXES, DOF_NAMES, OUTPUTS, ROTATIONS, STATUS_NAMES

    r = result
    ok = int(r.status[case]) == 0
    out = {
        "status": STATUS_NAMES[int(r.status[case])],
        "message": r.message[case],
        "dt": float(r.dt[case]),
        "move_time": float(r.move_time[case]),
        "natural_frequency": [float(f) for f in r.natural_frequency[case]],
        "damping_ratio": [float(z) for z in r.damping_ratio[case]],
        "mode_energy": [_labelled(e, DOF_NAMES) for e in r.mode_energy[case]],
        "mode_name": [mode_label(e) for e in r.mode_energy[case]],
        "heave_mode": heave_mode(r.mode_energy[case]) + 1,
        "mechanism": [bool(m) for m in r.mechanism[case]],
        "static_isolator_load": _labelled(r.static_isolator_load[case], isolators),
        "units": {name: OUTPUTS[name].unit for name in UNITS_STATED},
    }
    fpv = getattr(r, "floor_point_velocity", None)
    if fpv is not None and np.any(np.asarray(fpv[case]) > 0):
        from isolab.studies.questions.floor import vc_class

        band = r.floor_point_velocity_band[case]
        out["floor_point_velocity"] = {p: _labelled(v, AXES) for p, v in zip(points, fpv[case], strict=True)}
        out["floor_point_velocity_band"] = {p: _labelled(v, AXES) for p, v in zip(points, band, strict=True)}
        out["floor_vc_class"] = {
            p: vc_class(float(np.max(v))) for p, v in zip(points, fpv[case], strict=True)
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
        ready_time=float(r.ready_time[case]),
        point_ready_time=_labelled(r.point_ready_time[case], points),
        transmissibility=_labelled(r.transmissibility[case], AXES),
    )
    if getattr(r, "max_isolator_load", None) is not None:
        out["max_isolator_load"] = _labelled(r.max_isolator_load[case], isolators)
    if getattr(r, "peak_isolator_deflection", None) is not None:
        out["peak_isolator_deflection"] = {
            i: _labelled(v, AXES) for i, v in zip(isolators, r.peak_isolator_deflection[case], strict=True)
        }
    if getattr(r, "point_settling_time", None) is not None:
        out["point_settling_time"] = _labelled(r.point_settling_time[case], points)
    errors = getattr(r, "stage_following_error", None)
    if stages and errors is not None and np.any(np.asarray(errors[case]) > 0):  # stages on a servo
        out["peak_following_error"] = _labelled(errors[case], stages)
    return out


COMPILING = "compiling kernels, first run only"
"""What ``simulate`` and ``run`` print (stderr) before a run that compiles the engine's kernels."""


def say_if_compiling(
    integrators: list[str | None], fidelity: str | None = None, general: bool = True
) -> None:
    """Print :data:`COMPILING` to stderr when the kernels of ``integrators`` (None: still to be chosen) at
    ``fidelity`` (None: every level) are not cached on disk yet
    (:func:`isolab.studies.run.kernel_cache.kernels_cached`; without ``general``, the drivers of a run
    whose every case the output map observes), and then removes the kernel cache folders of other engine
    versions long unused (:func:`isolab.studies.run.kernel_cache.tidy_kernel_caches`)."""
    from isolab.studies.run.kernel_cache import kernels_cached, tidy_kernel_caches

    if not kernels_cached(integrators, fidelity=fidelity, general=general):
        typer.echo(COMPILING, err=True)
        tidy_kernel_caches()


def general_observer_sampled(study: Study) -> bool:
    """Whether a run of ``study``'s cases calls the general observer's driver at a linear level (a moving
    floor, mounts on their own axes: ``isolab.engine.general_observer_called``), judged on up to 16 of its
    cases spread over them: what may vary per case is the floor's amplitude, which a range spans."""
    from isolab.studies import general_observer_called

    n = int(study.n_cases)
    sample = np.unique(np.linspace(0, n - 1, min(n, 16)).round().astype(np.int64))
    return bool(general_observer_called(study.batch(sample)))


def fail(lines: list[str]) -> NoReturn:
    """Print each line as ``error: ...`` on stderr and exit with code 2 (bad input)."""
    for line in lines:
        typer.echo(f"error: {line}", err=True)
    raise typer.Exit(code=2)


def simulate(
    scene: Annotated[Path, typer.Argument(help="Scene file, YAML or JSON.")],
    as_json: Annotated[bool, typer.Option("--json", help="Print the outputs as JSON.")] = False,
    fidelity: Annotated[str | None, typer.Option(help="lti, ltv or nonlinear (default: scene's).")] = None,
    integrator: Annotated[str | None, typer.Option(help="euler, rk4, exact or reference.")] = None,
    dt: Annotated[float | None, typer.Option(help="Step, s (default: the scene's).")] = None,
    plot: Annotated[Path | None, typer.Option(help="Write c.g., rotation and force traces to a PNG.")] = None,
) -> None:
    """Simulate one scene and print its peaks, loads, natural frequencies and settling time."""
    from isolab.studies import SceneError
    from isolab.studies import simulate as run
    from isolab.studies.inputs.file_checks import FileProblem, check_scene_file, in_user_words
    from isolab.studies.inputs.study import scene_batch

    try:
        sc = check_scene_file(scene)
    except FileProblem as err:
        fail(err.lines)
    try:
        batch, names = scene_batch(sc)
        sim = sc.simulation
        fid = fidelity or sim.fidelity
        integ = integrator or sim.integrator
        step = dt or sim.dt
        reason = None
        if sim.request is not None and not (fidelity and integrator and dt):
            # the scene asks for an accuracy: measure the cheapest model that meets it on this scene
            from isolab.studies.inputs.study import Study
            from isolab.studies.run.accuracy import choose

            say_if_compiling([integrator])
            choice = choose(Study.model_validate({"name": scene.stem, "scene": sc.model_dump(mode="json")}))
            fid, integ = fidelity or choice.fidelity, integrator or choice.integrator
            step, reason = dt or choice.dt, choice.reason
        if fid is None or integ is None or step is None:  # resolved above; a scene always has defaults
            raise ValueError("simulation: no fidelity, integrator and step to run with")
        from isolab.studies import general_observer_called

        say_if_compiling([integ], fid, general_observer_called(batch, [0] if plot else None))
        t0 = time.perf_counter()
        result = run(batch, fid, integ, step, auto_step=sim.auto_step, record=[0] if plot else None)
        elapsed = time.perf_counter() - t0
    except (SceneError, ValueError) as exc:
        fail([in_user_words(str(exc), [s.name for s in sc.stages])])
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
        **case_outputs(result, 0, names["isolators"], names["points"], names["stages"]),
    }
    if sc.criteria is not None:
        from isolab.studies.questions.criteria import result_margins

        margin = result_margins(result, sc.criteria, names["points"], names["isolators"])
        out["criterion_margin"] = margin
        out["meets_criteria"] = bool(margin) and all(m >= 0 for m in margin.values())
    if plot:
        from isolab.service.plots.studies import case_png

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
        for line in floor_text(out):
            typer.echo(line)
        return
    for line in simulate_text(out) + floor_text(out):
        typer.echo(line)


def label_width(out: dict) -> int:
    """The width of the indented label column of :func:`simulate_text` and :func:`floor_text`: 24
    characters, or more where a point's or a criterion's name needs it (one space to spare)."""
    names = [f"peak displacement {p}" for p in out.get("peak_point_displacement", {})]
    names += list(out.get("criterion_margin", {})) + list(out.get("floor_point_velocity", {}))
    return max([24, *(len(n) + 1 for n in names)])


def floor_text(out: dict) -> list[str]:
    """The lines on the floor-induced velocity (worst one-third-octave band per point and axis, the VC
    criterion it meets) and the criteria margins, where ``out`` (:func:`case_outputs`) has them."""
    lines = []
    w = label_width(out)
    if "floor_point_velocity" in out:
        lines.append("  floor-induced velocity (worst one-third-octave band, RMS)")
        for point, values in out["floor_point_velocity"].items():
            band = out["floor_point_velocity_band"][point]
            axes = "  ".join(f"{a} {v * 1e6:.3g} um/s ({band[a]:.3g} Hz)" for a, v in values.items())
            vc = out["floor_vc_class"][point] or "none (above VC-A)"
            lines.append(f"    {point:<{w}}{axes}  meets {vc}")
    if "criterion_margin" in out:
        verdict = "all met" if out["meets_criteria"] else "NOT all met"
        lines.append(f"  criteria margins ({verdict}; fraction of the limit, positive: met)")
        for name, m in out["criterion_margin"].items():
            lines.append(f"    {name:<{w}}{m:+.3f}" + ("" if m >= 0 else "  NOT met"))
    return lines


def simulate_text(out: dict) -> list[str]:
    """The lines ``isolab simulate`` prints for an ok case (``out``: :func:`case_outputs` of it): modes
    named by their dominant motion and which is the heave mode, peaks of the c.g., each point and each
    isolator per axis (mm, mrad, kN), the isolator load range and deflections, and settling."""
    from isolab.studies import AXES, ROTATIONS

    def mm(v: float) -> str:
        return f"{v * 1e3:.3f} mm"

    def per_axis(values: dict, fmt) -> str:
        return "  ".join(f"{a} {fmt(values[a])}" for a in AXES)

    def worst(values: dict, pick) -> tuple[str, float]:
        name = pick(values, key=values.get)
        return name, values[name]

    lines = []
    w = label_width(out)
    pd, pr = out["peak_displacement"], out["peak_rotation"]
    lines.append(f"  {'peak c.g. displacement':<{w + 2}}" + per_axis(pd, mm))
    rotations = "  ".join(f"{a} {pr[a] * 1e3:.3f} mrad" for a in ROTATIONS)
    lines.append(f"  {'peak rotation':<{w + 2}}" + rotations)
    for point, values in out["peak_point_displacement"].items():
        lines.append(f"  {'peak displacement ' + point:<{w + 2}}" + per_axis(values, mm))
    lines.append("  modes")
    heave = out["heave_mode"]
    for k, (f, name) in enumerate(zip(out["natural_frequency"], out["mode_name"], strict=True), start=1):
        mark = "  <- heave mode" if k == heave else ""
        mech = " (mechanism)" if out["mechanism"][k - 1] else ""
        lines.append(f"    {k}  {f:7.2f} Hz  {name}{mech}{mark}")
    f_heave = out["natural_frequency"][heave - 1]
    lines.append(f"  {'heave mode':<{w + 2}}mode {heave} at {f_heave:.2f} Hz")
    lines.append("  peak isolator force (dynamic)")
    for iso, values in out["peak_isolator_force"].items():
        lines.append(f"    {iso:<{w}}" + per_axis(values, lambda v: f"{v / 1e3:.2f} kN"))
    low_name, low = worst(out["min_isolator_load"], min)
    loads = f"min {low / 1e3:.2f} kN ({low_name})"
    if "max_isolator_load" in out:
        high_name, high = worst(out["max_isolator_load"], max)
        loads += f", max {high / 1e3:.2f} kN ({high_name})"
    static = out["static_isolator_load"]
    loads += f"; static {min(static.values()) / 1e3:.2f} .. {max(static.values()) / 1e3:.2f} kN"
    lines.append(f"  {'isolator load (total)':<{w + 2}}{loads}")
    if any(out["liftoff"].values()):
        lines.append(f"  {'LIFTOFF':<{w + 2}}" + ", ".join(i for i, v in out["liftoff"].items() if v))
    if "peak_isolator_deflection" in out:
        lines.append("  peak isolator deflection")
        for iso, values in out["peak_isolator_deflection"].items():
            lines.append(f"    {iso:<{w}}" + per_axis(values, mm))
    st = "settled" if out["settled"] else "NOT settled (lower bound)"
    lines.append(f"  {'settling time':<{w + 2}}{out['settling_time']:.3f} s ({st})")
    if out.get("point_settling_time"):
        lines.append(
            f"  {'point settling time':<{w + 2}}"
            + ", ".join(f"{p} {t:.3f} s" for p, t in out["point_settling_time"].items())
        )
    if out.get("peak_following_error"):
        lines.append(
            f"  {'peak following error':<{w + 2}}"
            + ", ".join(f"{s} {e * 1e6:.1f} um" for s, e in out["peak_following_error"].items())
        )
    ready = ", ".join(f"{p} {t:.3f} s" for p, t in out["point_ready_time"].items())
    lines.append(
        f"  {'move end, then ready':<{w + 2}}{out['move_time']:.3f} s, ready {out['ready_time']:.3f} s"
        + (f" ({ready})" if ready else "")
    )
    return lines


def run_study_command(
    study: Annotated[Path, typer.Argument(help="Study file (YAML or JSON).")],
    out: Annotated[Path, typer.Option("-o", "--out", help="Write the dataset to this netCDF file.")],
    workers: Annotated[int, typer.Option(min=1, help="Local Dask worker processes.")] = 2,
) -> None:
    """Run a study on a local Dask cluster with a progress bar and write its dataset. The study is checked
    first as the service checks a submitted one, with the same case limit (ISOLAB_MAX_CASES)."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from isolab.service.settings import SettingsError, load_settings
    from isolab.studies.inputs.file_checks import FileProblem, check_study_file, in_user_words
    from isolab.studies.run.runner import run_local

    try:
        definition = check_study_file(study, load_settings().max_cases)
    except SettingsError as err:
        fail([str(err)])
    except FileProblem as err:
        fail(err.lines)
    sim = definition.simulation
    # the chosen model (or every one, when the study asks for an accuracy) and the reference that measures
    # each dataset's error
    chosen = sim.request is None
    say_if_compiling(
        [sim.integrator if chosen else None, "reference"],
        sim.fidelity if chosen else None,
        general=general_observer_sampled(definition),
    )
    t0 = time.perf_counter()
    try:
        with Progress(
            TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn()
        ) as bar:
            task = bar.add_task(study.name, total=None)

            def progress(done: int, total: int) -> None:
                bar.update(task, completed=done, total=total)

            ds = run_local(definition, out, workers=workers, progress=progress)
    except ValueError as exc:
        fail([in_user_words(str(exc), [s.name for s in definition.scene.stages] if definition.scene else [])])
    except OSError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(code=1) from None
    wall = time.perf_counter() - t0
    n = int(ds.attrs.get("n_cases", 0)) or int(np.prod([ds.sizes[d] for d in ds.status.dims]))
    robust = json.loads(str(ds.attrs.get("optimisation", "{}"))).get("robust")
    if robust:  # a robust optimisation's rows are candidates, each run as its nominal case and its draws
        simulated = n * (int(robust["samples"]) + 1)
        rate = f"{simulated / wall:.1f} cases/s"
        typer.echo(f"{simulated} cases simulated ({n} candidates) in {wall:.1f} s ({rate}) -> {out}")
    else:
        typer.echo(f"{n} cases in {wall:.1f} s ({n / wall:.1f} cases/s) -> {out}")
    from isolab.studies.questions.tolerances import described_reliability
    from isolab.studies.run.optimisation import describe_optimum

    for line in describe_optimum(ds) + described_reliability(ds):  # an optimum; a tolerance study's odds
        typer.echo(line)
