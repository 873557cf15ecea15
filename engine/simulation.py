"""Simulate a batch of cases: pick the level and integrator, guard stability, collect the outputs.

The integrators and the kernels (numba) load with the first call that needs them, not with this module.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from isolab.engine import frequency, modal, model, mount_laws, stability
from isolab.engine.linear_states.levelling import check_levelling
from isolab.engine.results import FAILED, OK, TIPPING, UNSTABLE, SimulationResult
from isolab.engine.scene import SceneBatch, SceneError
from isolab.engine.validation import validate

MAX_STEPS = 20_000_000
"""Largest number of steps one case may take (a guard against a step far too small for its duration)."""


def check_choice(fidelity: str, integrator: str) -> None:
    """Refuse an unknown level or integrator, or a pair that does not exist, naming the field."""
    from isolab.engine.integrators import INTEGRATORS
    from isolab.engine.kernels.params import FIDELITIES

    if fidelity not in FIDELITIES:
        raise SceneError("fidelity", f"must be one of {sorted(FIDELITIES)}, got {fidelity!r}")
    if integrator not in INTEGRATORS:
        raise SceneError("integrator", f"must be one of {sorted(INTEGRATORS)}, got {integrator!r}")
    levels = INTEGRATORS[integrator].levels
    if fidelity not in levels:
        raise SceneError(
            "integrator", f"{integrator!r} integrates only the {', '.join(levels)} level, not {fidelity!r}"
        )


SUB_STEPPED = "sub-stepped"
"""How the message of a case the stability guard sub-stepped begins (the case itself is ``ok``)."""


def substep_message(dt: float, step: float, n_div: int, integrator: str, fastest_hz: float) -> str:
    """What an ``ok`` case the stability guard cut into ``n_div`` sub-steps of ``step`` s (from ``dt`` s)
    says: that it was, and that its accuracy may be poor (a stable step near the limit is not accurate)."""
    return (
        f"{SUB_STEPPED}: {dt * 1e3:.3g} ms cut to {step * 1e3:.3g} ms ({n_div} sub-steps) by the stability "
        f"guard of the {integrator} integrator (fastest mode {fastest_hz:.4g} Hz at home); accuracy may be "
        "poor, choose a smaller dt or the exact integrator"
    )


SAMPLED_PEAKS = "peaks sampled"
"""How the part of an ``ok`` case's message begins that says its peaks were taken at the output steps only."""


def sampled_peak_message(step: np.ndarray, h_interp: np.ndarray) -> list[str]:
    """Per case, what its message says when its step ``step`` (C,), s, exceeds ``h_interp`` (C,), s (1/omega
    of the fastest mode): the peaks are then the output samples', not refined between steps, and may be
    low by up to ``1 - cos(omega h / 2)`` of a mode's amplitude. Empty where the peaks are refined."""
    out = []
    for h, lim in zip(np.asarray(step, dtype=float), np.asarray(h_interp, dtype=float), strict=True):
        if not h > lim:
            out.append("")
            continue
        loss = 1.0 - np.cos(min(h / lim, np.pi) / 2.0)
        out.append(
            f"{SAMPLED_PEAKS} at the output steps only: the step {h * 1e3:.3g} ms exceeds 1/omega of the "
            f"fastest mode ({1e3 * lim:.3g} ms, {1.0 / (2.0 * np.pi * lim):.4g} Hz), so peaks are not "
            f"refined between steps and may be low by up to {loss * 100:.2g} % of that mode's amplitude; "
            f"choose dt <= {1e3 * lim:.3g} ms for refined peaks"
        )
    return out


def _divergence_cause(integrator: str, step: float) -> str:
    """Why a case that passed the stability guard still ran away (the message after "diverged at t")."""
    from isolab.engine.kernels import peaks

    where = (
        f"the base moved more than {peaks.DIVERGED_DISPLACEMENT:g} m or turned more than "
        f"{peaks.DIVERGED_ROTATION:g} rad"
    )
    if integrator in ("exact", "reference"):
        return (
            f"{where} with the {integrator} integrator, so the scene itself runs away (mounts too soft "
            "for the load or the stage forces); stiffen or add mounts, or slow the stages"
        )
    return (
        f"{where} although the step ({step:.3g} s, {integrator}) is inside the stability limit with the "
        "stages at home and at the ends of their travel; the scene itself likely runs away (mounts too "
        "soft for the load or the stage forces): check it with the reference integrator"
    )


