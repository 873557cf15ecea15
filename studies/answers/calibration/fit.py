"""The least-squares fit of a calibration and its answer.

:func:`calibrate` checks a request and fits the parameters (and the time offset) with
:func:`scipy.optimize.least_squares` (trust region reflective, bounded):

- **one engine batch per Jacobian**: the base case and one case per parameter, perturbed by a forward
  difference, go to the engine in one :func:`~isolab.engine.simulate` call;
- **time offset**: one more fitted parameter; its start is the best of a scan over its bounds with the
  starting scene, and its Jacobian column is the (central-difference) time derivative of the simulated
  traces;
- **weights**: residuals are divided by each channel's noise, estimated from the residuals of a first fit
  (weighted by the channels' RMS), then the fit is repeated. A filtered sample counts as the filter's
  noise gain of an independent one. The residual variance ``s^2`` of the final fit gives the covariance
  ``s^2 (J^T J)^-1`` and the 1-sigma uncertainty of every fitted value;
- **identifiability**: a parameter whose Jacobian column is (near) zero, that is (near) collinear with
  others, or whose 1-sigma uncertainty exceeds a quarter of its bounds' width or half its value is
  reported as not determined by this measurement, with the reason; it keeps the scene's value and the
  others are fitted again without it.

The answer is a :class:`Calibration` (SI units), one :class:`ParameterFit` per fitted quantity.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import yaml
from pydantic import ValidationError
from scipy.optimize import least_squares

from isolab.studies.answers.calibration.measurements import LOCATION_CG, Measurement
from isolab.studies.answers.calibration.model import ChannelModel, simulation_choice
from isolab.studies.answers.calibration.parameters import (
    BoundedParameter,
    FitSpec,
    fit_parameters,
    to_si_loc,
)
from isolab.studies.inputs.definitions import (
    DefinitionError,
    Loc,
    detail,
    screen_definition,
    validation_details,
)
from isolab.studies.inputs.parameters import apply, scene_dict
from isolab.studies.inputs.schema import Scene
from isolab.studies.inputs.study import validate_scene

DEFAULT_HIGHPASS_HZ = 0.5
"""Corner of the high-pass filter applied to acceleration channels (measured and simulated), Hz."""
DEFAULT_OFFSET_FRACTION = 0.25
"""Default bounds of the time offset: +- this fraction of the measurement's span."""
FD_STEP = 1e-4
"""Forward-difference step of a parameter's Jacobian column, as a fraction of its bounds' width."""
UNDETERMINED_WIDTH_FRACTION = 0.25
"""A parameter whose 1-sigma uncertainty exceeds this fraction of its bounds' width is not determined."""
UNDETERMINED_RELATIVE = 0.5
"""... or exceeds this fraction of its fitted value's magnitude."""
ZERO_COLUMN = 1e-9
"""A Jacobian column shorter than this fraction of the longest is zero: the channels do not respond."""
COLLINEAR = 1e-8
"""Singular values of the column-normalised Jacobian below this fraction of the largest: collinear."""
MAX_SIMULATED_SAMPLES = 60_000
"""Longest simulated history of one case (samples of the engine's output step): 60 s at 1 ms."""
SCAN_POINTS = 801
"""Offsets tried by the scan that starts the time offset."""


@dataclass
class ParameterFit:
    """One fitted quantity. ``value``/``sigma`` are None when the measurement does not determine it."""

    path: str
    name: str
    unit: str
    lower: float
    upper: float
    start: float
    value: float | None
    sigma: float | None
    determined: bool
    reason: str = ""
    estimate: float = math.nan  # the fitted number even when not determined (kept out of the scene)

    def to_json(self) -> dict[str, Any]:
        return {
            "path": self.path,
            "name": self.name,
            "unit": self.unit,
            "lower": self.lower,
            "upper": self.upper,
            "start": self.start,
            "value": self.value,
            "sigma": self.sigma,
            "determined": self.determined,
            "reason": self.reason or None,
        }


