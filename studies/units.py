"""Numbers as engineers write them: ``"2 g"``, ``"3.5 Hz"``, ``"1.2e6 N/m"``, ``"800 mm"``, ``"5 %"``.

Every quantity of a study is stored in SI (m, kg, s, N, rad). A value may be given as a plain number (taken
as SI as is) or as a string with units, parsed by one shared :mod:`pint` registry and converted to the SI
unit of the dimension the field expects. Where an acceleration (or a jerk) is expected, ``g`` and ``gn``
mean standard gravity, 9.80665 m/s^2 (to pint, ``g`` is the gram). Frequencies are cycles per second:
an angular frequency (``"20 rad/s"``) is converted to Hz by dividing by 2 pi. A damping ratio or any
dimensionless number accepts percent (``"5 %"`` is 0.05).

The ``Annotated`` types at the end (``Length``, ``Mass``, ...) let pydantic fields accept both forms.
"""

from __future__ import annotations

import functools
import math
import re
import sys
from dataclasses import dataclass
from typing import Annotated, Any

import numpy as np
from pydantic import BeforeValidator, GetJsonSchemaHandler, ValidationInfo


@functools.cache
def unit_registry() -> Any:
    """The one :mod:`pint` unit registry of the product (quantities of two registries do not mix), built on
    first use: importing pint and building a registry take most of a second, and the units of
    :data:`COMMON_UNITS` are read without it."""
    import pint

    return pint.UnitRegistry()


STANDARD_GRAVITY = 9.80665
"""Standard gravity, m/s^2."""

# dimension -> (SI unit written for people, pint dimensionality, example)
DIMENSIONS: dict[str, tuple[str, str, str]] = {
    "length": ("m", "[length]", "800 mm"),
    "mass": ("kg", "[mass]", "1000 kg"),
    "time": ("s", "[time]", "200 ms"),
    "velocity": ("m/s", "[length]/[time]", "2 m/s"),
    "acceleration": ("m/s^2", "[length]/[time]**2", "2 g"),
    "jerk": ("m/s^3", "[length]/[time]**3", "200 m/s^3"),
    "frequency": ("Hz", "1/[time]", "3.5 Hz"),
    "stiffness": ("N/m", "[mass]/[time]**2", "1.2e6 N/m"),
    "damping": ("N s/m", "[mass]/[time]", "2e4 N s/m"),
    "density": ("kg/m^3", "[mass]/[length]**3", "2700 kg/m^3"),
    "inertia": ("kg m^2", "[mass]*[length]**2", "1e4 kg m^2"),
    "force": ("N", "[mass]*[length]/[time]**2", "2 kN"),
    "area": ("m^2", "[length]**2", "300 cm^2"),
    "pressure": ("Pa", "[mass]/[length]/[time]**2", "6 bar"),
    "displacement_psd": ("m^2/Hz", "[length]**2*[time]", "1e-12 m^2/Hz"),
    "velocity_psd": ("m^2/s^2/Hz", "[length]**2/[time]", "1e-10 m^2/s^2/Hz"),
    "angle": ("rad", "", "3 mrad"),
    "dimensionless": ("", "", "5 %"),
    "volume": ("m^3", "[length]**3", "20 l"),
    "viscosity": ("Pa s", "[mass]/[length]/[time]", "18 uPa s"),
}

MAX_QUANTITY_CHARS = 256
"""Longest text accepted where a value is expected (``"1.2e6 N/m"``: a few characters)."""
MAX_EXPONENT = 12.0
"""Largest power (in magnitude) a quantity's text may raise a number or unit to."""
MAX_POWERS = 4
"""Most power operators in one quantity's text (``"kg m^2 s^-2"`` has two)."""

_POWER = re.compile(r"\*\*|\^")
_EXPONENT = re.compile(r"\s*[-+]?\s*(\d+(?:\.\d*)?|\.\d+)(?:[eE][-+]?\d+)?")
_BASE_END = re.compile(r"[A-Za-z0-9_.%µ]\s*$")
_WORD_AND_DIGIT = re.compile(r"[A-Za-z_]+[0-9]")
"""A word and one digit (``rk4``, the integrator): no number in it."""