SLOT_LEVELS = ("lti", "ltv")
"""The levels that model the extra linear states (a flexible base, the mounts' relaxation branches)."""
SLOT_INTEGRATORS = ("rk4", "exact")
"""The integrators that step them."""


def check_slot(batch: SceneBatch, fidelity: str, integrator: str) -> None:
    """Refuse extra linear states (a flexible base ``base_mode_*``, mount relaxation branches
    ``iso_branch_*``) where they are not modelled, naming the input and the levels and integrators that
    model them."""
    used = [
        (what, field, apart)
        for what, field, apart, on in (
            ("a flexible base", "base_mode_frequency", ("iso_frame",), batch.n_base_modes > 0),
            (
                "mounts with internal states (an air mount's orifice, an elastomer's ladder)",
                "iso_branch_k",
                ("base_mode_frequency",),
                batch.has_mount_branches,
            ),
        )
        if on
    ]
    if np.size(np.asarray(batch.iso_branch_k)):
        mount_laws.check_branches(batch)
    for what, field, apart in used:
        if fidelity not in SLOT_LEVELS:
            raise SceneError(
                field,
                f"{what} is modelled at the {' and '.join(SLOT_LEVELS)} levels, not {fidelity!r}; "
                "choose one of them or leave it out",
            )
        if integrator not in SLOT_INTEGRATORS:
            raise SceneError(
                field, f"{what} is integrated by {' or '.join(SLOT_INTEGRATORS)}, not {integrator!r}"
            )
        for name, on in (
            ("floor", batch.has_floor_motion or batch.has_floor_spectrum),
            ("iso_ff_gain", batch.has_feedforward),
            ("iso_frame", batch.has_orientation and "iso_frame" in apart),
            ("base_mode_frequency", batch.n_base_modes > 0 and "base_mode_frequency" in apart),
        ):
            if on:
                raise SceneError(field, f"{what} is not modelled together with {name} (not yet)")


SERVO_LEVELS = ("lti",)
"""The levels that model a stage on a servo (its mass along the axis leaves the base's mass matrix, which
only the LTI level keeps constant)."""


def check_servo(batch: SceneBatch, fidelity: str, integrator: str) -> None:
    """Refuse a stage on a servo (``stage_servo_frequency``) where it is not modelled, naming the input and
    the levels and integrators that model it."""
    if not len(batch.servo_stages):
        return
    field = "stage_servo_frequency"
    if fidelity not in SERVO_LEVELS:
        raise SceneError(
            field,
            f"a stage on a servo is modelled at the {' and '.join(SERVO_LEVELS)} level, not {fidelity!r} "
            "(its mass along the axis leaves the base's mass matrix, which the time-varying levels "
            "rebuild as the stages travel); choose lti, or stages that follow their profiles exactly",
        )
    if integrator not in SLOT_INTEGRATORS:
        raise SceneError(
            field, f"a stage on a servo is integrated by {' or '.join(SLOT_INTEGRATORS)}, not {integrator!r}"
        )
    for name, used in (
        ("a flexible base", batch.n_base_modes > 0),
        ("iso_ff_gain", batch.has_feedforward),
    ):
        if used:
            raise SceneError(field, f"a stage on a servo is not modelled together with {name} (not yet)")


def with_following_errors(batch: SceneBatch) -> SceneBatch:
    """``batch`` with one more point of interest per stage on a servo: its following error, read along X
    (``SceneBatch.point_relative`` 2), so that its peak and settling come with the points'. ``batch``
    itself when no stage is on a servo."""
    servo = batch.servo_stages
    s = len(servo)
    if s == 0:
        return batch
    C = batch.n_cases

    def more(a: np.ndarray | None, extra: np.ndarray) -> np.ndarray:
        return np.concatenate([np.asarray(a), extra.astype(np.asarray(a).dtype)], axis=1)

    k = batch.n_base_modes
    return replace(
        batch,
        points=more(batch.points, np.zeros((C, s, 3))),
        point_settle_tol=more(batch.point_settle_tol, np.repeat(np.asarray(batch.settle_tol)[:, None], s, 1)),
        base_mode_point=more(batch.base_mode_point, np.zeros((C, s, 3, k))),
        point_relative=more(batch.point_relative, np.full((C, s), 2)),
        point_tool_stage=more(batch.point_tool_stage, np.broadcast_to(servo, (C, s)).copy()),
        point_work_stage=more(batch.point_work_stage, np.full((C, s), -1)),
    )


