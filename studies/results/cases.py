"""The case table of a stored study, and the small language that filters and sorts it.

:func:`case_table` flattens a study dataset to one row per case: the varied parameters, then the outputs
as columns (``peak_displacement_y``, ``min_isolator_load_min``, ``liftoff_any``, ``natural_frequency_1``
...), each with its SI unit. :func:`parse_filter` reads the filter language (parsed here, never evaluated
as Python):

    filter  := clause ("," clause)*            commas mean AND
    clause  := column op value
    op      := "<" | "<=" | ">" | ">=" | "==" | "!="
    value   := number [unit] | true | false | null | 'text' | "text" | bare-word

Numbers are SI unless a unit follows (``peak_displacement_y<5 mm``). A missing value (a case that did not
compute) matches only ``==null``. Text and yes/no columns take only ``==`` and ``!=``. A number must be
finite: ``inf``, ``nan`` and literals beyond a 64-bit float (``1e999``, ``1e308 km``) are refused. Every
mistake is a :class:`CaseQueryError` naming the query parameter.
"""

from __future__ import annotations

import csv
import io
import itertools
import math
import re
import threading
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from isolab.engine.results import ISOLATOR, OUTPUTS, OutputSpec
from isolab.studies.results.netcdf_locks import NETCDF_LOCK
from isolab.studies.results.store import Store
from isolab.studies.units import dimension_of, quantity_problem, to_si

if TYPE_CHECKING:  # xarray and netCDF4 load with the first dataset read
    import xarray as xr

MAX_CASE_ROWS = 100_000
"""Most rows one page of the case table holds."""
MAX_CASE_CELLS = 5_000_000
"""Most values (rows x columns) one page of the case table holds."""
MAX_FILTER_CLAUSES = 64
"""Most clauses of one filter."""


@dataclass
class CaseColumns:
    """A study's cases as columns: one array of ``n_cases`` values per column.

    Attributes:
        names: every column, in display order.
        data: column -> (n_cases,) array (float64 for numbers and yes/no with NaN missing; str for text).
        units: column -> SI unit ("1" dimensionless, "" text).
        kinds: column -> "number", "bool" or "text".
        parameters: the varied parameters (columns too).
        default: the columns shown when none are asked for.
        design_kind: "grid" or "sampled".
        display_units: numeric parameter -> the unit the study was written in (``"g"``, ``"%"``; its SI
            unit when written as plain numbers), from the coordinate's ``display_units``.
        scales: numeric parameter -> "linear" or "log", from the coordinate's ``scale``.
        long_names: column -> what it holds (the dataset variable's ``long_name`` and the column's label),
            for the columns that come from a dataset variable.
        outputs: column -> the output of the catalogue (:data:`isolab.engine.results.OUTPUTS`) it shows.
    """

    names: list[str] = field(default_factory=list)
    data: dict[str, np.ndarray] = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)
    kinds: dict[str, str] = field(default_factory=dict)
    parameters: list[str] = field(default_factory=list)
    default: list[str] = field(default_factory=list)
    design_kind: str = "grid"
    display_units: dict[str, str] = field(default_factory=dict)
    scales: dict[str, str] = field(default_factory=dict)
    long_names: dict[str, str] = field(default_factory=dict)
    outputs: dict[str, str] = field(default_factory=dict)

    @property
    def n_cases(self) -> int:
        return int(len(self.data["case"])) if "case" in self.data else 0

    def add(self, name: str, values: np.ndarray, unit: str, kind: str, default: bool) -> None:
        if name in self.data:
            return
        self.names.append(name)
        self.data[name] = values
        self.units[name] = unit
        self.kinds[name] = kind
        if default:
            self.default.append(name)