@functools.cache
def _pint_dimensionality(dimension: str) -> Any:
    return unit_registry().get_dimensionality(DIMENSIONS[dimension][1])


COMMON_UNITS: dict[tuple[str, str], float] = {
    ("m", "length"): 1.0,
    ("mm", "length"): 0.001,
    ("um", "length"): 1e-06,
    ("µm", "length"): 1e-06,
    ("cm", "length"): 0.01,
    ("kg", "mass"): 1.0,
    ("t", "mass"): 1000.0,
    ("s", "time"): 1.0,
    ("ms", "time"): 0.001,
    ("m/s", "velocity"): 1.0,
    ("mm/s", "velocity"): 0.001,
    ("um/s", "velocity"): 1e-06,
    ("m/s^2", "acceleration"): 1.0,
    ("mm/s^2", "acceleration"): 0.001,
    ("g", "acceleration"): 9.80665,
    ("gn", "acceleration"): 9.80665,
    ("m/s^3", "jerk"): 1.0,
    ("Hz", "frequency"): 1.0,
    ("kHz", "frequency"): 1000.0,
    ("N/m", "stiffness"): 1.0,
    ("kN/m", "stiffness"): 1000.0,
    ("MN/m", "stiffness"): 1000000.0,
    ("N/mm", "stiffness"): 1000.0,
    ("N s/m", "damping"): 1.0,
    ("kN s/m", "damping"): 1000.0,
    ("kg/m^3", "density"): 1.0,
    ("kg m^2", "inertia"): 1.0,
    ("N", "force"): 1.0,
    ("kN", "force"): 1000.0,
    ("m^2/Hz", "displacement_psd"): 1.0,
    ("m^2/s^2/Hz", "velocity_psd"): 1.0,
    ("rad", "angle"): 1.0,
    ("mrad", "angle"): 0.001,
    ("urad", "angle"): 1e-06,
    ("%", "dimensionless"): 0.01,
}
"""What one of the units engineers write most is in the SI unit of its dimension: exactly the float the
units parser gives (a test holds each to it), so ``"<number> <unit>"`` of these reads without the parser."""
_COMMON_UNIT_NAMES = frozenset(unit for unit, _ in COMMON_UNITS)

# "<number> <unit>" with a plain decimal number and a unit made of names, powers and / or *: read as the
# number times the unit's factor, the factor parsed once per unit (:func:`_unit_factor`). A list of a
# hundred thousand "2.5 m/s^2" then costs microseconds a value, not a units-parser run each.
_UNIT_NAME = r"[A-Za-z_%\u00b5\u03bc\u00b0][A-Za-z_0-9\u00b5\u03bc\u00b0]*(?:\s*(?:\*\*|\^)\s*-?\d+)?"
_SIMPLE_QUANTITY = re.compile(
    r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)(?:\s+|(?![eE]))"
    rf"({_UNIT_NAME}(?:\s*[/*]\s*{_UNIT_NAME}|\s+{_UNIT_NAME})*)\s*"
)


def _simple_quantity(text: str) -> tuple[float, str] | None:
    """(number, unit text) of ``"<number> <unit>"`` text with a finite number, else None."""
    m = _SIMPLE_QUANTITY.fullmatch(text)
    if m is None:
        return None
    number = float(m.group(1))
    return (number, m.group(2)) if math.isfinite(number) else None


def _unit_factor(unit: str, dimension: str) -> float | None:
    """:func:`parsed_unit_factor`, from :data:`COMMON_UNITS` where the unit is there."""
    common = COMMON_UNITS.get((unit, dimension))
    return common if common is not None else parsed_unit_factor(unit, dimension)


@functools.lru_cache(maxsize=4096)
def parsed_unit_factor(unit: str, dimension: str) -> float | None:
    """What one ``unit`` is in the SI unit of ``dimension`` (read by the full :func:`to_si`), or None when
    the unit is not of that dimension, not readable, not a plain multiple (a logarithmic unit) or an
    angular frequency: such text takes the full path, which names the problem (and gives the same float
    to the last bit: ``number * factor`` is what the units parser computes)."""
    try:
        one = _to_si(f"1 {unit}", dimension, "unit", fast=False)
        two = _to_si(f"2 {unit}", dimension, "unit", fast=False)
    except ValueError:
        return None
    if dimension == "frequency" and _unit_scale(unit) != one:
        return None  # an angular frequency (rad/s, rpm): the full path divides by 2 pi after converting
    return one if one != 0.0 and math.isfinite(one) and two == 2.0 * one else None