def general_observer_called(batch: SceneBatch, record: list[int] | None = None) -> bool:
    """Whether a stepped method's run of ``batch`` at a linear level calls its general observer's driver
    (``engine.integrators.stepping.GENERAL``): a recorded case (``record``), or a case the linear output
    map does not observe (a moving floor, mounts on their own axes, extra states that push through the
    mounts: ``engine.integrators.output_map.still_floor``). Otherwise the run calls, and on an empty kernel
    cache compiles, the output map's driver alone."""
    from isolab.engine.integrators import output_map

    still = output_map.still_floor(model.params(with_following_errors(batch)))
    return bool(record) or not bool(np.all(still))


def simulate(
    batch: SceneBatch,
    fidelity: str = "ltv",
    integrator: str = "rk4",
    dt: float = 1e-3,
    auto_step: bool = True,
    record: list[int] | None = None,
) -> SimulationResult:
    """Simulate every case of ``batch``.

    Args:
        batch: the cases (see ``engine.scene``).
        fidelity: "lti", "ltv" or "nonlinear" (see docs/physics.md).
        integrator: "euler" (semi-implicit), "rk4", "exact" (LTI only) or "reference" (adaptive).
        dt: output step, s; also the integration step of the fixed-step methods.
        auto_step: when ``dt`` is past the integrator's stability limit for a case, divide it into as
            many sub-steps as needed; when False such a case comes back ``unstable``.
        record: indices of cases whose time histories to keep (``result.history``).

    Returns:
        A ``SimulationResult``; cases that went or would go numerically unstable, tip over or fail
        carry that status and a message, and NaN instead of their peaks, loads, deflections, RMS, final
        displacement, settling times and transmissibility (the static preloads and the modes stay filled: see
        ``SimulationResult``).
    """
    from isolab.engine.integrators import INTEGRATORS
    from isolab.engine.kernels import peaks
    from isolab.engine.kernels.params import FIDELITIES

    check_choice(fidelity, integrator)
    if not (np.isfinite(dt) and dt > 0):
        raise SceneError("dt", f"must be a positive, finite step in s, got {dt!r}")
    validate(batch)
    check_slot(batch, fidelity, integrator)
    check_servo(batch, fidelity, integrator)
    check_levelling(batch, fidelity, integrator)
    given = batch
    p_given = batch.n_points
    batch = with_following_errors(batch)
    C = batch.n_cases
    if record:
        bad = [r for r in record if not 0 <= r < C]
        if bad:
            raise SceneError("record", f"case indices {bad} outside 0..{C - 1}")
    level = FIDELITIES[fidelity]
    P = model.params(batch)
    M0 = model.mass_matrix(batch)
    K0 = model.stiffness_matrix(batch)
    C0 = model.damping_matrix(batch)
    md = modal.modes(M0, K0, C0)
    status = np.zeros(C, dtype=np.int8)
    message = [""] * C
    for c in np.flatnonzero(md.tipping).tolist():
        status[c] = TIPPING
        message[c] = (
            "statically unstable: the rocking stiffness of the weights above the mounts "
            "exceeds the mounts' own; widen the layout, lower the c.g. or stiffen the mounts"
        )

    # the time-varying levels change mass and gravity stiffness as the stages travel: the guards look at
    # the stages at the ends of their travel too
    placed = [
        (model.mass_matrix(batch, rho), model.stiffness_matrix(batch, rho))
        for rho in (model.travel_positions(batch) if fidelity != "lti" else [])
    ]
    for M, K in placed:
        for c in np.flatnonzero(modal.modes(M, K, C0).tipping & (status == OK)).tolist():
            status[c] = TIPPING
            message[c] = (
                "statically unstable with the stages at the ends of their travel: the rocking "
                "stiffness of the weights above the mounts exceeds the mounts' own; widen the "
                "layout, lower the c.g., shorten the travel or stiffen the mounts"
            )

    # stability guard (fixed-step integrators)
    steps = np.full(C, float(dt))
    n_div = np.ones(C, dtype=np.int64)
    method = INTEGRATORS[integrator]
    nz = P.zA.shape[1]
    A0 = model.slot_state_matrix(P) if nz else modal.state_matrix(M0, K0, C0)
    if method.guarded:
        n_div = stability.subdivisions(A0, dt, method.step_matrix)
        for M, K in placed:
            more = stability.subdivisions(modal.state_matrix(M, K, C0), dt, method.step_matrix)
            n_div = np.where((n_div == 0) | (more == 0), 0, np.maximum(n_div, more))
        fastest = md.frequency.max(axis=1)
        for c in range(C):
            if status[c] != OK or n_div[c] == 1:
                continue
            if n_div[c] == 0 or not auto_step:
                status[c] = UNSTABLE
                need = "more than 4096 sub-steps" if n_div[c] == 0 else f"{n_div[c]} sub-steps"
                message[c] = (
                    f"dt = {dt:.4g} s is past the {integrator} stability limit of the fastest mode "
                    f"({fastest[c]:.4g} Hz at home, needs {need}); "
                    + ("use a smaller dt or the exact integrator" if n_div[c] else "use the exact integrator")
                )
                n_div[c] = 1
        n_div[status != OK] = 1
        steps = dt / n_div
        for c in np.flatnonzero(n_div > 1).tolist():
            message[c] = substep_message(dt, steps[c], int(n_div[c]), integrator, fastest[c])
    duration = np.asarray(batch.duration, dtype=float)
    n_steps = np.rint(duration / steps).astype(np.int64)
    n_steps = np.maximum(n_steps, 1)
    too_many = n_steps > MAX_STEPS
    for c in np.flatnonzero(too_many & (status == OK)).tolist():
        status[c] = FAILED
        message[c] = f"{n_steps[c]} steps of {steps[c]:.3g} s exceed the limit of {MAX_STEPS} per case"
    n_steps[too_many] = 1

    target = model.static_offset(batch, fidelity)
    rest, rest_n, rest_target = model.rest_offsets(batch, fidelity)
    slot_run: dict[str, np.ndarray] = {}
    point_offset = rest_point_offset = None
    fastest_hz = np.asarray(md.frequency).max(axis=1)
    if nz:
        target, z_end = model.slot_static(batch, fidelity, target)
        z_rest = np.zeros(rest_target.shape[:2] + (nz,))
        for k in range(rest_target.shape[1]):
            has = rest_n > k
            when = np.where(
                has, np.where(np.isfinite(rest[:, k, 1]), 0.5 * (rest[:, k, 0] + rest[:, k, 1]), 0.0), 0.0
            )
            rho = model.placed_positions(batch, model.positions_at(batch, when))
            q, z = model.slot_static(batch, fidelity, rest_target[:, k], rho)
            rest_target[has, k] = q[has]
            z_rest[has, k] = z[has]
        slot_run = {"slot_target": z_end, "slot_rest_target": z_rest}
        p3 = 3 * batch.n_points
        point_offset = np.einsum("czr,cz->cr", P.zO[:, 0, :, :p3], z_end).reshape(C, -1, 3)
        rest_point_offset = np.einsum("czr,ckz->ckr", P.zO[:, 0, :, :p3], z_rest).reshape(
            C, rest_target.shape[1], -1, 3
        )
        fastest_hz = np.maximum(fastest_hz, np.abs(np.linalg.eigvals(A0)).max(axis=1) / (2.0 * np.pi))
    O = peaks.allocate(
        C,
        batch.n_points,
        batch.n_isolators,
        target,
        batch.last_move_end(),
        np.asarray(batch.settle_tol),
        record,
        int(n_steps[list(record)].max()) if record else 0,
        rest=rest,
        rest_n=rest_n,
        rest_target=rest_target,
        point_tol=batch.point_settle_tol,
        # a peak between output times is interpolated over intervals of at most 1/omega of the fastest mode
        h_interp=1.0 / (2.0 * np.pi * np.maximum(fastest_hz, 1e-300)),
        # the nonlinear level's rest of a point is u + (R - I) p, not the linearised u + theta x p (with
        # extra linear states, what they add at rest)
        point_offset=model.point_rest_offsets(batch, target) if fidelity == "nonlinear" else point_offset,
        rest_point_offset=(
            np.moveaxis(model.point_rest_offsets(batch, np.moveaxis(rest_target, 1, 0)), 0, 1)
            if fidelity == "nonlinear"
            else rest_point_offset
        ),
    )
    sampled = sampled_peak_message(steps, np.asarray(O.h_interp))
    for c in np.flatnonzero(status == OK).tolist():
        if sampled[c]:
            message[c] = f"{message[c]}; {sampled[c]}" if message[c] else sampled[c]
    W = model.work(batch)
    run_status = status.copy()
    method.run(P, level, steps, n_steps, O, W, run_status, messages=message, **slot_run)
    for c in range(C):
        if status[c] != OK:
            continue
        if run_status[c] == UNSTABLE:
            status[c] = UNSTABLE
            message[c] = f"diverged at t = {O.diverged[c]:.4g} s: " + _divergence_cause(integrator, steps[c])
        elif run_status[c] == FAILED:
            status[c] = FAILED
            failed_why = message[c] if not message[c].startswith((SUB_STEPPED, SAMPLED_PEAKS)) else ""
            message[c] = failed_why or (
                "the mass matrix lost positive definiteness (the base turned "
                "beyond the range the model holds)"
            )

    t_end = n_steps * steps
    t_last = batch.last_move_end()
    settled = O.last_viol < t_end - 0.5 * steps
    settling = np.where(np.isfinite(O.last_viol), np.maximum(O.last_viol - t_last, 0.0), 0.0)
    settling = np.where(settled, settling, np.maximum(t_end - t_last, 0.0))
    point_settling = peaks.finish_settling(O, t_end)

    if batch.has_floor_motion and np.any(batch.floor_amp != 0):
        d, _, _ = model.relative_geometry(batch)
        c_rel = batch.iso_c * (1.0 - batch.iso_skyhook[..., None])
        T = modal.transmissibility(
            M0, K0, C0, d, batch.iso_k, c_rel, np.where(batch.floor_amp != 0, batch.floor_freq, 0.0)
        )
    else:
        T = np.zeros((C, 3))

    # steady-state response to the floor spectrum: no stepping, so every case but a tipping one has it
    fpv = np.zeros((C, p_given, 3))
    fpb = np.zeros((C, p_given, 3))
    if batch.has_floor_spectrum:
        bands = frequency.batch_point_band_velocity(given, matrices=(M0, K0, C0), modes=md)
        bands[status == TIPPING] = np.nan
        fpv, fpb = frequency.worst_band(bands)
        relative = np.asarray(given.point_relative) != 0  # the floor moves tool and work together
        fpv[relative] = 0.0
        fpb[relative] = 0.0

    bad = status != OK
    nan = np.nan

    def per_case(a: np.ndarray) -> np.ndarray:
        a = np.array(a, dtype=float)
        a[bad] = nan
        return a

    rms = np.sqrt(O.sumsq / np.maximum(O.nobs, 1)[:, None])
    history = None
    if record:
        history = {
            "time": O.h_t,
            "displacement": O.h_u,
            "rotation": O.h_th,
            "point_displacement": O.h_poi[:, :, :p_given],
            "isolator_force": O.h_force,
            "n_samples": n_steps[list(record)] + 1,
        }
    errors = np.zeros((C, batch.n_stages))
    errors[:, batch.servo_stages] = O.poi[:, p_given:, 0]
    return SimulationResult(
        status=status,
        message=message,
        dt=np.asarray(steps, dtype=float),
        peak_displacement=per_case(O.u),
        peak_rotation=per_case(O.th),
        peak_point_displacement=per_case(O.poi[:, :p_given]),
        peak_isolator_force=per_case(O.force),
        static_isolator_load=np.array(P.f0),
        min_isolator_load=per_case(O.min_load),
        rms_displacement=per_case(rms),
        final_displacement=per_case(target),
        settling_time=per_case(settling),
        settled=np.where(bad, False, settled),
        point_settling_time=per_case(point_settling[:, :p_given]),
        peak_isolator_deflection=per_case(O.defl),
        max_isolator_load=per_case(O.max_load),
        natural_frequency=np.array(md.frequency),
        damping_ratio=np.array(md.damping_ratio),
        mode_energy=np.array(md.energy),
        mechanism=np.array(md.mechanism),
        transmissibility=per_case(T),
        floor_point_velocity=fpv,
        floor_point_velocity_band=fpb,
        peak_following_error=per_case(errors.max(axis=1) if batch.n_stages else np.zeros(C)),
        stage_following_error=per_case(errors),
        move_time=np.asarray(t_last, dtype=float),
        ready_time=per_case(t_last + settling),
        point_ready_time=per_case(t_last[:, None] + point_settling[:, :p_given]),
        history=history,
    )