EACH = ""
"""A summary column per component of an output (every label of its dimensions)."""
SUMMARY: tuple[tuple[str, str], ...] = (
    ("peak_displacement", EACH),
    ("peak_rotation", EACH),
    ("peak_isolator_force", ISOLATOR),
    ("min_isolator_load", ISOLATOR),
    ("max_isolator_load", ISOLATOR),
    ("peak_isolator_deflection", ISOLATOR),
    ("liftoff", ISOLATOR),
    ("settling_time", EACH),
    ("settled", EACH),
    ("natural_frequency", EACH),
    ("peak_point_displacement", EACH),
    ("point_settling_time", EACH),
    ("move_time", EACH),
    ("point_ready_time", EACH),
    ("floor_point_velocity", "axis"),
)
"""The outputs the case table shows by default, in order, and how: each component (:data:`EACH`), or the
worst over a dimension (as the catalogue judges the output: ``peak_isolator_force_z`` the largest over the
isolators; ``min_isolator_load_min``, ``liftoff_any`` when no dimension is left)."""
DETAIL: tuple[tuple[str, ...], ...] = (
    ("damping_ratio",),
    ("peak_isolator_force",),
    ("peak_isolator_deflection",),
    ("min_isolator_load",),
    ("max_isolator_load",),
    ("static_isolator_load",),
    ("liftoff",),
    ("rms_displacement",),
    ("final_displacement",),
    ("final_rotation",),
    ("transmissibility",),
    ("floor_point_velocity", "floor_point_velocity_band"),
)
"""The outputs whose every component is a column asked for by name, in order (outputs of the same dimensions
grouped in a tuple alternate, component by component); any other output of the catalogue follows, the
settings (the step ``dt``) last."""
NOT_TABULATED = frozenset({"mode_energy", "mechanism"})
"""Outputs of the dataset the case table leaves out (per mode and degree of freedom: read them there)."""


def case_table(ds: xr.Dataset) -> CaseColumns:
    """Flatten a study dataset to one row per case (see the column list of ``GET /studies/{id}/cases``).

    Grid studies are flattened in C order of their parameter dimensions, which is the study's case order;
    sampled studies follow their ``case`` dimension.
    """
    case_dims = tuple(str(d) for d in ds["status"].dims)
    sampled = case_dims == ("case",)
    n = int(np.prod([ds.sizes[d] for d in case_dims])) if case_dims else 1
    t = CaseColumns(design_kind="sampled" if sampled else "grid")

    def flat(name: str) -> np.ndarray:
        da = ds[name]
        extra = [d for d in da.dims if d not in case_dims]
        return np.asarray(da.transpose(*case_dims, *extra).values).reshape(n, -1)

    def unit_of(name: str) -> str:
        return str(ds[name].attrs.get("units", ""))

    if sampled:
        t.add("case", np.asarray(ds["case"].values, dtype=np.int64), "1", "number", True)
        params = [str(c) for c, v in ds.coords.items() if v.dims == ("case",) and c != "case"]
        values = {p: np.asarray(ds[p].values) for p in params}
    else:
        t.add("case", np.arange(n, dtype=np.int64), "1", "number", True)
        params = [str(d) for d in case_dims]
        grids = (
            np.meshgrid(*[np.asarray(ds[d].values) for d in case_dims], indexing="ij") if case_dims else []
        )
        values = {p: g.reshape(n) for p, g in zip(params, grids, strict=True)}
    t.parameters = params
    for p in params:
        v = values[p]
        text = v.dtype.kind in "USO"
        t.add(
            p,
            v.astype(str) if text else v.astype(np.float64),
            "" if text else unit_of(p),
            "text" if text else "number",
            True,
        )
        if not text:
            t.display_units[p] = str(ds[p].attrs.get("display_units", "")) or unit_of(p)
            t.scales[p] = str(ds[p].attrs.get("scale", "linear"))

    def components(name: str) -> tuple[list[str], np.ndarray]:
        """Column suffixes of every component of an output, and its values (n, components)."""
        own = [str(d) for d in ds[name].dims if d not in case_dims]
        labels = [[str(v) for v in ds[d].values] for d in own]
        suffixes = ["_".join(combo) for combo in itertools.product(*labels)]
        return suffixes, flat(name).astype(np.float64)

    def add_output(name: str, column: str, values: np.ndarray, default: bool) -> None:
        spec = OUTPUTS[name]
        t.add(column, values, unit_of(name), "bool" if spec.flag else "number", default)
        t.outputs.setdefault(column, name)

    def summary(name: str, over: str) -> None:
        spec = OUTPUTS[name]
        if over == EACH:
            suffixes, values = components(name)
            for k, suffix in enumerate(suffixes):
                add_output(name, f"{name}_{suffix}" if suffix else name, values[:, k], True)
            return
        kept, values = _worst_over(ds[name], case_dims, over, spec)
        labels = [[str(v) for v in ds[d].values] for d in kept]
        if not kept:
            suffix = "any" if spec.flag else spec.worst
            add_output(name, f"{name}_{suffix}", values[:, 0], True)
        for k, combo in enumerate(itertools.product(*labels) if kept else []):
            add_output(name, f"{name}_{'_'.join(combo)}", values[:, k], True)

    def detail(names: tuple[str, ...]) -> None:
        parts = [(name, *components(name)) for name in names if name in ds]
        if not parts:
            return
        for k in range(len(parts[0][1])):
            for name, suffixes, values in parts:
                column = f"{name}_{suffixes[k]}" if suffixes[k] else name
                add_output(name, column, values[:, k], False)

    for name, over in SUMMARY:
        if name in ds:  # older datasets lack the newer outputs
            summary(name, over)
    status_names = str(ds["status"].attrs.get("flag_meanings", "ok unstable tipping failed")).split()
    codes = flat("status")[:, 0].astype(np.int64)
    t.add(
        "status",
        np.array(
            [status_names[c] if 0 <= c < len(status_names) else str(c) for c in codes], dtype=str
        ).reshape(n),
        "",
        "text",
        True,
    )
    if "meets_criteria" in ds:  # a study with design criteria (studies.questions.criteria)
        t.add("meets_criteria", flat("meets_criteria").astype(np.float64)[:, 0], "1", "bool", True)
        margin = flat("criterion_margin").astype(np.float64)
        for k, name in enumerate(str(c) for c in ds["criterion"].values):
            t.add(f"margin_{name}", margin[:, k], "1", "number", True)
    # the rest: asked for by name
    listed = {name for group in DETAIL for name in group} | {name for name, _ in SUMMARY}
    others = [name for name in OUTPUTS if name not in listed and name not in NOT_TABULATED]
    for group in (*DETAIL, *((name,) for name in others)):  # the catalogue's order: the settings last
        detail(group)
    t.add("message", flat("message")[:, 0].astype(str), "", "text", False)
    # an optimisation's cases (studies.run.optimisation): shown by default
    for name, kind in (("generation", "number"), ("feasible", "bool"), ("pareto", "bool"), ("best", "bool")):
        if name in ds.data_vars:
            t.add(name, flat(name).astype(np.float64)[:, 0], "1", kind, True)
    if "constraint_violation" in ds.data_vars:
        violation = flat("constraint_violation")[:, 0].astype(np.float64)
        t.add("constraint_violation", violation, "1", "number", False)
    # a robust optimisation's candidates (studies.run.robust): judged on their tolerance clouds
    robust = [
        str(k) for k, v in ds.data_vars.items() if v.dims == ("case",) and str(k).endswith("_statistic")
    ]
    if "nominal_feasible" in ds.data_vars:
        t.add("probability_meets_criteria", flat("probability_meets_criteria")[:, 0], "1", "number", True)
        t.add("nominal_feasible", flat("nominal_feasible")[:, 0].astype(np.float64), "1", "bool", False)
        for name in robust:
            t.add(
                name,
                flat(name)[:, 0].astype(np.float64),
                str(ds[name].attrs.get("units", "")),
                "number",
                True,
            )
    _add_long_names(t, ds)
    return t