_GRAVITY_TOKEN = re.compile(r"(?<![A-Za-z_])(gn|g)(?![A-Za-z_0-9])")


def dimension_of(unit: str) -> str | None:
    """The dimension whose SI unit is ``unit`` (``"m/s^2"`` -> ``"acceleration"``; ``"1"`` or ``""`` ->
    ``"dimensionless"``), or None for a unit no dimension of :data:`DIMENSIONS` has (``"kg/s^3"``)."""
    if unit in ("", "1"):
        return "dimensionless"
    return next((name for name, spec in DIMENSIONS.items() if spec[0] == unit), None)


def si_unit(dimension: str) -> str:
    """The SI unit string of ``dimension`` ("" for dimensionless)."""
    _check_dimension(dimension)
    return DIMENSIONS[dimension][0]


def _check_dimension(dimension: str) -> None:
    if dimension not in DIMENSIONS:
        raise ValueError(f"unknown dimension {dimension!r}; known: {', '.join(DIMENSIONS)}")


def _finite(x: float, field: str, value: Any) -> float:
    if not math.isfinite(x):
        raise ValueError(f"{field}: must be a finite number, got {value!r}")
    return x


def quantity_text_problem(text: str) -> str | None:
    """Why the quantity text ``text`` is refused before the units parser reads it, or None.

    The parser computes integer powers exactly, so ``"9**9**9 kg"`` would run for hours. Refused: more than
    :data:`MAX_QUANTITY_CHARS` characters; more than :data:`MAX_POWERS` power operators (``**`` or ``^``);
    a power whose exponent is not a plain number of at most :data:`MAX_EXPONENT` in magnitude, is raised
    again (``9**9**9``) or applies to a bracket.
    """
    if len(text) > MAX_QUANTITY_CHARS:
        return f"longer than {MAX_QUANTITY_CHARS} characters"
    powers = list(_POWER.finditer(text))
    if not powers:
        return None
    if len(powers) > MAX_POWERS:
        return f"more than {MAX_POWERS} powers (** or ^)"
    for op in powers:
        if not _BASE_END.search(text[: op.start()]):
            return "a power must follow a number or a unit, not a bracket or an operator"
        exponent = _EXPONENT.match(text, op.end())
        if exponent is None:
            return "an exponent must be a plain number (such as m/s^2 or 10**6)"
        value = float(exponent.group(0).replace(" ", ""))
        if abs(value) > MAX_EXPONENT:
            return f"exponent {exponent.group(0).strip()} is larger than {MAX_EXPONENT:g} in magnitude"
        if _POWER.match(text[exponent.end() :].lstrip()):
            return "a power cannot be raised to a power again"
    return None


def quantity_problem(text: str) -> str | None:
    """Why the quantity text ``text`` is refused, or None when it is safe to hand to the units parser: the
    rules of :func:`quantity_text_problem`, and a value no 64-bit float holds (``10**999``)."""
    if len(text) <= MAX_QUANTITY_CHARS:
        simple = _simple_quantity(text)
        if simple is not None and abs(simple[0]) < 1e200:  # the unit decides, once per unit
            return _unit_problem(simple[1])
    return quantity_text_problem(text) or _magnitude_problem(text)


def _unit_problem(unit: str) -> str | None:
    """:func:`parsed_unit_problem`; None for a unit of :data:`COMMON_UNITS`."""
    return None if unit in _COMMON_UNIT_NAMES else parsed_unit_problem(unit)


@functools.lru_cache(maxsize=4096)
def parsed_unit_problem(unit: str) -> str | None:
    """:func:`quantity_problem` of ``"<number> <unit>"`` with a moderate number: only the unit's powers and
    size can make it hostile, so the answer is that of ``"1 <unit>"`` (numbers beyond 1e200 aside)."""
    return quantity_text_problem(f"1 {unit}") or _magnitude_problem(f"1e200 {unit}")


