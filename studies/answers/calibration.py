"""Calibrate a scene against measured motion: fit isolator (or any continuous) parameters to a test.

A measurement is a time column plus channels. Each channel names where it measures (``cg`` or a point of
interest of the scene), an axis (``x``, ``y``, ``z`` or the rotations ``rx``, ``ry``, ``rz``), a quantity
(``displacement``, ``velocity`` or ``acceleration``) and its units, written as a column header::

    time [s], cg.z.displacement [mm], tool.y.acceleration [g], cg.rx.velocity [mrad/s]

(:func:`read_measurement` reads CSV or netCDF files, :func:`measurement_from_csv` CSV text and
:func:`measurement_from_columns` JSON-like columns.) The parameters to fit are study parameter paths
(:mod:`isolab.studies.inputs.parameters`: ``isolators.f_vertical``, ``isolators.zeta``, ``stages.y.mass``
...) with
bounds. :func:`calibrate` fits them with :func:`scipy.optimize.least_squares` (trust region reflective,
bounded):

- **one engine batch per Jacobian**: the base case and one case per parameter, perturbed by a forward
  difference, go to the engine in one :func:`~isolab.engine.simulate` call;
- **time offset**: the measurement's clock is not the simulation's. The simulated motion at measurement
  time ``t`` is the one at ``t - offset`` (before the simulation's zero the machine is at rest). ``offset``
  is one more fitted parameter; its start is the best of a scan over its bounds with the starting scene,
  and its Jacobian column is the (central-difference) time derivative of the simulated traces;
- **sample rates**: the engine records displacement at its step ``dt``; velocity and acceleration are its
  central first and second differences there (the mean over +- ``dt``), and every channel is interpolated
  linearly onto the measurement's times;
- **acceleration channels**: fitted in acceleration. Accelerometers carry a bias and drift, so acceleration
  channels, measured and simulated alike, have a straight line fitted and removed and pass through the same
  zero-phase band-pass (2nd-order Butterworth run forwards and backwards): high-pass ``highpass`` (default
  0.5 Hz), low-pass ``lowpass`` (default a fifth of the sample rate, at most ``0.03 / dt``: above it the
  engine's step smears a stage's acceleration jumps); 0 switches either off. Applied to both, the filters
  bias nothing. A filtered sample counts as the filter's noise gain of an independent one in the weights
  and the degrees of freedom;
- **weights**: residuals are divided by each channel's noise, estimated from the residuals of a first fit
  (weighted by the channels' RMS), then the fit is repeated. The residual variance ``s^2`` of the final fit
  gives the covariance ``s^2 (J^T J)^-1`` and the 1-sigma uncertainty of every fitted value;
- **identifiability**: a parameter whose Jacobian column is (near) zero, that is (near) collinear with
  others (the singular values of the column-normalised Jacobian), or whose 1-sigma uncertainty exceeds a
  quarter of its bounds' width or half its value is reported as not determined by this measurement, with
  the reason, instead of a number; it keeps the scene's value and the others are fitted again without it.

The answer (:class:`Calibration`) holds the fitted values with uncertainties, the misfit (RMS residual)
per channel before (the scene as given, aligned in time by the offset scan) and after, and the calibrated
scene as YAML. Errors in the input raise :class:`~isolab.studies.inputs.definitions.DefinitionError` whose
details name the field (``loc``).
"""

from __future__ import annotations

import io
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from pydantic import ValidationError
from scipy.optimize import least_squares
from scipy.signal import butter, detrend, sosfiltfilt

from isolab.engine import STATUS_NAMES, SceneError, simulate
from isolab.studies.inputs.definitions import (
    DefinitionError,
    Loc,
    detail,
    screen_definition,
    validation_details,
)
from isolab.studies.inputs.parameters import Target, apply, resolve, scene_dict
from isolab.studies.inputs.scenes import build_batch
from isolab.studies.inputs.schema import Scene
from isolab.studies.inputs.study import validate_scene
from isolab.studies.units import to_si

LOCATION_CG = "cg"
AXIS_NAMES = ("x", "y", "z", "rx", "ry", "rz")
QUANTITIES = ("displacement", "velocity", "acceleration")
"""Quantities a channel may measure; the index is the order of the time derivative of displacement."""
QUANTITY_ALIASES = {
    "displacement": "displacement",
    "disp": "displacement",
    "d": "displacement",
    "velocity": "velocity",
    "vel": "velocity",
    "v": "velocity",
    "acceleration": "acceleration",
    "accel": "acceleration",
    "acc": "acceleration",
    "a": "acceleration",
}
TIME_NAMES = ("time", "t")

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
MAX_PARAMETERS = 8
MAX_CHANNELS = 16
MAX_SAMPLES = 200_000
"""Most samples of one measurement (per channel)."""
MAX_SIMULATED_SAMPLES = 60_000
"""Longest simulated history of one case (samples of the engine's output step): 60 s at 1 ms."""
MIN_SAMPLES = 16
SCAN_POINTS = 801
"""Offsets tried by the scan that starts the time offset."""