def _add_long_names(t: CaseColumns, ds: xr.Dataset) -> None:
    """Fill ``t.long_names`` of the output columns named after a dataset variable: its ``long_name``, then
    the column's label (``peak_displacement_y`` -> "peak absolute displacement of the machine c.g., y")."""
    variables = sorted((str(v) for v in ds.data_vars), key=len, reverse=True)
    for c in t.names:
        if c in t.parameters or c in t.long_names:
            continue
        v = next((v for v in variables if c == v or c.startswith(v + "_")), None)
        if v is None or not ds[v].attrs.get("long_name"):
            continue
        label = c[len(v) + 1 :].replace("_", " ")
        t.long_names[c] = str(ds[v].attrs["long_name"]) + (f", {label}" if label else "")


def _worst_over(
    var: xr.DataArray, case_dims: tuple[str, ...], over: str, spec: OutputSpec
) -> tuple[list[str], np.ndarray]:
    """``var`` reduced over its dimension ``over`` to the worst value as the catalogue judges the output
    (``spec.worst``; missing values ignored, all missing stays missing): (the dimensions kept, the values
    as (cases, components kept))."""
    n = int(np.prod([var.sizes[d] for d in case_dims])) if case_dims else 1
    kept = [str(d) for d in var.dims if d not in case_dims and d != over]
    width = int(np.prod([var.sizes[d] for d in kept]))
    a = np.asarray(var.transpose(*case_dims, *kept, over).values, dtype=np.float64)
    worst = _nan_reduce(
        np.nanmax if spec.worst == "max" else np.nanmin, a.reshape(n * width, var.sizes[over])
    )
    return kept, worst.reshape(n, width)


