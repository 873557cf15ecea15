"""Measured motion for a calibration: channels, their units and the files and requests they come from.

A measurement is a time column plus channels. Each channel names where it measures (``cg`` or a point of
interest of the scene), an axis (``x``, ``y``, ``z`` or the rotations ``rx``, ``ry``, ``rz``), a quantity
(``displacement``, ``velocity`` or ``acceleration``) and its units, written as a column header::

    time [s], cg.z.displacement [mm], tool.y.acceleration [g], cg.rx.velocity [mrad/s]

:func:`read_measurement` reads CSV or netCDF files, :func:`measurement_from_csv` CSV text and
:func:`measurement_from_columns` JSON-like columns; values are held in SI (m, m/s, m/s^2; rad, rad/s,
rad/s^2) and times in s. :func:`measurement_csv` writes a measurement back as CSV.
"""

from __future__ import annotations

import io
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from isolab.studies.inputs.definitions import DefinitionError, Loc, detail
from isolab.studies.units import to_si

LOCATION_CG = "cg"
"""The location name of the scene's centre of gravity (any other location is a point of the scene)."""
AXIS_NAMES = ("x", "y", "z", "rx", "ry", "rz")
"""Axes a channel may measure along: translations, then rotations about x, y and z."""
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
"""Names the time column of a CSV measurement may have."""

MAX_CHANNELS = 16
"""Most channels of one measurement."""
MAX_SAMPLES = 200_000
"""Most samples of one measurement (per channel)."""
MIN_SAMPLES = 16
"""Fewest samples of one measurement (per channel)."""

_HEADER = re.compile(r"^\s*(?P<name>[^\[\(]*?)\s*(?:[\[\(](?P<unit>[^\]\)]*)[\]\)])?\s*$")


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
                    f"channel {name!r}: values[{int(np.flatnonzero(bad)[0])}] is not a finite number",
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
        raise DefinitionError(
            [detail([*prefix, "time"], f"times must increase: time[{i}] is not after time[{i - 1}]")]
        )
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
    loc = [*pre, "csv"]
    numbered = [
        (n, ln)
        for n, ln in enumerate(text.splitlines(), start=1)
        if ln.strip() and not ln.lstrip().startswith("#")
    ]
    if len(numbered) < 2:
        raise DefinitionError([detail(loc, "a header row and at least one row of samples")])
    head_line, head = numbered[0]
    sep = next((s for s in (",", ";", "\t") if s in head), ",")
    header = [h.strip() for h in head.split(sep)]
    if len(header) < 2:
        raise DefinitionError([detail(loc, "the header names time and at least one channel")])
    rows = numbered[1:]
    try:
        data = np.loadtxt(
            io.StringIO("\n".join(ln for _, ln in rows)), delimiter=sep, ndmin=2, dtype=np.float64
        )
        readable = data.shape[1] == len(header)
    except ValueError:
        readable = False
    if not readable:
        raise DefinitionError([detail(loc, _csv_problem(rows, header, sep, head_line))])
    bad = ~np.isfinite(data)
    if bad.any():
        r, c = (int(v) for v in np.argwhere(bad)[0])
        cell = rows[r][1].split(sep)[c].strip()
        raise DefinitionError(
            [detail(loc, f"line {rows[r][0]}, column {header[c]!r}: {cell!r} is not a finite number")]
        )
    tname, tunit = parse_header(header[0], loc)
    if tname.lower() not in TIME_NAMES:
        raise DefinitionError([detail(loc, f"the first column must be time, got {tname!r}")])
    t = _time_values(data[:, 0], tunit or "s", loc)
    back = np.flatnonzero(np.diff(t) <= 0)
    if back.size:
        r = int(back[0]) + 1
        raise DefinitionError(
            [
                detail(
                    loc,
                    f"line {rows[r][0]}, column {header[0]!r}: times must increase, and "
                    f"{rows[r][1].split(sep)[0].strip()} does not follow "
                    f"{rows[r - 1][1].split(sep)[0].strip()} (line {rows[r - 1][0]})",
                )
            ]
        )
    channels = []
    for i, h in enumerate(header[1:], start=1):
        name, unit = parse_header(h, loc)
        channels.append(parse_channel(name, unit, data[:, i], loc))
    return _check_measurement(Measurement(t, channels, source), loc)


def _csv_problem(rows: Sequence[tuple[int, str]], header: list[str], sep: str, head_line: int) -> str:
    """Why the CSV's samples cannot be read, at the first line and column that fails, in a user's words
    (lines counted from 1 as a text editor shows them)."""
    for line, text in rows:
        cells = [c.strip() for c in text.split(sep)]
        if len(cells) != len(header):
            return (
                f"line {line} has {len(cells)} value{'' if len(cells) == 1 else 's'}, but the header "
                f"(line {head_line}) names {len(header)} columns ({', '.join(header)})"
            )
        for name, cell in zip(header, cells, strict=True):
            try:
                float(cell)
            except ValueError:
                why = "it is empty" if not cell else f"{cell!r} is not a number"
                return f"line {line}, column {name!r}: {why}"
    return "cannot read the samples as numbers"


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


def stated_noise(m: Measurement, noise: Mapping[str, Any] | None, prefix: Loc) -> np.ndarray:
    """(ch,) each channel's stated sensor noise (standard deviation of one sample) in SI, NaN where
    ``noise`` (channel name -> a number in the channel's unit, or text with units) does not name it.

    Raises:
        DefinitionError: an unknown channel, or a noise that is not a positive finite quantity of the
            channel's kind, at ``prefix + ["noise", name]``.
    """
    out = np.full(len(m.channels), np.nan)
    if noise is None:
        return out
    if not isinstance(noise, Mapping):
        raise DefinitionError([detail([*prefix, "noise"], "a mapping of channel name -> its noise")])
    index = {c.name: k for k, c in enumerate(m.channels)}
    for name, value in noise.items():
        loc = [*prefix, "noise", name]
        key = str(name).strip()
        if key not in index:
            raise DefinitionError(
                [detail(loc, f"no channel {key!r} in the measurement ({', '.join(index)})")]
            )
        c = m.channels[index[key]]
        if isinstance(value, bool) or not isinstance(value, int | float | str):
            raise DefinitionError([detail(loc, "must be a number in the channel's unit, or text with units")])
        if isinstance(value, str):
            amount, _, unit = value.strip().partition(" ")
            try:
                number = float(amount)
            except ValueError:
                raise DefinitionError(
                    [detail(loc, f"{value!r}: write a number and a unit, e.g. '0.01 mm'")]
                ) from None
            factor = _unit_factor(unit.strip(), c.quantity, c.rotational, loc) if unit.strip() else c.factor
        else:
            number, factor = float(value), c.factor
        si = number * factor
        if not (np.isfinite(si) and si > 0):
            raise DefinitionError([detail(loc, f"must be a positive noise, got {value!r}")])
        out[index[key]] = si
    return out