def _magnitude_problem(text: str) -> str | None:
    """The units parser's reading of a screened text: None unless its number overflows a float. Read
    without building the parser (about half a second in a fresh process): a text without a digit, a word
    such as ``air``, and a word and one digit, such as ``rk4`` (:data:`_WORD_AND_DIGIT`), hold no number
    (the parser reads the second as a unit it does not know, ``km2`` too; validation names the field)."""
    if not any(ch.isdigit() for ch in text) or _WORD_AND_DIGIT.fullmatch(text):
        return None
    try:
        q = unit_registry().Quantity(text)
        magnitude = q.magnitude if hasattr(q, "magnitude") else q
        float(np.asarray(magnitude, dtype=float))
        if hasattr(q, "to_base_units"):
            float(np.asarray(q.to_base_units().magnitude, dtype=float))
    except OverflowError:
        return "the number is too large for a 64-bit float"
    except Exception:  # unreadable text: validation names the field and the reason
        return None
    return None


@functools.lru_cache(maxsize=4096)
def _unit_scale(unit: str) -> float:
    """|one ``unit``| in base units, as the units parser reads it (inf when it cannot)."""
    try:
        return abs(float(unit_registry().Quantity(f"1 {unit}").to_base_units().magnitude))
    except Exception:  # unreadable or not a plain multiple: the full check decides
        return math.inf


def _describe(dimension: str) -> str:
    unit, _, example = DIMENSIONS[dimension]
    what = "a dimensionless number" if dimension == "dimensionless" else dimension
    if what == dimension:
        what = ("an " if dimension[0] in "aeiou" else "a ") + dimension
    return what + (f" in {unit}" if unit else "") + f" (a number in SI or a string such as {example!r})"


def to_si(value: Any, dimension: str, field: str) -> float:
    """``value`` in the SI unit of ``dimension``, as a float.

    Args:
        value: a number (SI as is), a numeric string, a string with units (``"2 g"``) or a pint quantity.
        dimension: one of :data:`DIMENSIONS` (length, mass, time, velocity, acceleration, jerk, frequency,
            stiffness, damping, density, inertia, force, angle, dimensionless).
        field: the name of the input, used in error messages.

    Raises:
        ValueError: naming ``field`` and the reason, for a wrong dimension, text that is not a quantity,
            NaN or infinity, or a value of another type (booleans included).
    """
    return _to_si(value, dimension, field, fast=True)