def _nan_reduce(func: Any, a: np.ndarray) -> np.ndarray:
    """Reduce over the last axis ignoring NaN; all-NaN rows stay NaN (without a warning)."""
    out = np.full(a.shape[0], np.nan)
    ok = ~np.all(np.isnan(a), axis=1) if a.shape[1] else np.zeros(a.shape[0], dtype=bool)
    if ok.any():
        out[ok] = func(a[ok], axis=1)
    return out


READ_CHUNK_CACHE = 4 * 1024 * 1024
"""HDF5 chunk cache per variable while a case table is read, bytes."""

CACHE_CASES = 1_000_000
"""Rows of case tables kept in memory at once (the most recently used; the newest is always kept): about
0.9 GB for a 1,000,000-case study of the article scene's 111 columns."""

_TABLES: OrderedDict[tuple[str, int, int], CaseColumns] = OrderedDict()
_TABLES_LOCK = threading.Lock()


def _cached_case_table(path: str, mtime_ns: int, size: int) -> CaseColumns:
    import netCDF4
    import xarray as xr

    key = (path, mtime_ns, size)
    with _TABLES_LOCK:
        if key in _TABLES:
            _TABLES.move_to_end(key)
            return _TABLES[key]
    # variable by variable from the file (read lazily, and not cached by xarray): the table's columns are
    # all that is held, not the dataset beside them; and with a small HDF5 chunk cache per variable (the
    # library's default, 64 MB each, held for every variable read while the file is open, took 0.65 GB
    # beside a 1,000,000-case table)
    with NETCDF_LOCK:
        default = netCDF4.get_chunk_cache()
        netCDF4.set_chunk_cache(READ_CHUNK_CACHE, default[1], default[2])
        try:
            ds = xr.open_dataset(path, cache=False)
        finally:
            netCDF4.set_chunk_cache(*default)
        with ds:
            table = case_table(ds)
    with _TABLES_LOCK:
        _TABLES[key] = table
        while len(_TABLES) > 1 and sum(t.n_cases for t in _TABLES.values()) > CACHE_CASES:
            _TABLES.popitem(last=False)
    return table


def stored_case_table(store: Store, study_id: str) -> CaseColumns:
    """The case table of a done study (cached while its file is unchanged).

    Raises:
        FileNotFoundError: the study has no dataset file.
    """
    path = store.path(study_id)
    try:
        st = path.stat()
    except FileNotFoundError:
        raise FileNotFoundError(f"study {study_id} has no dataset file") from None
    return _cached_case_table(str(path), st.st_mtime_ns, st.st_size)


# ---------------------------------------------------------------------------------- filter language
class CaseQueryError(ValueError):
    """A query of the case table (or of one case) is wrong: ``param`` names the parameter, ``where`` says
    where it was given (``"query"`` or ``"path"``)."""

    def __init__(self, param: str, message: str, where: str = "query"):
        super().__init__(message)
        self.param = param
        self.where = where


_OPS = ("<=", ">=", "==", "!=", "<", ">")
_CLAUSE = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*(<=|>=|==|!=|<|>)\s*(.*?)\s*$", re.DOTALL)
_NUMBER = re.compile(r"^[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?$")
_QUANTITY = re.compile(r"^[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?\s*[A-Za-z%µ][A-Za-z0-9%µ/^* .]*$")
_BARE = re.compile(r"^[A-Za-z_][A-Za-z0-9_.\-]*$")
_NON_FINITE = re.compile(r"^[-+]?(?:inf|infinity|nan)(?![A-Za-z0-9_])", re.IGNORECASE)


@dataclass(frozen=True)
class Condition:
    """One filter clause: ``column op value`` (value: float, bool, str or None for null)."""

    column: str
    op: str
    value: Any


def _check_column(table: CaseColumns, column: str, param: str) -> None:
    if column not in table.data:
        raise CaseQueryError(param, f"{param}: unknown column {column!r}; columns: {', '.join(table.names)}")