_HEADER = re.compile(r"^\s*(?P<name>[^\[\(]*?)\s*(?:[\[\(](?P<unit>[^\]\)]*)[\]\)])?\s*$")


# --------------------------------------------------------------------------------------------- measurement
@dataclass
class Channel:
    """One measured channel, values in SI (m, m/s, m/s^2; rad, rad/s, rad/s^2)."""

    name: str  # canonical: location.axis.quantity
    location: str  # "cg" or a point name
    axis: str
    quantity: str
    unit: str  # as given ("" for SI)
    factor: float  # SI per given unit
    values: np.ndarray

    @property
    def order(self) -> int:
        return QUANTITIES.index(self.quantity)

    @property
    def rotational(self) -> bool:
        return self.axis.startswith("r")

    @property
    def si_unit(self) -> str:
        base = "rad" if self.rotational else "m"
        return base + ("", "/s", "/s^2")[self.order]


@dataclass
class Measurement:
    """Sample times (s, increasing) and channels of one test."""

    time: np.ndarray
    channels: list[Channel]
    source: str = ""


def parse_header(text: str, loc: Loc) -> tuple[str, str]:
    """``"cg.z.displacement [mm]"`` -> ("cg.z.displacement", "mm"); the unit may be in ( ) or absent."""
    m = _HEADER.match(text)
    if m is None or not m.group("name"):
        raise DefinitionError([detail(loc, f"cannot read the column header {text!r}: write NAME [UNIT]")])
    return m.group("name").strip(), (m.group("unit") or "").strip()


def _unit_factor(unit: str, quantity: str, rotational: bool, loc: Loc) -> float:
    """SI per ``unit`` of a channel of ``quantity`` (the project's unit layer; ``g`` is standard gravity)."""
    order = QUANTITIES.index(quantity)
    if not unit:
        return 1.0
    where = ".".join(str(x) for x in loc if x != "body")
    try:
        if rotational:
            per_time = ("", " * s", " * s^2")[order]
            return to_si(f"1 ({unit}){per_time}", "angle", where)
        return to_si(f"1 ({unit})", ("length", "velocity", "acceleration")[order], where)
    except ValueError as err:
        msg = str(err)
        kind = ("rad", "rad/s", "rad/s^2")[order] if rotational else ("m", "m/s", "m/s^2")[order]
        raise DefinitionError(
            [detail(loc, f"unit {unit!r} is not a unit of {quantity} (like {kind}): {msg}")]
        ) from None