@dataclass
class Calibration:
    """The answer of :func:`calibrate` (SI units). ``traces`` holds what a plot needs: the measurement's
    times and, per channel, measured, simulated before and simulated after (filtered like the fit saw
    them)."""

    parameters: list[ParameterFit]
    time_offset: ParameterFit
    channels: list[dict[str, Any]]
    identifiability: dict[str, Any]
    residual_variance: float
    degrees_of_freedom: float
    scene: dict[str, Any]
    scene_yaml: str
    simulation: dict[str, Any]
    highpass: float
    lowpass: float
    evaluations: dict[str, Any]
    message: str
    traces: dict[str, Any] = field(repr=False)

    def to_json(self) -> dict[str, Any]:
        return {
            "parameters": [p.to_json() for p in self.parameters],
            "time_offset": self.time_offset.to_json(),
            "channels": self.channels,
            "identifiability": self.identifiability,
            "residual_variance": self.residual_variance,
            "degrees_of_freedom": self.degrees_of_freedom,
            "scene": self.scene,
            "scene_yaml": self.scene_yaml,
            "simulation": self.simulation,
            "highpass": self.highpass,
            "lowpass": self.lowpass,
            "evaluations": self.evaluations,
            "message": self.message,
        }


def _finite_jac(J: np.ndarray | None) -> np.ndarray:
    """A Jacobian least_squares can use: a column whose perturbed case failed counts as no response."""
    assert J is not None
    return np.nan_to_num(J, nan=0.0, posinf=0.0, neginf=0.0)


def _verdict(
    J: np.ndarray,
    s2: float,
    x: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    free: list[int],
    names: list[str],
) -> tuple[np.ndarray, list[str], dict[str, Any]]:
    """1-sigma uncertainties (NaN where not determined), reasons ("" where determined) and the
    identifiability figures of the weighted Jacobian ``J`` (columns in the units of ``x``)."""
    P = J.shape[1]
    sigma = np.full(P, np.nan)
    reasons = [""] * P
    norms = np.linalg.norm(J, axis=0)
    zero = norms <= ZERO_COLUMN * max(float(norms.max()), 1e-300)
    for z in np.flatnonzero(zero):
        reasons[int(z)] = "not determined by this measurement: the measured channels do not respond to it"
    live = np.flatnonzero(~zero)
    corr = np.full((P, P), np.nan)
    sv: list[float] = []
    if live.size:
        Jn = J[:, live] / norms[live]
        _, s, vt = np.linalg.svd(Jn, full_matrices=False)
        sv = (s / s[0]).tolist()
        small = s < COLLINEAR * s[0]
        keep = ~small
        inv = (vt[keep].T / s[keep] ** 2) @ vt[keep]  # pseudo-inverse of Jn^T Jn
        cov_n = s2 * inv
        d = np.sqrt(np.clip(np.diag(cov_n), 0.0, None))
        sigma[live] = d / norms[live]
        with np.errstate(invalid="ignore", divide="ignore"):
            corr[np.ix_(live, live)] = cov_n / np.outer(d, d)
        for row in np.flatnonzero(small):
            group = [int(live[q]) for q in np.flatnonzero(np.abs(vt[row]) > 0.1)]
            for g in group:
                others = ", ".join(names[j] for j in group if j != g)
                reasons[g] = (
                    "not determined by this measurement: collinear with "
                    + (others or "the others")
                    + " (only a combination of them is seen)"
                )
    width = upper - lower
    for i in range(P):
        if reasons[i]:
            sigma[i] = np.nan
            continue
        big = sigma[i] > UNDETERMINED_WIDTH_FRACTION * width[i]
        if names[i] != "time_offset":  # an offset near zero is a value like any other
            big = big or sigma[i] > UNDETERMINED_RELATIVE * abs(x[i])
        if big:
            partner = ""
            row = np.abs(np.nan_to_num(corr[i]))
            row[i] = 0.0
            if row.max() > 0.9:
                j = int(row.argmax())
                partner = f"; correlated with {names[j]} at {corr[i, j]:+.4f}"
            reasons[i] = (
                f"not determined by this measurement: 1-sigma uncertainty {sigma[i]:.3g} is more than "
                f"{UNDETERMINED_WIDTH_FRACTION:g} of the bounds' width or "
                f"{UNDETERMINED_RELATIVE:g} of the value" + partner
            )
            sigma[i] = np.nan
    info = {
        "names": names,
        "fitted": list(names),
        "singular_values": sv,
        "condition_number": (1.0 / sv[-1]) if sv and sv[-1] > 0 else None,
        "correlation": [[None if not np.isfinite(v) else float(v) for v in row] for row in corr],
    }
    return sigma, reasons, info