def _filter_value(table: CaseColumns, column: str, op: str, raw: str) -> Any:
    kind = table.kinds[column]
    where = f"filter: {column}{op}{raw}"
    if raw == "":
        raise CaseQueryError("filter", f"{where}: a value is missing after {op!r}")
    if raw == "null":
        if op not in ("==", "!="):
            raise CaseQueryError("filter", f"{where}: null takes only == and !=")
        return None
    if kind == "bool":
        if op not in ("==", "!="):
            raise CaseQueryError("filter", f"{where}: {column} is yes/no; use == or != with true or false")
        if raw.lower() in ("true", "false", "1", "0"):
            return raw.lower() in ("true", "1")
        raise CaseQueryError("filter", f"{where}: {column} is yes/no; compare it with true or false")
    if kind == "text":
        if op not in ("==", "!="):
            raise CaseQueryError("filter", f"{where}: {column} is text; use == or !=")
        if len(raw) >= 2 and raw[0] == raw[-1] and raw[0] in "'\"":
            return raw[1:-1]
        if _BARE.match(raw):
            return raw
        raise CaseQueryError("filter", f"{where}: quote text values ('...')")
    if _NON_FINITE.match(raw):
        raise CaseQueryError("filter", f"{where}: not a finite number; compare with a finite value")
    if _NUMBER.match(raw):
        return _finite_value(float(raw), where)
    if _QUANTITY.match(raw):
        problem = quantity_problem(raw)
        if problem is not None:
            raise CaseQueryError("filter", f"{where}: {problem}")
        dimension = dimension_of(table.units[column])
        if dimension is None:
            raise CaseQueryError(
                "filter", f"{where}: {column} has unit {table.units[column]!r}; give a number"
            )
        try:
            value = to_si(raw, dimension, f"filter: {column}")
        except ValueError as err:
            raise CaseQueryError("filter", str(err)) from None
        return _finite_value(value, where)
    raise CaseQueryError("filter", f"{where}: {column} holds numbers; give a number (SI, or with a unit)")


def _finite_value(value: float, where: str) -> float:
    """``value`` when finite; a literal beyond a 64-bit float (``1e999``) reads as infinity: refused."""
    if not math.isfinite(value):
        raise CaseQueryError(
            "filter", f"{where}: not a finite number (beyond a 64-bit float); compare with a finite value"
        )
    return value


def _split_clauses(text: str) -> list[str]:
    """Split at commas outside quotes."""
    parts: list[str] = []
    current: list[str] = []
    quote: str | None = None
    for ch in text:
        if quote:
            quote = None if ch == quote else quote
        elif ch in "'\"":
            quote = ch
        elif ch == ",":
            parts.append("".join(current).strip())
            current = []
            continue
        current.append(ch)
    if quote:
        raise CaseQueryError("filter", f"filter: a quote ({quote}) is not closed")
    parts.append("".join(current).strip())
    return parts


def parse_filter(text: str, table: CaseColumns) -> list[Condition]:
    """The clauses of a filter expression (see the module docstring); CaseQueryError names what is wrong."""
    text = text.strip()
    if not text:
        return []
    if len(text) > 4000:
        raise CaseQueryError("filter", "filter: longer than 4000 characters")
    parts = _split_clauses(text)
    if any(not p for p in parts):
        raise CaseQueryError("filter", "filter: an empty clause (two commas in a row, or a trailing comma)")
    if len(parts) > MAX_FILTER_CLAUSES:
        raise CaseQueryError("filter", f"filter: more than {MAX_FILTER_CLAUSES} clauses")
    out = []
    for part in parts:
        m = _CLAUSE.match(part)
        if not m:
            raise CaseQueryError(
                "filter",
                f"filter: cannot read {part!r}; write column<op>value with op one of "
                f"{', '.join(_OPS)}, clauses joined by commas",
            )
        column, op, raw = m.group(1), m.group(2), m.group(3)
        _check_column(table, column, "filter")
        out.append(Condition(column, op, _filter_value(table, column, op, raw)))
    return out


def filter_mask(table: CaseColumns, conditions: list[Condition]) -> np.ndarray:
    """Cases that pass every condition (AND)."""
    mask = np.ones(table.n_cases, dtype=bool)
    for c in conditions:
        col = table.data[c.column]
        kind = table.kinds[c.column]
        if kind == "text":
            missing = np.zeros(col.shape, dtype=bool)
            if c.value is None:
                hit = missing if c.op == "==" else ~missing
            else:
                eq = col == c.value
                hit = eq if c.op == "==" else ~eq
        else:
            missing = np.isnan(col)
            if c.value is None:
                hit = missing if c.op == "==" else ~missing
            else:
                v = float(c.value)
                with np.errstate(invalid="ignore"):
                    close = np.isclose(col, v, rtol=1e-9, atol=0.0)
                    hit = {
                        "==": close,
                        "!=": ~close,
                        "<": (col < v) & ~close,
                        "<=": (col <= v) | close,
                        ">": (col > v) & ~close,
                        ">=": (col >= v) | close,
                    }[c.op]
                hit = hit & ~missing
        mask &= hit
    return mask


