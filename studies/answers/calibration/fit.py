"""The least-squares fit of a calibration and its answer.

:func:`calibrate` checks a request and fits the parameters (and the time offset) with
:func:`scipy.optimize.least_squares` (trust region reflective, bounded):

- **one engine batch per Jacobian**: the base case and one case per parameter, perturbed by a forward
  difference, go to the engine in one :func:`~isolab.engine.simulate` call;
- **time offset**: one more fitted parameter; its start is the best of a scan over its bounds with the
  starting scene, and its Jacobian column is the (central-difference) time derivative of the simulated
  traces;
- **starts**: the scene's values (and, with ``starts: N``, ``N - 1`` Sobol' points within the bounds,
  the best fit kept: :mod:`.starts`);
- **weights**: residuals are divided by each channel's sensor noise, stated or estimated from the record
  alone (:mod:`.uncertainty`). A filtered sample counts as the filter's noise gain of an independent
  one. A second fit weights each channel by its noise inflated by what the first left: its chi-square
  per degree of freedom and the correlation of its residuals. The covariance ``(J^T J)^-1`` of the
  Jacobian so weighted gives the 1-sigma uncertainty of every fitted value, and the chi-square against
  the noise (``residual_variance``, about 1 when the residuals are the noise) judges the fit;
- **identifiability**: a parameter whose Jacobian column is (near) zero per bounds' width, that is
  (near) collinear with others, or whose 1-sigma uncertainty exceeds a quarter of its bounds' width or
  half its value is reported as not determined by this measurement, with the reason; it keeps the
  scene's value and the others are fitted again without it.

The answer is a :class:`Calibration` (SI units), one :class:`ParameterFit` per fitted quantity.
"""

from __future__ import annotations

import hashlib
import math
import textwrap
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import yaml
from pydantic import ValidationError