@dataclass
class PreparedFit:
    """A checked calibration, ready to fit: its channel model (:attr:`model`, whose ``duration``,
    ``choice`` and ``params`` size its cost), the fitted parameters and the time offset's bounds."""

    model: ChannelModel
    params: list[BoundedParameter]
    offset: tuple[float, float, Any]
    offset_fixed: bool
    prefix: Loc

    def run(self) -> Calibration:
        """The least-squares fit (see :func:`calibrate`)."""
        return _fit(self.model, self.params, self.offset, self.offset_fixed, self.prefix)


def calibrate(
    scene: Mapping[str, Any] | Scene,
    measurement: Measurement,
    fit: Sequence[FitSpec | Mapping[str, Any]],
    offset: Mapping[str, Any] | None = None,
    simulation: Mapping[str, Any] | None = None,
    highpass: Any = None,
    lowpass: Any = None,
    prefix: Loc | None = None,
) -> Calibration:
    """Fit ``fit``'s parameters of ``scene`` (and the time offset) to ``measurement``: see
    :func:`prepare_calibration` for the arguments; raises :class:`DefinitionError` on bad input."""
    return prepare_calibration(scene, measurement, fit, offset, simulation, highpass, lowpass, prefix).run()


def prepare_calibration(
    scene: Mapping[str, Any] | Scene,
    measurement: Measurement,
    fit: Sequence[FitSpec | Mapping[str, Any]],
    offset: Mapping[str, Any] | None = None,
    simulation: Mapping[str, Any] | None = None,
    highpass: Any = None,
    lowpass: Any = None,
    prefix: Loc | None = None,
) -> PreparedFit:
    """Check a calibration of ``fit``'s parameters of ``scene`` (and the time offset) against
    ``measurement``, without running the engine; :meth:`PreparedFit.run` fits it.

    Args:
        scene: a scene definition (data, validated here) or a validated Scene.
        measurement: see :func:`read_measurement` and friends.
        fit: parameter paths with bounds (:class:`FitSpec` or ``{"path", "lower", "upper", "start"?}``).
        offset: ``{"lower", "upper", "start"?}`` of the time offset in s (default +- a quarter of the
            measurement's span), or ``{"value": ...}`` to hold it fixed.
        simulation: ``fidelity``, ``integrator``, ``dt``, ``auto_step`` overriding the scene's (default the
            scene's; ltv with rk4 at 1 ms where the scene has an accuracy request instead).
        highpass: corner of the acceleration channels' high-pass filter, Hz (default 0.5 Hz; 0: none).
        lowpass: corner of their low-pass filter, Hz (default a fifth of the measurement's sample rate, at
            most a tenth of the simulation's, ``0.1 / dt``; 0: none).
        prefix: where the request's fields live, for error locations (default ``["body"]``).

    Raises:
        DefinitionError: bad input, each detail naming the field.
    """
    pre: Loc = ["body"] if prefix is None else list(prefix)
    if isinstance(scene, Scene):
        sc = scene
    else:
        problems = screen_definition(dict(scene), [*pre, "scene"])
        if problems:
            raise DefinitionError(problems)
        try:
            sc = validate_scene(dict(scene))
        except ValidationError as err:
            raise DefinitionError(validation_details(err, [*pre, "scene"])) from None
    for i, ch in enumerate(measurement.channels):
        if ch.location != LOCATION_CG and ch.location not in sc.points:
            known = ", ".join(["cg", *sc.points])
            raise DefinitionError(
                [
                    detail(
                        [*pre, "measurement", "channels", i],
                        f"channel {ch.name!r}: {ch.location!r} is not a point of the scene ({known})",
                    )
                ]
            )
    params = fit_parameters(sc, fit, pre)
    choice = simulation_choice(sc, simulation, pre)
    hp = DEFAULT_HIGHPASS_HZ if highpass is None else to_si_loc(highpass, "frequency", [*pre, "highpass"])
    if hp < 0:
        raise DefinitionError([detail([*pre, "highpass"], "must be 0 (off) or a positive frequency")])
    lp = None if lowpass is None else to_si_loc(lowpass, "frequency", [*pre, "lowpass"])
    if lp is not None and lp < 0:
        raise DefinitionError([detail([*pre, "lowpass"], "must be 0 (off) or a positive frequency")])
    t = measurement.time
    span = float(t[-1] - t[0])
    off = dict(offset or {})
    fixed_offset = off.get("value")
    if fixed_offset is not None:
        v = to_si_loc(fixed_offset, "time", [*pre, "offset", "value"])
        o_lo, o_hi = v - 1e-12, v + 1e-12
    else:
        o_lo = to_si_loc(off.get("lower", -DEFAULT_OFFSET_FRACTION * span), "time", [*pre, "offset", "lower"])
        o_hi = to_si_loc(off.get("upper", DEFAULT_OFFSET_FRACTION * span), "time", [*pre, "offset", "upper"])
        if not o_hi > o_lo:
            raise DefinitionError([detail([*pre, "offset", "upper"], "must be above offset.lower")])
    duration = float(t[-1] - o_lo)
    if duration <= 0:
        raise DefinitionError(
            [
                detail(
                    [*pre, "offset", "value" if fixed_offset is not None else "lower"],
                    "leaves no measured sample after the motion starts",
                )
            ]
        )
    if duration / choice.dt > MAX_SIMULATED_SAMPLES:
        raise DefinitionError(
            [
                detail(
                    [*pre, "measurement", "time"],
                    f"the fit would simulate {duration:.4g} s at {choice.dt:g} s: more than "
                    f"{MAX_SIMULATED_SAMPLES} steps; shorten the measurement or take a longer step",
                )
            ]
        )
    model = ChannelModel(sc, params, measurement, choice, (o_lo, o_hi), hp, lp, pre)
    return PreparedFit(model, params, (o_lo, o_hi, off.get("start")), fixed_offset is not None, pre)