def parse_sort(text: str, table: CaseColumns) -> list[tuple[str, bool]]:
    """``-a,b`` -> [(a, descending), (b, ascending)]."""
    keys = []
    for part in (p.strip() for p in text.split(",")):
        if not part:
            continue
        desc = part.startswith("-")
        name = part.lstrip("-+").strip()
        _check_column(table, name, "sort")
        keys.append((name, desc))
    return keys


def sort_order(table: CaseColumns, rows: np.ndarray, keys: list[tuple[str, bool]]) -> np.ndarray:
    """``rows`` (case positions) sorted by ``keys``; missing values last; ties keep case order."""
    if not keys or rows.size == 0:
        return rows
    lex: list[np.ndarray] = []
    for name, desc in reversed(keys):
        col = table.data[name][rows]
        if table.kinds[name] == "text":
            _, rank = np.unique(col, return_inverse=True)
            value = rank.astype(np.float64)
            missing = np.zeros(rows.size, dtype=bool)
        else:
            value = col.astype(np.float64)
            missing = np.isnan(value)
            value = np.where(missing, 0.0, value)
        lex.append(-value if desc else value)
        lex.append(missing.astype(np.int8))
    return rows[np.lexsort(lex)]


def parse_columns(text: str | None, table: CaseColumns) -> list[str]:
    if text is None or not text.strip():
        return list(table.default)
    if text.strip() == "all":
        return list(table.names)
    cols = []
    for part in (p.strip() for p in text.split(",")):
        if not part:
            continue
        _check_column(table, part, "columns")
        if part not in cols:
            cols.append(part)
    return cols


def json_values(values: np.ndarray, kind: str) -> list[Any]:
    """Column values as JSON-able Python: NaN -> None, yes/no -> bool, whole numbers of ``case`` -> int."""
    if kind == "text":
        return [str(v) for v in values.tolist()]
    a = np.asarray(values)
    if a.dtype.kind in "iu":
        return [int(v) for v in a.tolist()]
    if kind == "bool":
        return [None if math.isnan(v) else bool(v) for v in a.astype(np.float64).tolist()]
    return [None if not math.isfinite(v) else v for v in a.astype(np.float64).tolist()]


def select_cases(
    table: CaseColumns, filter: str | None, sort: str | None, columns: str | None, limit: int, offset: int
) -> tuple[list[str], np.ndarray, int]:
    """(columns, case positions of the page, number of cases matching the filter)."""
    cols = parse_columns(columns, table)
    conditions = parse_filter(filter or "", table)
    keys = parse_sort(sort or "", table)
    rows = np.flatnonzero(filter_mask(table, conditions))
    rows = sort_order(table, rows, keys)
    return cols, rows[offset : offset + limit], int(rows.size)


def _csv_cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v)
    return str(v)


def csv_header(name: str, unit: str) -> str:
    """A CSV column heading with its unit: ``peak_displacement_y [m]``; a text column, or a number without
    a unit (``"1"``: case numbers, yes/no, ratios), is its name alone."""
    return f"{name} [{unit}]" if unit not in ("", "1") else name


def cases_csv(table: CaseColumns, columns: list[str], rows: np.ndarray) -> str:
    """The cases at positions ``rows`` as CSV text: a header of column names with their SI unit
    (:func:`csv_header`: ``peak_displacement_y [m]``), then one line per case (empty for a missing value,
    ``true``/``false`` for yes/no, numbers in SI)."""
    values = {c: json_values(table.data[c][rows], table.kinds[c]) for c in columns}
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow([csv_header(c, table.units[c]) for c in columns])
    for i in range(rows.size):
        writer.writerow([_csv_cell(values[c][i]) for c in columns])
    return buf.getvalue()


def check_page_size(n_rows: int, n_columns: int) -> None:
    """Refuse a page of more than :data:`MAX_CASE_CELLS` values (CaseQueryError naming ``limit``)."""
    if n_rows * n_columns > MAX_CASE_CELLS:
        raise CaseQueryError(
            "limit",
            f"limit: {n_rows} rows x {n_columns} columns is more than {MAX_CASE_CELLS} values; "
            "ask for fewer rows or columns (offset pages through the rest)",
        )