def _to_si(value: Any, dimension: str, field: str, fast: bool) -> float:
    """:func:`to_si`; ``fast`` reads ``"<number> <unit>"`` text through the unit's cached factor."""
    _check_dimension(dimension)
    if isinstance(value, bool | np.bool_):
        raise ValueError(f"{field}: expected {_describe(dimension)}, got the boolean {value!r}")
    if isinstance(value, int | float | np.integer | np.floating):
        return _finite(float(value), field, value)
    if isinstance(value, str):
        text = value.strip()
        if not text:
            raise ValueError(f"{field}: expected {_describe(dimension)}, got an empty string")
        simple = _simple_quantity(text) if fast else None
        if simple is not None:
            factor = _unit_factor(simple[1], dimension)
            if factor is not None and math.isfinite(simple[0] * factor):
                return simple[0] * factor
        try:
            plain = float(text)
        except ValueError:
            plain = None
        if plain is not None:
            return _finite(plain, field, value)
        problem = quantity_text_problem(text)
        if problem is not None:
            raise ValueError(f"{field}: cannot read {value!r} as {_describe(dimension)}: {problem}")
        if dimension in ("acceleration", "jerk"):
            text = _GRAVITY_TOKEN.sub("standard_gravity", text)
        try:
            q = unit_registry().Quantity(text)
        except Exception as err:  # pint raises many kinds of errors on text it cannot read
            raise ValueError(f"{field}: cannot read {value!r} as {_describe(dimension)}: {err}") from None
    elif _is_quantity(value):
        q = value
    else:
        raise ValueError(f"{field}: expected {_describe(dimension)}, got {type(value).__name__} {value!r}")
    try:
        if not _is_quantity(q):  # a bare number such as "2*3"
            return _finite(float(q), field, value)
        magnitude = float(np.asarray(q.magnitude, dtype=float))
        _finite(magnitude, field, value)
        base = q.to_base_units()
        float(np.asarray(base.magnitude, dtype=float))
    except OverflowError:
        raise ValueError(f"{field}: {value!r} is too large for a 64-bit float") from None
    except (TypeError, ValueError) as err:
        if str(err).startswith(f"{field}:"):
            raise
        raise ValueError(f"{field}: {value!r} is not a single number") from None
    angle_power = dict(base.unit_items()).get("radian", 0)
    expected = _pint_dimensionality(dimension)
    if q.dimensionality != expected:
        raise ValueError(
            f"{field}: expected {_describe(dimension)}, got {value!r} which is "
            f"{q.dimensionality or 'dimensionless'}"
        )
    x = float(base.magnitude)
    if dimension == "angle":
        if angle_power not in (0, 1):
            raise ValueError(f"{field}: expected {_describe(dimension)}, got {value!r}")
    elif dimension == "frequency" and angle_power == 1:
        x /= 2.0 * math.pi  # angular frequency (rad/s, rpm) to cycles per second
    elif angle_power != 0:
        raise ValueError(f"{field}: expected {_describe(dimension)}, got the angle-bearing {value!r}")
    return _finite(x, field, value)


def _is_quantity(value: Any) -> bool:
    """Whether ``value`` is a pint quantity (never, while pint is not imported)."""
    pint = sys.modules.get("pint")
    return pint is not None and isinstance(value, pint.Quantity)


def _validator(dimension: str):
    def parse(value: Any, info: ValidationInfo) -> Any:
        if value is None:
            return value  # optional fields: pydantic decides whether None is allowed
        return to_si(value, dimension, info.field_name or dimension)

    return BeforeValidator(parse)


_NUMERIC_BOUNDS = {
    "gt": "exclusiveMinimum",
    "ge": "minimum",
    "lt": "exclusiveMaximum",
    "le": "maximum",
    "exclusiveMinimum": "exclusiveMinimum",
    "minimum": "minimum",
    "exclusiveMaximum": "exclusiveMaximum",
    "maximum": "maximum",
}


@dataclass(frozen=True)
class QuantityJsonSchema:
    """The JSON schema of a quantity of ``dimension``: a number (SI) or a string with units.

    Besides ``anyOf`` number/string and a description, it carries ``x-dimension`` and ``x-unit`` (the SI
    unit numbers are read in), and the numeric bounds of the field (``Field(gt=...)`` and the like) as
    JSON Schema's ``exclusiveMinimum``/``minimum``/... at its top level, where they apply to numbers
    only (a string is converted, then checked, by the validator)."""

    dimension: str

    def __get_pydantic_json_schema__(self, core_schema: Any, handler: GetJsonSchemaHandler) -> dict[str, Any]:
        unit, _, example = DIMENSIONS[self.dimension]
        number = handler(core_schema)  # the float's schema with its constraints: {"type": "number", "gt": 0}
        out: dict[str, Any] = {
            "anyOf": [{"type": "number"}, {"type": "string"}],
            "description": f"{self.dimension}: a number in SI ({unit or 'dimensionless'}) or a string with "
            f"units, e.g. {example!r}",
            "x-dimension": self.dimension,
            "x-unit": unit,
        }
        for key, value in number.items():
            if key in _NUMERIC_BOUNDS:
                out[_NUMERIC_BOUNDS[key]] = value
        return out


def _json_schema(dimension: str) -> QuantityJsonSchema:
    return QuantityJsonSchema(dimension)


def _quantity(dimension: str):
    return Annotated[float, _validator(dimension), _json_schema(dimension)]