def _fit(
    model: ChannelModel,
    params: list[BoundedParameter],
    offset: tuple[float, float, Any],
    offset_fixed: bool,
    pre: Loc,
) -> Calibration:
    P = len(params)
    names = [p.target.path for p in params] + ["time_offset"]
    lower = np.array([p.lower for p in params] + [offset[0]])
    upper = np.array([p.upper for p in params] + [offset[1]])
    scale = upper - lower
    start = np.array([p.start for p in params] + [0.0])
    y = model.measured

    # ---- the starting scene: one case, and the offset scan
    base = model.histories(start[None, :P])[0]
    if base is None:
        raise DefinitionError(
            [detail([*pre, "scene"], "the scene as given does not simulate (unstable, tipping or invalid)")]
        )
    if offset[2] is not None:
        tau0 = to_si_loc(offset[2], "time", [*pre, "offset", "start"])
    else:
        taus = np.linspace(offset[0], offset[1], SCAN_POINTS) if not offset_fixed else np.array([offset[0]])
        rms0 = np.sqrt(np.mean(y**2, axis=0)) + 1e-300
        cost = [float(np.sum(((model.predict(base, tau) - y) / rms0) ** 2)) for tau in taus]
        tau0 = float(taus[int(np.argmin(cost))])
    start[P] = min(max(tau0, lower[P]), upper[P])
    before = model.predict(base, start[P])

    free = list(range(P)) + ([] if offset_fixed else [P])
    cache: dict[bytes, tuple[np.ndarray, np.ndarray | None]] = {}

    def full(xf: np.ndarray) -> np.ndarray:
        x = start.copy()
        x[free] = xf * scale[free]
        return x

    def evaluate(xf: np.ndarray, weights: np.ndarray, with_jac: bool) -> tuple[np.ndarray, np.ndarray | None]:
        key = xf.tobytes() + weights.tobytes()
        hit = cache.get(key)
        if hit is not None and (hit[1] is not None or not with_jac):
            return hit
        x = full(xf)
        fp = [i for i in free if i < P]
        rows = [x[:P]]
        steps = []
        if with_jac:
            for i in fp:
                h = FD_STEP * scale[i]
                h = h if x[i] + h <= upper[i] else -h
                xi = x[:P].copy()
                xi[i] += h
                rows.append(xi)
                steps.append(h)
        splines = model.histories(np.array(rows))
        if splines[0] is None:
            r = np.full(y.size, np.nan)
            out = (r, np.full((y.size, len(free)), np.nan) if with_jac else None)
            cache[key] = out
            return out
        p0 = model.predict(splines[0], x[P])
        r = ((p0 - y) * weights).ravel()
        J = None
        if with_jac:
            J = np.zeros((y.size, len(free)))
            for k, (i, h) in enumerate(zip(fp, steps, strict=True)):
                sp = splines[k + 1]
                if sp is None:
                    J[:, free.index(i)] = np.nan
                    continue
                J[:, free.index(i)] = ((model.predict(sp, x[P]) - p0) * weights).ravel() / h * scale[i]
            if P in free:
                h = 0.5 * model.choice.dt
                d = (model.predict(splines[0], x[P] + h) - model.predict(splines[0], x[P] - h)) / (2 * h)
                J[:, free.index(P)] = (d * weights).ravel() * scale[P]
        cache[key] = (r, J)
        return r, J

    def run(weights: np.ndarray, x0: np.ndarray) -> Any:
        lo = lower[free] / scale[free]
        hi = upper[free] / scale[free]
        try:
            return _solve(weights, x0, lo, hi)
        except (ValueError, np.linalg.LinAlgError) as err:
            raise DefinitionError(
                [detail([*pre, "measurement"], f"the fit cannot go on from this measurement: {err}")]
            ) from None

    def _solve(weights: np.ndarray, x0: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> Any:
        return least_squares(
            lambda z: evaluate(z, weights, False)[0],
            np.clip(x0[free] / scale[free], lo, hi),
            jac=lambda z: _finite_jac(evaluate(z, weights, True)[1]),
            bounds=(lo, hi),
            method="trf",
            x_scale=1.0,
            xtol=1e-8,
            ftol=1e-8,
            gtol=1e-8,
            max_nfev=60,
        )

    # pass 1: weights from each channel's RMS; pass 2: from each channel's residual (its noise)
    # a filtered channel's samples are not independent: each counts as ``gain`` of one (its weight is
    # sqrt(gain) / noise, the degrees of freedom sum gain over the samples)
    gain = model.gain
    nch = y.shape[1]
    n_eff = float(np.sum(gain) * y.shape[0])
    w = np.sqrt(gain) / (np.sqrt(np.mean(y**2, axis=0)) + 1e-300)
    n_fev = n_jev = 0
    undetermined: dict[int, str] = {}
    x = start.copy()
    res: Any = None
    for _ in range(P + 2):
        for _pass in range(2 if nch > 1 else 1):  # one channel: its weight changes nothing
            res = run(w[None, :], x)
            n_fev += res.nfev
            n_jev += res.njev or 0
            x = full(res.x)
            r = res.fun.reshape(y.shape) / w[None, :]
            noise = np.sqrt(np.mean(r**2, axis=0))
            w = np.sqrt(gain) / np.maximum(noise, 1e-12 * (np.sqrt(np.mean(y**2, axis=0)) + 1e-300))
        rr, J = evaluate(res.x, w[None, :], True)
        dof = max(n_eff - len(free), 1.0)
        s2 = float(np.sum(rr**2) / dof)
        Jx = (J if J is not None else np.zeros((y.size, 0))) / scale[free]
        sig_free, reasons_free, info = _verdict(
            Jx, s2, x[free], lower[free], upper[free], free, [names[i] for i in free]
        )
        new = {free[k]: reasons_free[k] for k in range(len(free)) if reasons_free[k]}
        if not new:
            break
        undetermined.update(new)
        for i in new:
            x[i] = start[i]
        free = [i for i in free if i not in new]
        if not free:
            break
        cache.clear()
    final = model.histories(x[None, :P])[0]
    assert final is not None
    after = model.predict(final, x[P])
    if not free:
        dof = n_eff
        s2 = float(np.sum(((after - y) * w) ** 2) / dof)
        sig_free, info = (
            np.zeros(0),
            {"names": [], "fitted": [], "singular_values": [], "condition_number": None, "correlation": []},
        )

    sigma = {free[k]: float(sig_free[k]) for k in range(len(free))}
    fits = []
    for i in range(P + 1):
        p = params[i].target if i < P else None
        det = i not in undetermined and (i in free)
        fits.append(
            ParameterFit(
                path=names[i],
                name=p.name if p is not None else "time_offset",
                unit=p.unit if p is not None else "s",
                lower=float(lower[i]),
                upper=float(upper[i]),
                start=float(start[i]),
                value=float(x[i]) if det else None,
                sigma=sigma.get(i) if det else None,
                determined=det,
                reason=undetermined.get(i, "" if det else "held fixed"),
                estimate=float(x[i]),
            )
        )
    channels = []
    for k, c in enumerate(model.meas.channels):
        channels.append(
            {
                "name": c.name,
                "location": c.location,
                "axis": c.axis,
                "quantity": c.quantity,
                "unit": c.unit or c.si_unit,
                "si_unit": c.si_unit,
                "samples": int(y.shape[0]),
                "filtered": bool(c.order == 2 and model.sos is not None),
                "effective_samples": float(gain[k] * y.shape[0]),
                "rms_measured": float(np.sqrt(np.mean(y[:, k] ** 2))),
                "rms_before": float(np.sqrt(np.mean((before[:, k] - y[:, k]) ** 2))),
                "rms_after": float(np.sqrt(np.mean((after[:, k] - y[:, k]) ** 2))),
            }
        )
    kept = [i for i in range(P) if fits[i].determined]  # what the measurement does not determine stays
    data = apply(scene_dict(model.scene), [params[i].target for i in kept], [float(x[i]) for i in kept])
    calibrated = validate_scene(data)
    out_scene = scene_dict(calibrated)
    header = ["# calibrated by isolab against " + (model.meas.source or "a measurement")]
    for f in fits:
        if f.determined and f.value is not None and f.sigma is not None:
            header.append(f"#   {f.path} = {f.value:.6g} +- {f.sigma:.2g} {f.unit}".rstrip())
        elif f.reason != "held fixed":
            header.append(
                f"#   {f.path}: not determined by this measurement (left at {f.start:.6g} {f.unit})".rstrip()
            )
    text = "\n".join(header) + "\n" + yaml.safe_dump(out_scene, sort_keys=False)
    choice = model.choice
    return Calibration(
        parameters=fits[:P],
        time_offset=fits[P],
        channels=channels,
        identifiability=info,
        residual_variance=s2,
        degrees_of_freedom=float(dof),
        scene=out_scene,
        scene_yaml=text,
        simulation={
            "fidelity": choice.fidelity,
            "integrator": choice.integrator,
            "dt": choice.dt,
            "duration": model.duration,
        },
        highpass=model.highpass,
        lowpass=model.lowpass,
        evaluations={"engine_calls": model.calls, "cases": model.cases, "nfev": n_fev, "njev": n_jev},
        message=str(res.message) if res is not None else "",
        traces={
            "time": model.t,
            "channels": [
                {
                    "name": ch.name,
                    "unit": ch.unit or ch.si_unit,
                    "factor": ch.factor if ch.unit else 1.0,
                    "measured": y[:, k],
                    "before": before[:, k],
                    "after": after[:, k],
                }
                for k, ch in enumerate(model.meas.channels)
            ],
        },
    )