def parse_channel(name: str, unit: str, values: Any, loc: Loc, value_loc: Loc | None = None) -> Channel:
    """A channel from its name (``location.axis.quantity``), unit and values (given units)."""
    parts = name.strip().split(".")
    if len(parts) != 3:
        raise DefinitionError(
            [
                detail(
                    loc,
                    f"channel {name!r}: name it LOCATION.AXIS.QUANTITY, e.g. cg.z.displacement or "
                    "tool.y.acceleration (LOCATION cg or a point of the scene, AXIS x, y, z, rx, ry or rz, "
                    "QUANTITY displacement, velocity or acceleration)",
                )
            ]
        )
    location, axis, quantity = parts[0].strip(), parts[1].strip().lower(), parts[2].strip().lower()
    if axis not in AXIS_NAMES:
        raise DefinitionError([detail(loc, f"channel {name!r}: axis {axis!r} is not one of {AXIS_NAMES}")])
    if quantity not in QUANTITY_ALIASES:
        raise DefinitionError(
            [detail(loc, f"channel {name!r}: quantity {quantity!r} is not one of {', '.join(QUANTITIES)}")]
        )
    quantity = QUANTITY_ALIASES[quantity]
    if location.lower() in ("cg", "c.g"):
        location = LOCATION_CG
    factor = _unit_factor(unit, quantity, axis.startswith("r"), loc)
    try:
        raw = np.asarray(values, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise DefinitionError(
            [detail(value_loc or loc, f"channel {name!r}: values must be numbers")]
        ) from None
    bad = ~np.isfinite(raw)
    if bad.any():
        raise DefinitionError(
            [
                detail(
                    value_loc or loc,
                    f"channel {name!r}: sample {int(np.flatnonzero(bad)[0])} is not a finite number",
                )
            ]
        )
    with np.errstate(over="ignore", invalid="ignore"):
        si = raw * factor
    if not np.all(np.isfinite(si)):
        raise DefinitionError(
            [detail(value_loc or loc, f"channel {name!r}: values too large for a float in SI")]
        )
    return Channel(f"{location}.{axis}.{quantity}", location, axis, quantity, unit, factor, si)


def _time_values(values: Any, unit: str, loc: Loc) -> np.ndarray:
    factor = 1.0
    if unit:
        try:
            factor = to_si(f"1 ({unit})", "time", ".".join(str(x) for x in loc if x != "body"))
        except ValueError as err:
            raise DefinitionError([detail(loc, f"time unit {unit!r}: {err}")]) from None
    try:
        t = np.asarray(values, dtype=np.float64).reshape(-1) * factor
    except (TypeError, ValueError):
        raise DefinitionError([detail(loc, "time values must be numbers")]) from None
    if not np.all(np.isfinite(t)):
        raise DefinitionError([detail(loc, "time values must be finite numbers")])
    return t


def _check_measurement(m: Measurement, prefix: Loc) -> Measurement:
    t = m.time
    if t.size < MIN_SAMPLES:
        raise DefinitionError([detail([*prefix, "time"], f"at least {MIN_SAMPLES} samples, got {t.size}")])
    if t.size > MAX_SAMPLES:
        raise DefinitionError(
            [detail([*prefix, "time"], f"at most {MAX_SAMPLES} samples per channel, got {t.size}")]
        )
    if np.any(np.diff(t) <= 0):
        i = int(np.flatnonzero(np.diff(t) <= 0)[0]) + 1
        raise DefinitionError([detail([*prefix, "time"], f"times must increase; sample {i} does not")])
    if not m.channels:
        raise DefinitionError([detail([*prefix, "channels"], "no channel: give at least one")])
    if len(m.channels) > MAX_CHANNELS:
        raise DefinitionError([detail([*prefix, "channels"], f"at most {MAX_CHANNELS} channels")])
    seen: dict[str, int] = {}
    for i, c in enumerate(m.channels):
        if c.values.size != t.size:
            raise DefinitionError(
                [
                    detail(
                        [*prefix, "channels", i],
                        f"channel {c.name!r} has {c.values.size} samples, time has {t.size}",
                    )
                ]
            )
        if c.name in seen:
            raise DefinitionError(
                [
                    detail(
                        [*prefix, "channels", i],
                        f"channel {c.name!r} is given twice (also channel {seen[c.name]})",
                    )
                ]
            )
        seen[c.name] = i
    return m


def measurement_from_columns(
    time: Any, channels: Sequence[Mapping[str, Any]], time_unit: str = "s", prefix: Loc | None = None
) -> Measurement:
    """A measurement from JSON-like columns: ``time`` (in ``time_unit``) and channels
    ``{"name": "cg.z.displacement", "unit": "mm", "values": [...]}``."""
    pre: Loc = ["body", "measurement"] if prefix is None else list(prefix)
    t = _time_values(time, time_unit, [*pre, "time"])
    out = []
    for i, ch in enumerate(channels):
        loc = [*pre, "channels", i]
        if not isinstance(ch, Mapping) or "name" not in ch or "values" not in ch:
            raise DefinitionError([detail(loc, "a channel is {name, unit, values}")])
        out.append(
            parse_channel(
                str(ch["name"]), str(ch.get("unit") or ""), ch["values"], [*loc, "name"], [*loc, "values"]
            )
        )
    return _check_measurement(Measurement(t, out, "columns"), pre)


def measurement_from_csv(text: str, prefix: Loc | None = None, source: str = "CSV") -> Measurement:
    """A measurement from CSV text: a header row naming each column (``time [s]`` first, then channels
    ``cg.z.displacement [mm]`` ...), then one row per sample. Comma, semicolon or tab separated; lines
    starting with ``#`` are comments."""
    pre: Loc = ["body", "measurement"] if prefix is None else list(prefix)
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if len(lines) < 2:
        raise DefinitionError([detail([*pre, "csv"], "a header row and at least one row of samples")])
    sep = next((s for s in (",", ";", "\t") if s in lines[0]), ",")
    header = [h.strip() for h in lines[0].split(sep)]
    if len(header) < 2:
        raise DefinitionError([detail([*pre, "csv"], "the header names time and at least one channel")])
    try:
        data = np.loadtxt(io.StringIO("\n".join(lines[1:])), delimiter=sep, ndmin=2, dtype=np.float64)
    except ValueError as err:
        raise DefinitionError([detail([*pre, "csv"], f"cannot read the samples as numbers: {err}")]) from None
    if data.shape[1] != len(header):
        raise DefinitionError(
            [detail([*pre, "csv"], f"the header has {len(header)} columns, the rows {data.shape[1]}")]
        )
    tname, tunit = parse_header(header[0], [*pre, "csv"])
    if tname.lower() not in TIME_NAMES:
        raise DefinitionError([detail([*pre, "csv"], f"the first column must be time, got {tname!r}")])
    t = _time_values(data[:, 0], tunit or "s", [*pre, "csv"])
    channels = []
    for i, h in enumerate(header[1:], start=1):
        name, unit = parse_header(h, [*pre, "csv"])
        channels.append(parse_channel(name, unit, data[:, i], [*pre, "csv"]))
    return _check_measurement(Measurement(t, channels, source), [*pre, "csv"])


def measurement_from_netcdf(path: str | Path) -> Measurement:
    """A measurement from a netCDF file: a ``time`` coordinate (``units`` attribute, default s; or a
    datetime/timedelta axis, taken from its first sample) and one variable per channel along it, named
    ``location.axis.quantity`` (or with ``location``, ``axis``, ``quantity`` attributes) with a ``units``
    attribute."""
    import xarray as xr

    pre: Loc = ["measurement"]
    with xr.open_dataset(path, decode_times=True) as ds:
        ds = ds.load()
    if "time" not in ds.coords and "time" not in ds.variables:
        raise DefinitionError([detail([*pre, "time"], f"{path}: no time coordinate")])
    tv = ds["time"]
    if np.issubdtype(tv.dtype, np.datetime64) or np.issubdtype(tv.dtype, np.timedelta64):
        t = (tv.values - tv.values[0]) / np.timedelta64(1, "ns") * 1e-9
    else:
        t = _time_values(tv.values, str(tv.attrs.get("units", "s")), [*pre, "time"])
    channels = []
    for i, (var_name, var) in enumerate(ds.data_vars.items()):
        if var.dims != ("time",):
            continue
        a = var.attrs
        if {"location", "axis", "quantity"} <= set(a):
            name = f"{a['location']}.{a['axis']}.{a['quantity']}"
        else:
            name = str(var_name)
        channels.append(parse_channel(name, str(a.get("units", "")), var.values, [*pre, "channels", i]))
    return _check_measurement(Measurement(np.asarray(t, dtype=np.float64), channels, str(path)), pre)


def read_measurement(path: str | Path) -> Measurement:
    """A measurement file: netCDF (``.nc``, ``.nc4``, ``.cdf``) or CSV (anything else)."""
    p = Path(path)
    if p.suffix.lower() in (".nc", ".nc4", ".cdf", ".netcdf"):
        return measurement_from_netcdf(p)
    return measurement_from_csv(p.read_text(encoding="utf-8"), prefix=["measurement"], source=str(p))


def measurement_csv(m: Measurement, units: Mapping[str, str] | None = None) -> str:
    """The measurement as CSV text (the header as :func:`measurement_from_csv` reads it), each channel
    in its own unit (or ``units[name]``)."""
    cols = [m.time]
    header = ["time [s]"]
    for c in m.channels:
        unit = (units or {}).get(c.name, c.unit)
        factor = c.factor if unit == c.unit else _unit_factor(unit, c.quantity, c.rotational, [c.name])
        header.append(f"{c.name} [{unit}]" if unit else c.name)
        cols.append(c.values / factor)
    buf = io.StringIO()
    np.savetxt(buf, np.column_stack(cols), delimiter=",", header=",".join(header), comments="", fmt="%.10g")
    return buf.getvalue()


# ----------------------------------------------------------------------------------------------- parameters
@dataclass(frozen=True)
class FitSpec:
    """A parameter to fit: its study parameter path, bounds and optional start (numbers in SI or text
    with units)."""

    path: str
    lower: Any
    upper: Any
    start: Any = None


_FIT = re.compile(
    r"^\s*(?P<path>[^=]+?)\s*=\s*(?P<lower>[^:@]+?)\s*:\s*(?P<upper>[^:@]+?)\s*(?:@\s*(?P<start>.+?))?\s*$"
)


def parse_fit(text: str) -> FitSpec:
    """``"isolators.f_vertical=1:6"`` (or ``"=1 Hz:6 Hz"``, with a start ``"=1:6@3.5"``) as a FitSpec."""
    m = _FIT.match(text)
    if m is None:
        raise ValueError(
            f"--fit {text!r}: write PATH=LOWER:UPPER (e.g. isolators.f_vertical=1:6 or =1 Hz:6 Hz)"
        )
    return FitSpec(m.group("path"), m.group("lower"), m.group("upper"), m.group("start"))


@dataclass
class _Param:
    target: Target
    lower: float
    upper: float
    start: float
    scale: float


def _plain(value: Any, target: Target, loc: Loc) -> float:
    where = ".".join(str(x) for x in loc if x != "body")
    try:
        return to_si(value, target.dimension, where)
    except ValueError as err:
        raise DefinitionError([detail(loc, str(err))]) from None


def _scene_value(scene: Scene, target: Target) -> float | None:
    """The value ``target`` has in ``scene`` (a preset's figure where the scene leaves it to the preset)."""
    node: Any = scene_dict(scene)
    parts = target.writes[0].split(".")
    for i, part in enumerate(parts):
        if isinstance(node, list):
            if i and parts[i - 1] == "stages":
                node = next((s for s in node if s.get("name") == part), None)
            else:
                node = node[int(part)] if part.isdigit() and int(part) < len(node) else None
        elif isinstance(node, dict):
            node = node.get(part)
        else:
            node = None
        if node is None:
            break
    if isinstance(node, int | float) and not isinstance(node, bool):
        return float(node)
    iso = scene.isolators
    key = parts[-1]
    if parts[0] == "isolators" and key in ("f_vertical", "f_horizontal", "zeta"):
        if parts[1] == "list" and iso.mounts is not None:
            mount = iso.mounts[int(parts[2])]
            if mount.preset is not None:
                return float(getattr(iso.preset_of(mount.preset), key))
            own = getattr(iso, key)
            if own is not None:
                return float(own)
        return float(getattr(iso.preset_of(iso.preset), key))
    return None


def _parameters(scene: Scene, fit: Sequence[FitSpec | Mapping[str, Any]], prefix: Loc) -> list[_Param]:
    if not fit:
        raise DefinitionError([detail([*prefix, "fit"], "name at least one parameter to fit")])
    if len(fit) > MAX_PARAMETERS:
        raise DefinitionError([detail([*prefix, "fit"], f"at most {MAX_PARAMETERS} parameters")])
    out: list[_Param] = []
    base = scene_dict(scene)
    for i, spec in enumerate(fit):
        loc = [*prefix, "fit", i]
        try:
            s = spec if isinstance(spec, FitSpec) else FitSpec(**dict(spec))
        except TypeError:
            raise DefinitionError(
                [detail(loc, "a parameter to fit is {path, lower, upper, start?}")]
            ) from None
        try:
            t = resolve(s.path, scene)
        except ValueError as err:
            raise DefinitionError([detail([*loc, "path"], str(err))]) from None
        if t.categorical or t.path.split(".")[0] == "simulation":
            raise DefinitionError(
                [detail([*loc, "path"], f"{s.path!r} cannot be fitted: only continuous scene inputs can")]
            )
        for j, other in enumerate(out):
            if set(t.writes) & set(other.target.writes):
                raise DefinitionError([detail([*loc, "path"], f"{s.path!r} sets what fit[{j}] already fits")])
        lo, hi = _plain(s.lower, t, [*loc, "lower"]), _plain(s.upper, t, [*loc, "upper"])
        if not hi > lo:
            raise DefinitionError([detail([*loc, "upper"], f"must be above lower ({lo:g} {t.unit})".strip())])
        if s.start is not None:
            start = _plain(s.start, t, [*loc, "start"])
            if not lo <= start <= hi:
                raise DefinitionError(
                    [detail([*loc, "start"], f"must lie between the bounds {lo:g} and {hi:g}")]
                )
        else:
            current = _scene_value(scene, t)
            start = (lo + hi) / 2.0 if current is None else min(max(current, lo), hi)
        for bound, name in ((lo, "lower"), (hi, "upper")):
            try:
                build_batch([validate_scene(apply(base, [t], [bound]))])
            except (ValueError, ValidationError) as err:
                msg = (
                    "; ".join(d["msg"] for d in validation_details(err, []))
                    if isinstance(err, ValidationError)
                    else str(err)
                )
                raise DefinitionError(
                    [
                        detail(
                            [*loc, name],
                            f"{t.path} = {bound:g} {t.unit} makes the scene invalid: {msg}".strip(),
                        )
                    ]
                ) from None
        out.append(_Param(t, lo, hi, start, hi - lo))
    return out


# -------------------------------------------------------------------------------------------------- model
@dataclass
class _Choice:
    fidelity: str
    integrator: str
    dt: float
    auto_step: bool


class _Model:
    """Simulated channels of a scene on the measurement's times, as the parameters and offset vary."""

    def __init__(
        self,
        scene: Scene,
        params: list[_Param],
        meas: Measurement,
        choice: _Choice,
        offset_bounds: tuple[float, float],
        highpass: float,
        lowpass: float | None,
        prefix: Loc,
        check_signal: bool = True,
    ):
        self.scene = scene
        self.params = params
        self.meas = meas
        self.choice = choice
        self.t = meas.time
        self.duration = max(float(meas.time[-1] - offset_bounds[0]) + 3 * choice.dt, 10 * choice.dt)
        self.points = list(scene.points)
        self.sos: np.ndarray | None = None
        self.highpass = 0.0
        self.lowpass = 0.0
        self.accel = [k for k, c in enumerate(meas.channels) if c.order == 2]
        self.gain = np.ones(len(meas.channels))
        if self.accel:
            step = np.diff(self.t)
            fs = 1.0 / float(step.mean())
            lp = min(0.2 * fs, 0.03 / choice.dt) if lowpass is None else lowpass
            if lp >= 0.45 * fs:
                raise DefinitionError(
                    [detail([*prefix, "lowpass"], f"must be below half the sample rate ({fs / 2:g} Hz)")]
                )
            if highpass > 0 and lp > 0 and not highpass < lp:
                raise DefinitionError([detail([*prefix, "highpass"], f"must be below lowpass ({lp:g} Hz)")])
            if highpass >= 0.45 * fs:
                raise DefinitionError(
                    [detail([*prefix, "highpass"], f"must be below half the sample rate ({fs / 2:g} Hz)")]
                )
            if (highpass > 0 or lp > 0) and np.max(np.abs(step - step.mean())) > 0.01 * step.mean():
                raise DefinitionError(
                    [
                        detail(
                            [*prefix, "measurement", "time"],
                            "acceleration channels are filtered, which needs evenly spaced samples (within "
                            "1 %); resample them, or switch the filters off (highpass 0, lowpass 0)",
                        )
                    ]
                )
            if highpass > 0 and lp > 0:
                self.sos = butter(2, [highpass, lp], btype="bandpass", fs=fs, output="sos")
            elif highpass > 0:
                self.sos = butter(2, highpass, btype="highpass", fs=fs, output="sos")
            elif lp > 0:
                self.sos = butter(2, lp, btype="lowpass", fs=fs, output="sos")
            self.highpass, self.lowpass = float(highpass), float(lp)
            if self.sos is not None:
                if self.t.size <= 3 * (2 * len(self.sos) + 1):
                    raise DefinitionError(
                        [
                            detail(
                                [*prefix, "measurement", "time"],
                                f"{self.t.size} samples are too few to filter the acceleration channels; "
                                "give more, or switch the filters off (highpass 0, lowpass 0)",
                            )
                        ]
                    )
                self.gain[self.accel] = _noise_gain(self.sos, self.t.size)
        self.cases = 0
        self.calls = 0
        self.measured = self.filtered(np.stack([c.values for c in meas.channels], axis=1))
        rms = np.sqrt(np.mean(self.measured**2, axis=0))
        for k, c in enumerate(meas.channels if check_signal else []):
            if not (np.isfinite(rms[k]) and rms[k] > 1e-30 and rms[k] < 1e30):
                raise DefinitionError(
                    [
                        detail(
                            [*prefix, "measurement", "channels", k],
                            f"channel {c.name!r} has no usable signal (RMS {rms[k]:.3g} in SI"
                            + (", after the acceleration filters)" if c.order == 2 else ")"),
                        )
                    ]
                )

    def filtered(self, y: np.ndarray) -> np.ndarray:
        """(N, ch) with the acceleration channels detrended (a straight line fitted and removed: the
        sensor's bias and linear drift) and band-passed (zero phase)."""
        if self.sos is None:
            return y
        y = np.array(y, dtype=np.float64, copy=True)
        y[:, self.accel] = sosfiltfilt(self.sos, detrend(y[:, self.accel], axis=0), axis=0)
        return y

    def histories(self, values: np.ndarray) -> list[tuple[np.ndarray, np.ndarray] | None]:
        """Per row of ``values`` (SI parameter values, shape (k, P)), from ONE engine call: the engine's
        times (from one step before the motion) and each channel's quantity there (finite differences of
        the recorded displacement); None for a case that failed."""
        k = values.shape[0]
        overrides: dict[str, np.ndarray] = {"simulation.duration": np.full(k, self.duration)}
        for j, p in enumerate(self.params):
            for leaf in p.target.writes:
                overrides[leaf] = values[:, j]
        try:
            batch = build_batch([self.scene], overrides, n_cases=k)
        except ValueError:
            return [None] * k
        c = self.choice
        result = simulate(batch, c.fidelity, c.integrator, c.dt, auto_step=c.auto_step, record=list(range(k)))
        self.cases += k
        self.calls += 1
        h = result.history
        assert h is not None
        out: list[tuple[np.ndarray, np.ndarray] | None] = []
        for i in range(k):
            if STATUS_NAMES[int(result.status[i])] != "ok":
                out.append(None)
                continue
            n = int(h["n_samples"][i])
            t = np.asarray(h["time"][i, :n])
            cols = []
            for ch in self.meas.channels:
                a = AXIS_NAMES.index(ch.axis)
                if a >= 3:
                    cols.append(h["rotation"][i, :n, a - 3])
                elif ch.location == LOCATION_CG:
                    cols.append(h["displacement"][i, :n, a])
                else:
                    cols.append(h["point_displacement"][i, :n, self.points.index(ch.location), a])
            y = np.stack(cols, axis=1)
            if not np.all(np.isfinite(y)) or t.size < 3:
                out.append(None)
                continue
            dt = float(t[1] - t[0])
            # at rest before the motion: one sample of zeros at -dt, and the last sample held
            yp = np.concatenate([np.zeros((1, y.shape[1])), y, y[-1:]])
            q = np.empty((t.size + 1, y.shape[1]))
            q[0] = 0.0
            for kk, ch in enumerate(self.meas.channels):
                if ch.order == 0:
                    q[1:, kk] = y[:, kk]
                elif ch.order == 1:  # central difference: the mean velocity over +- dt
                    q[1:, kk] = (yp[2:, kk] - yp[:-2, kk]) / (2 * dt)
                else:  # second difference: the acceleration averaged over +- dt
                    q[1:, kk] = (yp[2:, kk] - 2 * yp[1:-1, kk] + yp[:-2, kk]) / dt**2
            out.append((np.concatenate([[-dt], t]), q))
        return out

    def sample(self, hist: tuple[np.ndarray, np.ndarray], offset: float) -> np.ndarray:
        """(N, ch) simulated channels at the measurement's times (interpolated linearly; zero before the
        motion starts), unfiltered."""
        tg, q = hist
        ts = self.t - offset
        out = np.empty((ts.size, q.shape[1]))
        for k in range(q.shape[1]):
            out[:, k] = np.interp(ts, tg, q[:, k], left=0.0, right=q[-1, k])
        return out

    def predict(self, hist: tuple[np.ndarray, np.ndarray], offset: float) -> np.ndarray:
        """(N, ch) simulated channels at the measurement's times, filtered like the measurement."""
        return self.filtered(self.sample(hist, offset))


def _noise_gain(sos: np.ndarray, n: int) -> float:
    """Variance of white noise of unit variance after the zero-phase filter ``sos`` (sum of the squared
    impulse response): the fraction of a filtered channel's samples that count as independent."""
    m = min(n, 20_000)
    x = np.zeros(m)
    x[m // 2] = 1.0
    return float(np.clip(np.sum(sosfiltfilt(sos, x) ** 2), 1e-6, 1.0))


# ------------------------------------------------------------------------------------------------ the fit
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


def _choice(scene: Scene, simulation: Mapping[str, Any] | None, prefix: Loc) -> _Choice:
    sim = scene.simulation
    data = {k: getattr(sim, k) for k in ("fidelity", "integrator", "dt", "auto_step")}
    for k, v in (simulation or {}).items():
        if k not in ("fidelity", "integrator", "dt", "auto_step"):
            raise DefinitionError(
                [
                    detail(
                        [*prefix, "simulation", k],
                        "a calibration chooses only fidelity, integrator, dt, auto_step",
                    )
                ]
            )
        data[k] = v
    if data["dt"] is not None:
        data["dt"] = to_si_loc(data["dt"], "time", [*prefix, "simulation", "dt"])
    fidelity = data["fidelity"] or "ltv"
    integrator = data["integrator"] or ("exact" if fidelity == "lti" else "rk4")
    dt = float(data["dt"] or 1e-3)
    if not (math.isfinite(dt) and dt > 0):
        raise DefinitionError([detail([*prefix, "simulation", "dt"], "must be a positive step in s")])
    from isolab.engine import check_choice

    try:
        check_choice(fidelity, integrator)
    except SceneError as err:
        raise DefinitionError([detail([*prefix, "simulation", err.field], err.reason)]) from None
    return _Choice(fidelity, integrator, dt, bool(data["auto_step"]))


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
    """Fit ``fit``'s parameters of ``scene`` (and the time offset) to ``measurement``.

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
    params = _parameters(sc, fit, pre)
    choice = _choice(sc, simulation, pre)
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
    model = _Model(sc, params, measurement, choice, (o_lo, o_hi), hp, lp, pre)
    return _fit(model, params, (o_lo, o_hi, off.get("start")), fixed_offset is not None, pre)


def to_si_loc(value: Any, dimension: str, loc: Loc) -> float:
    """:func:`~isolab.studies.units.to_si` raising DefinitionError at ``loc``."""
    try:
        return to_si(value, dimension, ".".join(str(x) for x in loc if x != "body"))
    except ValueError as err:
        raise DefinitionError([detail(loc, str(err))]) from None


def _fit(
    model: _Model, params: list[_Param], offset: tuple[float, float, Any], offset_fixed: bool, pre: Loc
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


# ------------------------------------------------------------------------------------- synthetic tests
def synthetic_measurement(
    scene: Mapping[str, Any] | Scene,
    channels: Sequence[tuple[str, str]],
    time: np.ndarray,
    offset: float = 0.0,
    noise: float = 0.0,
    bias: float = 0.0,
    drift: float = 0.0,
    seed: int = 0,
    simulation: Mapping[str, Any] | None = None,
) -> Measurement:
    """What sensors would record of ``scene``: each channel ``(name, unit)`` at ``time`` (s), the motion
    starting at ``offset`` on that clock, plus white noise of ``noise`` times the channel's RMS and, on
    acceleration channels, a bias (m/s^2 or rad/s^2) and a linear drift (per s). For tests and examples.
    """
    sc = scene if isinstance(scene, Scene) else validate_scene(dict(scene))
    t = np.asarray(time, dtype=np.float64)
    chans = [parse_channel(n, u, np.zeros(t.size), [n]) for n, u in channels]
    meas = Measurement(t, chans, "synthetic")
    model = _Model(
        sc, [], meas, _choice(sc, simulation, []), (offset, offset), 0.0, 0.0, [], check_signal=False
    )
    hist = model.histories(np.zeros((1, 0)))[0]
    if hist is None:
        raise ValueError("the scene does not simulate")
    clean = model.sample(hist, offset)
    rng = np.random.default_rng(seed)
    for k, ch in enumerate(chans):
        v = clean[:, k] + noise * float(np.sqrt(np.mean(clean[:, k] ** 2))) * rng.standard_normal(t.size)
        if ch.order == 2:
            v = v + bias + drift * (t - t[0])
        ch.values = v
    return meas


# ------------------------------------------------------------------------------------------- requests
def request_measurement(data: Mapping[str, Any], prefix: Loc | None = None) -> Measurement:
    """The measurement of a request: ``{"csv": text}`` or ``{"time": [...], "time_unit": "s",
    "channels": [{"name", "unit", "values"}]}``."""
    pre: Loc = ["body", "measurement"] if prefix is None else list(prefix)
    if data.get("csv") is not None:
        if data.get("time") is not None or data.get("channels") is not None:
            raise DefinitionError([detail(pre, "give csv, or time and channels, not both")])
        return measurement_from_csv(str(data["csv"]), pre, source="the request's CSV")
    if data.get("time") is None or data.get("channels") is None:
        raise DefinitionError([detail(pre, "give csv (text), or time and channels (columns)")])
    return measurement_from_columns(data["time"], data["channels"], str(data.get("time_unit") or "s"), pre)


def calibrate_request(body: Mapping[str, Any]) -> Calibration:
    """:func:`calibrate` of a request body (``scene``, ``measurement``, ``fit``, and optionally
    ``offset``, ``simulation``, ``highpass``, ``lowpass``), errors located under ``body``."""
    meas = request_measurement(dict(body.get("measurement") or {}))
    fit = [{k: v for k, v in dict(f).items() if v is not None} for f in body.get("fit") or []]
    return calibrate(
        dict(body.get("scene") or {}),
        meas,
        fit,
        offset={k: v for k, v in dict(body.get("offset") or {}).items() if v is not None} or None,
        simulation=body.get("simulation"),
        highpass=body.get("highpass"),
        lowpass=body.get("lowpass"),
    )