from isolab.studies.answers.calibration.measurements import LOCATION_CG, Measurement, stated_noise
from isolab.studies.answers.calibration.model import ChannelModel, check_step, simulation_choice
from isolab.studies.answers.calibration.parameters import (
    BoundedParameter,
    FitSpec,
    fit_parameters,
    to_si_loc,
)
from isolab.studies.answers.calibration.scene_text import calibrated_text
from isolab.studies.answers.calibration.starts import start_count, start_points, start_spread
from isolab.studies.answers.calibration.uncertainty import (
    ChannelMisfit,
    channel_inflation,
    filter_correlation_length,
    goodness_of_fit,
    parameter_verdict,
    record_noise,
    step_timing_error,
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
    goodness_of_fit: dict[str, Any]
    starts: dict[str, Any]
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
            "goodness_of_fit": self.goodness_of_fit,
            "starts": self.starts,
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


@dataclass
class PreparedFit:
    """A checked calibration, ready to fit: its channel model (:attr:`model`, whose ``duration``,
    ``choice`` and ``params`` size its cost), the fitted parameters, the time offset's bounds, each
    channel's stated noise (SI, NaN where the record's own scatter estimates it), the number of starts
    and the scene's text (its file, or the data as given) the calibrated scene is written into."""

    model: ChannelModel
    params: list[BoundedParameter]
    offset: tuple[float, float, Any]
    offset_fixed: bool
    prefix: Loc
    noise: np.ndarray
    starts: int
    scene_text: str

    def run(self) -> Calibration:
        """The least-squares fit (see :func:`calibrate`)."""
        return _fit(self)


def calibrate(
    scene: Mapping[str, Any] | Scene,
    measurement: Measurement,
    fit: Sequence[FitSpec | Mapping[str, Any]],
    **options: Any,
) -> Calibration:
    """Fit ``fit``'s parameters of ``scene`` (and the time offset) to ``measurement``: see
    :func:`prepare_calibration` for the arguments and ``options``; raises :class:`DefinitionError` on bad
    input."""
    return prepare_calibration(scene, measurement, fit, **options).run()


def prepare_calibration(
    scene: Mapping[str, Any] | Scene,
    measurement: Measurement,
    fit: Sequence[FitSpec | Mapping[str, Any]],
    offset: Mapping[str, Any] | None = None,
    simulation: Mapping[str, Any] | None = None,
    highpass: Any = None,
    lowpass: Any = None,
    prefix: Loc | None = None,
    noise: Mapping[str, Any] | None = None,
    starts: Any = 1,
    scene_text: str | None = None,
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
            most ``0.03 / dt``; 0: none).
        prefix: where the request's fields live, for error locations (default ``["body"]``).
        noise: each channel's sensor noise (standard deviation of one sample), by channel name: a number
            in the channel's unit or text with units. A channel not named has its noise estimated from
            the record's own sample-to-sample scatter (:func:`.uncertainty.record_noise`).
        starts: fits started from the scene's values and ``starts - 1`` more points of a Sobol'
            sequence within the bounds; the best is kept and the spread reported (default 1).
        scene_text: the scene's file as written (YAML or JSON); the calibrated scene is this text with
            the fitted values written in, in the units the scene used, and its comments kept (default the
            scene data as given, dumped as YAML).

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
    check_step(sc, measurement, choice, pre)
    stated = stated_noise(measurement, noise, pre)
    n_starts = start_count(starts, [*pre, "starts"])
    if scene_text is None:
        data = scene_dict(sc) if isinstance(scene, Scene) else dict(scene)
        scene_text = yaml.safe_dump(data, sort_keys=False)
    model = ChannelModel(sc, params, measurement, choice, (o_lo, o_hi), hp, lp, pre)
    return PreparedFit(
        model,
        params,
        (o_lo, o_hi, off.get("start")),
        fixed_offset is not None,
        pre,
        stated,
        n_starts,
        scene_text,
    )


def _fit(prep: PreparedFit) -> Calibration:
    model, params, offset, pre = prep.model, prep.params, prep.offset, prep.prefix
    P = len(params)
    names = [p.target.path for p in params] + ["time_offset"]
    lower = np.array([p.lower for p in params] + [offset[0]])
    upper = np.array([p.upper for p in params] + [offset[1]])
    scale = upper - lower
    start = np.array([p.start for p in params] + [0.0])
    y = model.measured
    nch = y.shape[1]

    # ---- each channel's noise: stated, or the record's own scatter; what a filtered sample counts for
    raw = np.stack([c.values for c in model.meas.channels], axis=1)
    stated = np.isfinite(prep.noise)
    sigma_raw = np.where(stated, prep.noise, [record_noise(raw[:, k]) for k in range(nch)])
    sigma_raw = np.maximum(sigma_raw, 1e-9 * np.sqrt(np.mean(y**2, axis=0)) + 1e-300)  # a noiseless record
    gain = model.gain  # a filtered sample counts as ``gain`` of an independent one
    samples = gain * y.shape[0]
    noise_f = sigma_raw * np.sqrt(gain)
    reference = np.where(
        [c.order == 2 for c in model.meas.channels],
        filter_correlation_length(model.sos, y.shape[0]),
        1.0,
    )

    def scan(hist: tuple[np.ndarray, np.ndarray]) -> float:
        """The offset that best aligns ``hist`` with the measurement (a scan over its bounds)."""
        if offset[2] is not None:
            tau = to_si_loc(offset[2], "time", [*pre, "offset", "start"])
        else:
            taus = np.linspace(offset[0], offset[1], SCAN_POINTS) if not prep.offset_fixed else offset[:1]
            rms0 = np.sqrt(np.mean(y**2, axis=0)) + 1e-300
            cost = np.sum(((model.predict_many(hist, taus) - y) / rms0) ** 2, axis=(1, 2))
            tau = float(taus[int(np.argmin(cost))])
        return min(max(tau, lower[P]), upper[P])

    base = model.histories(start[None, :P])[0]
    if base is None:
        raise DefinitionError(
            [detail([*pre, "scene"], "the scene as given does not simulate (unstable, tipping or invalid)")]
        )
    start[P] = scan(base)
    before = model.predict(base, start[P])

    free = list(range(P)) + ([] if prep.offset_fixed else [P])
    cache: dict[bytes, tuple[np.ndarray, np.ndarray | None]] = {}

    def full(xf: np.ndarray) -> np.ndarray:
        x = start.copy()
        x[free] = xf * scale[free]
        return x

    def evaluate(xf: np.ndarray, weights: np.ndarray, with_jac: bool) -> tuple[np.ndarray, np.ndarray | None]:
        key = xf.tobytes() + hashlib.blake2b(weights.tobytes(), digest_size=16).digest()
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
        from scipy.optimize import least_squares  # on first use: importing scipy costs a command 0.4 s

        lo = lower[free] / scale[free]
        hi = upper[free] / scale[free]
        try:
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
        except (ValueError, np.linalg.LinAlgError) as err:
            raise DefinitionError(
                [detail([*pre, "measurement"], f"the fit cannot go on from this measurement: {err}")]
            ) from None

    shape = 1.0 / np.sqrt(model.profile)  # a filtered sample near the record's ends is noisier

    def misfits(fun: np.ndarray, weights: np.ndarray) -> list[ChannelMisfit]:
        r = fun.reshape(y.shape) / weights
        return channel_inflation(r * shape, noise_f, samples, reference, len(free))

    def inflated(ms: list[ChannelMisfit]) -> np.ndarray:
        """(N, ch) weights of the samples: each channel's noise, inflated by its misfit and correlation (a
        noise estimated from the record yields to the residuals where they are smaller)."""
        c = np.array(
            [
                (max(1.0, m.reduced) if stated[k] else max(m.reduced, 1e-12)) * max(1.0, m.correlation)
                for k, m in enumerate(ms)
            ]
        )
        return shape / (sigma_raw * np.sqrt(c))

    # pass 1 weights each channel by its noise; pass 2 by its noise inflated by what pass 1 left
    w = shape / sigma_raw
    n_fev = n_jev = 0
    undetermined: dict[int, str] = {}
    x = start.copy()
    res: Any = None
    points = start_points(start[:P], lower[:P], upper[:P], prep.starts)
    ends = np.tile(start[:P], (len(points), 1))
    costs: list[float] = []
    best = 0
    for attempt in range(P + 2):
        for _pass in range(2 if nch > 1 else 1):
            if attempt == 0 and _pass == 0:
                for j, pt in enumerate(points):
                    hist = base if j == 0 else model.histories(pt[None, :])[0]
                    if hist is None:  # this start does not simulate: it ends where it began
                        costs.append(math.inf)
                        continue
                    rj = run(w, np.concatenate([pt, [scan(hist) if j else start[P]]]))
                    n_fev += rj.nfev
                    n_jev += rj.njev or 0
                    ends[j] = full(rj.x)[:P]
                    costs.append(2.0 * float(rj.cost))
                    if res is None or rj.cost < res.cost:
                        res, best = rj, j
                x = full(res.x)
                w = inflated(misfits(res.fun, w))
                continue
            res = run(w, x)
            n_fev += res.nfev
            n_jev += res.njev or 0
            x = full(res.x)
            w = inflated(misfits(res.fun, w))
        _, J = evaluate((x[free] / scale[free]), w, True)
        Jx = (J if J is not None else np.zeros((y.size, 0))) / scale[free]
        sig_free, reasons_free, info = parameter_verdict(Jx, scale[free], x[free], [names[i] for i in free])
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
    final_misfits = channel_inflation((after - y) * shape, noise_f, samples, reference, len(free))
    fit_quality = goodness_of_fit(
        [c.name for c in model.meas.channels],
        final_misfits,
        ["stated" if s else "estimated" for s in stated],
        len(free),
        y.shape[0],
    )
    if not free:
        sig_free, info = (
            np.zeros(0),
            {"names": [], "fitted": [], "singular_values": [], "condition_number": None, "correlation": []},
        )

    sigma = {free[k]: float(sig_free[k]) for k in range(len(free))}
    timing = step_timing_error(model.choice.dt) if any(c.order == 2 for c in model.meas.channels) else 0.0
    if P in sigma and math.isfinite(sigma[P]):  # the engine places an acceleration jump within a step
        sigma[P] = math.hypot(sigma[P], timing)
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
    spread = start_spread(
        names[:P], points, ends, costs, best, np.array([sigma.get(i, math.nan) for i in range(P)])
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
                "effective_samples": float(samples[k]),
                "noise": float(sigma_raw[k]),
                "noise_source": "stated" if stated[k] else "estimated",
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
    header += ["#   " + line for line in textwrap.wrap(fit_quality["verdict"], 100)]
    text = calibrated_text(prep.scene_text, header, [(params[i].target, float(x[i])) for i in kept])
    choice = model.choice
    return Calibration(
        parameters=fits[:P],
        time_offset=fits[P],
        channels=channels,
        identifiability=info,
        residual_variance=float(fit_quality["reduced_chi_square"]),
        degrees_of_freedom=float(fit_quality["dof"]),
        goodness_of_fit=fit_quality,
        starts=spread,
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