Length = _quantity("length")
Mass = _quantity("mass")
Time = _quantity("time")
Velocity = _quantity("velocity")
Acceleration = _quantity("acceleration")
Jerk = _quantity("jerk")
Frequency = _quantity("frequency")
Stiffness = _quantity("stiffness")
Damping = _quantity("damping")
Density = _quantity("density")
Inertia = _quantity("inertia")
Angle = _quantity("angle")
Dimensionless = _quantity("dimensionless")
Force = _quantity("force")
Area = _quantity("area")
Pressure = _quantity("pressure")
DisplacementPSD = _quantity("displacement_psd")
VelocityPSD = _quantity("velocity_psd")
Volume = _quantity("volume")
Viscosity = _quantity("viscosity")


# ------------------------------------------------------------------------------ units for people to read
def unit_value(unit: str, dimension: str) -> float | None:
    """What one ``unit`` is in the SI unit of ``dimension`` (``"g"``, acceleration -> 9.80665; ``"%"``,
    dimensionless -> 0.01; ``"rad/s"``, frequency -> 1/(2 pi) Hz), or None when ``unit`` is not a
    readable, positive multiple of that dimension. The SI unit itself (and ``""``/``"1"`` for a
    dimensionless number) is 1."""
    if dimension not in DIMENSIONS:
        return None
    if unit == DIMENSIONS[dimension][0] or (dimension == "dimensionless" and unit in ("", "1")):
        return 1.0
    try:
        one = to_si(f"1 {unit}", dimension, "unit")
    except ValueError:
        return None
    return one if math.isfinite(one) and one > 0.0 else None


def written_unit(value: Any, dimension: str) -> str | None:
    """The unit a quantity was written in (``"0.5 g"`` -> ``"g"``, ``"5 %"`` -> ``"%"``, ``"20 kN/m"`` ->
    ``"kN/m"``), or None for a plain number (SI) or text that is not ``<number> <unit>`` with a unit of
    ``dimension``."""
    if not isinstance(value, str):
        return None
    simple = _simple_quantity(value.strip())
    if simple is None:
        return None
    unit = " ".join(simple[1].split())
    return unit if unit_value(unit, dimension) is not None else None


# SI unit -> (smallest magnitude of the values, unit they are then shown in, its value in SI), largest first
_READABLE: dict[str, tuple[tuple[float, str, float], ...]] = {
    "m": ((1.0, "m", 1.0), (1e-3, "mm", 1e-3), (0.0, "um", 1e-6)),
    "rad": ((1.0, "rad", 1.0), (1e-3, "mrad", 1e-3), (0.0, "urad", 1e-6)),
    "N": ((1e6, "MN", 1e6), (1e3, "kN", 1e3), (0.0, "N", 1.0)),
    "m/s": ((1.0, "m/s", 1.0), (1e-3, "mm/s", 1e-3), (0.0, "um/s", 1e-6)),
}


def readable_unit(si: str, values: Any) -> tuple[str, float]:
    """The unit to show values in SI unit ``si`` in, chosen by their largest magnitude, and its value in
    SI (shown = SI value / that): lengths in m, mm or um; angles in rad, mrad or urad; forces in N, kN or
    MN; velocities in m/s, mm/s or um/s; SI when every value is zero or missing. Other units stay SI (``"1"``
    and ``""`` shown as ``""``)."""
    if si not in _READABLE:
        return ("" if si in ("", "1") else si), 1.0
    a = np.abs(np.asarray(values, dtype=np.float64))
    a = a[np.isfinite(a)]
    top = float(a.max()) if a.size else 0.0
    if top == 0.0:  # nothing to size by (all zero or missing): SI
        return si, 1.0
    for least, unit, value in _READABLE[si]:
        if top >= least:
            return unit, value
    return si, 1.0


def shown_in(values: Any, si: str, unit: str) -> tuple[np.ndarray, str]:
    """``values`` in SI unit ``si`` converted to ``unit`` (a unit of the same dimension, e.g. ``"g"`` for
    m/s^2), and the unit they are then in: ``si`` itself when ``unit`` is empty or not of that dimension."""
    v = np.asarray(values, dtype=np.float64)
    dimension = dimension_of(si)
    one = unit_value(unit, dimension) if unit and dimension is not None else None
    if one is None:
        return v, si
    return v / one, unit
