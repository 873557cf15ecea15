"""``/studies``: submit, list, inspect, cancel and delete studies; fetch their datasets, case tables,
per-case time histories and plots.

Handlers are thin: the catalog and files are :class:`studies.store.Store`, running is
:class:`service.jobs.JobQueue`. This module also holds the per-case table every tabular answer is built
from: :func:`case_table` flattens a study dataset to one row per case, and :func:`parse_filter` reads the
small filter language of ``GET /studies/{id}/cases`` (parsed here, never evaluated as Python):

    filter  := clause ("," clause)*            commas mean AND
    clause  := column op value
    op      := "<" | "<=" | ">" | ">=" | "==" | "!="
    value   := number [unit] | true | false | null | 'text' | "text" | bare-word

Numbers are SI unless a unit follows (``peak_displacement_y<5 mm``). A missing value (a case that did not
compute) matches only ``==null``. Text and yes/no columns take only ``==`` and ``!=``.
"""

from __future__ import annotations

import csv
import functools
import io
import json
import math
import re
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
import xarray as xr
from fastapi import APIRouter, Body, Depends, HTTPException, Query, Request, Response
from fastapi import Path as PathParam
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import FileResponse, JSONResponse
from pydantic import ValidationError

from isolab.service import plots
from isolab.service.jobs import JobQueue
from isolab.service.request_limits import case_count_bound, quantity_problem, screen_definition
from isolab.service.routes import app_settings, run_heavy
from isolab.service.schemas import (
    EXAMPLE_LHS_STUDY,
    EXAMPLE_STUDY,
    CaseTable,
    MessageBody,
    StudyAccepted,
    StudyDetail,
    StudyLinks,
    StudyList,
    StudyProgress,
    StudyStatusName,
    StudySummary,
    Timeseries,
    ValidationErrorBody,
)
from isolab.service.settings import Settings
from isolab.studies.store import NETCDF_LOCK, Store, StudyNotFound, utc_now

router = APIRouter(prefix="/studies", tags=["studies"])

NOT_FOUND = {404: {"model": MessageBody, "description": "no study with this id (or a malformed id)"}}
NOT_DONE = {409: {"model": MessageBody, "description": "the study is not done yet"}}
INVALID = {422: {"model": ValidationErrorBody, "description": "invalid input; `loc` names the field"}}
MAX_CASE_ROWS = 100_000
"""Most rows one ``GET /studies/{id}/cases`` answer holds."""
MAX_FILTER_CLAUSES = 64
MAX_CASE_CELLS = 5_000_000
"""Most values (rows x columns) one ``GET /studies/{id}/cases`` answer holds."""
MAX_RECORDED_SAMPLES = 2_000_000
"""Longest time history (samples) a case is recomputed with: about 200 bytes a sample in memory."""
MAX_RETURNED_SAMPLES = 200_000
"""Most samples per series one time-series answer holds (``every`` thins them)."""
MAX_OFFSET = 1_000_000_000
"""Largest ``offset`` of a listing (SQLite integers stop at 2**63)."""
StudyId = Annotated[str, PathParam(description="study id (32 hex digits)")]


# ------------------------------------------------------------------------------------- dependencies
# The dependencies are coroutines: they only read app state, and a plain function would cost every
# request a round trip through the thread pool.
async def study_store(request: Request) -> Store:
    """FastAPI dependency: the app's study store (the job queue's; opened on first use)."""
    return _jobs(request).store


async def job_queue(request: Request) -> JobQueue:
    """FastAPI dependency: the app's study queue (started by the lifespan)."""
    return _jobs(request)


def _jobs(request: Request) -> JobQueue:
    jobs = getattr(request.app.state, "jobs", None)
    if jobs is None:
        raise RuntimeError(
            "the job queue is not running: serve the app made by create_app() with its lifespan"
        )
    return jobs


# ------------------------------------------------------------------------------------------- errors
def invalid(loc: list[str | int], msg: str, kind: str = "value_error") -> HTTPException:
    """A 422 with FastAPI's error shape: ``{"detail": [{"loc": [...], "msg": ..., "type": ...}]}``."""
    return HTTPException(status_code=422, detail=[{"loc": loc, "msg": msg, "type": kind}])


_MESSAGE_LOC = re.compile(r"^([A-Za-z_]\w*(?:\[\d+\])?(?:\.[A-Za-z_]\w*(?:\[\d+\])?)*)(?: \([^)]*\))?: ")


def _loc_from_message(msg: str) -> list[str | int]:
    """``design.samples: ...`` -> ['design', 'samples']; ``parameters[0].path: ...`` -> ['parameters', 0,
    'path']; no such prefix -> []."""
    m = _MESSAGE_LOC.match(msg)
    if not m:
        return []
    loc: list[str | int] = []
    for part in m.group(1).split("."):
        name, _, rest = part.partition("[")
        loc.append(name)
        if rest:
            loc.append(int(rest.rstrip("]")))
    return loc


def validation_details(err: ValidationError, prefix: list[str | int]) -> list[dict[str, Any]]:
    """pydantic errors as 422 details whose ``loc`` is the full path of the field (under ``prefix``)."""
    out = []
    for e in err.errors(include_url=False):
        msg = str(e["msg"]).removeprefix("Value error, ")
        loc = [x for x in e["loc"]] or _loc_from_message(msg)
        out.append({"loc": [*prefix, *loc], "msg": msg, "type": str(e["type"])})
    return out


def _row(store: Store, study_id: str) -> dict[str, Any]:
    try:
        return store.get(study_id)
    except (StudyNotFound, ValueError):
        raise HTTPException(status_code=404, detail=f"no study with id {study_id!r}") from None


def _require_done(row: dict[str, Any]) -> None:
    if row["status"] != "done":
        detail = f"study {row['id']} is {row['status']}"
        if row["status"] in ("queued", "running"):
            detail += f" ({row['n_done']} of {row['n_cases']} cases done)"
        elif row.get("error"):
            detail += f": {row['error']}"
        raise HTTPException(status_code=409, detail=detail + "; its results exist once it is done")


# -------------------------------------------------------------------------------------- catalog rows
def links(study_id: str) -> StudyLinks:
    base = f"/studies/{study_id}"
    return StudyLinks(self=base, dataset=f"{base}/dataset", cases=f"{base}/cases")


def summary(row: dict[str, Any]) -> dict[str, Any]:
    return {
        "id": row["id"],
        "name": row["name"],
        "status": row["status"],
        "progress": StudyProgress(done=row["n_done"], total=row["n_cases"], failed=row["n_failed"]),
        "created": row["created"],
        "started": row["started"],
        "finished": row["finished"],
        "error": row["error"],
        "parameters": row["parameters"] or [],
        "isolator_types": row["isolator_types"] or [],
        "fidelity": row["fidelity"],
        "integrator": row["integrator"],
        "dt": row["dt"],
        "links": links(row["id"]),
    }


# ------------------------------------------------------------------------------------- study objects
def too_many_cases(n_cases: int, loc: list[str | int], max_cases: int) -> HTTPException:
    return invalid(
        loc,
        f"the study has {n_cases} cases, more than this service's limit of {max_cases} (ISOLAB_MAX_CASES)",
    )


def validate_definition(body: dict[str, Any], max_cases: int | None = None) -> Any:
    """A :class:`studies.study.Study` from a REST body (inline scene only); 422 naming the field.

    Hostile values (:func:`service.request_limits.screen_definition`) are refused before validation, and
    so is a study whose case count, read from the raw definition, is above ``max_cases``: its design is
    never built."""
    from isolab.studies.study import Study

    if body.get("scene_file") is not None:
        raise invalid(
            ["body", "scene_file"],
            "scene_file is not read over the API: give the scene inline "
            "under 'scene' (the Python client and `isolab submit` inline it for you)",
        )
    problems = screen_definition(body, ["body"])
    if problems:
        raise HTTPException(status_code=422, detail=problems)
    bound = case_count_bound(body)
    if max_cases is not None and bound is not None and bound[0] > max_cases:
        raise too_many_cases(bound[0], bound[1], max_cases)
    try:
        return Study.model_validate(body)
    except ValidationError as err:
        raise HTTPException(status_code=422, detail=validation_details(err, ["body"])) from None
    except (OverflowError, RecursionError) as err:  # a number or a structure past what can be computed
        raise invalid(["body"], f"the definition cannot be computed: {type(err).__name__}: {err}") from None


def stored_definition(study: Any) -> dict[str, Any]:
    """The definition the catalog keeps: validated, SI, defaults filled in, names as users write them."""
    return study.model_dump(mode="json", by_alias=True, exclude_none=True)


@functools.lru_cache(maxsize=16)
def _study_from_json(text: str) -> Any:
    from isolab.studies.study import Study

    return Study.model_validate(json.loads(text))


def study_of(row: dict[str, Any]) -> Any:
    """The study object of a catalog row (cached by definition)."""
    return _study_from_json(json.dumps(row["definition"], sort_keys=True))


def _labels(study: Any) -> tuple[list[str], list[str]]:
    from isolab.studies.runner import study_labels

    return study_labels(study)


# ---------------------------------------------------------------------------------------- case table
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
    """

    names: list[str] = field(default_factory=list)
    data: dict[str, np.ndarray] = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)
    kinds: dict[str, str] = field(default_factory=dict)
    parameters: list[str] = field(default_factory=list)
    default: list[str] = field(default_factory=list)
    design_kind: str = "grid"

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


def case_table(ds: xr.Dataset) -> CaseColumns:
    """Flatten a study dataset to one row per case (see the column list of ``GET /studies/{id}/cases``).

    Grid studies are flattened in C order of their parameter dimensions, which is the study's case order;
    sampled studies follow their ``case`` dimension.
    """
    case_dims = tuple(ds["status"].dims)
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

    axes = [str(a) for a in ds["axis"].values]
    rotations = [str(r) for r in ds["rotation"].values]
    isolators = [str(i) for i in ds["isolator"].values]
    points = [str(p) for p in ds["point"].values]
    modes = [str(int(m)) for m in ds["mode"].values]

    def per(
        name: str, labels: list[str], default: bool, prefix: str | None = None, kind: str = "number"
    ) -> None:
        a = flat(name).astype(np.float64)
        for k, label in enumerate(labels):
            t.add(f"{prefix or name}_{label}", a[:, k], unit_of(name), kind, default)

    per("peak_displacement", axes, True)
    per("peak_rotation", rotations, True)
    force = flat("peak_isolator_force").astype(np.float64).reshape(n, len(isolators), len(axes))
    for k, a in enumerate(axes):
        t.add(f"peak_isolator_force_{a}", _nan_reduce(np.nanmax, force[:, :, k]), "N", "number", True)
    min_load = flat("min_isolator_load").astype(np.float64)
    t.add("min_isolator_load_min", _nan_reduce(np.nanmin, min_load), "N", "number", True)
    liftoff = flat("liftoff").astype(np.float64)
    t.add("liftoff_any", _nan_reduce(np.nanmax, liftoff), "1", "bool", True)
    for name in ("settling_time", "settled"):
        t.add(
            name,
            flat(name).astype(np.float64)[:, 0],
            unit_of(name),
            "bool" if name == "settled" else "number",
            True,
        )
    per("natural_frequency", modes, True)
    ppd = flat("peak_point_displacement").astype(np.float64).reshape(n, len(points), len(axes))
    for j, p in enumerate(points):
        for k, a in enumerate(axes):
            t.add(f"peak_point_displacement_{p}_{a}", ppd[:, j, k], "m", "number", True)
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
    # the rest: asked for by name
    per("damping_ratio", modes, False)
    for j, iso in enumerate(isolators):
        for k, a in enumerate(axes):
            t.add(f"peak_isolator_force_{iso}_{a}", force[:, j, k], "N", "number", False)
    per("min_isolator_load", isolators, False)
    per("static_isolator_load", isolators, False)
    per("liftoff", isolators, False, kind="bool")
    per("rms_displacement", axes, False)
    per("final_displacement", axes, False)
    per("final_rotation", rotations, False)
    per("transmissibility", axes, False)
    t.add("dt", flat("dt").astype(np.float64)[:, 0], "s", "number", False)
    t.add("message", flat("message")[:, 0].astype(str), "", "text", False)
    return t


def _nan_reduce(func: Any, a: np.ndarray) -> np.ndarray:
    """Reduce over the last axis ignoring NaN; all-NaN rows stay NaN (without a warning)."""
    out = np.full(a.shape[0], np.nan)
    ok = ~np.all(np.isnan(a), axis=1) if a.shape[1] else np.zeros(a.shape[0], dtype=bool)
    if ok.any():
        out[ok] = func(a[ok], axis=1)
    return out


@functools.lru_cache(maxsize=4)
def _cached_case_table(path: str, mtime_ns: int, size: int) -> CaseColumns:
    with NETCDF_LOCK, xr.open_dataset(path) as ds:
        loaded = ds.load()
    return case_table(loaded)


def stored_case_table(store: Store, study_id: str) -> CaseColumns:
    """The case table of a done study (cached while its file is unchanged)."""
    path = store.path(study_id)
    try:
        st = path.stat()
    except FileNotFoundError:
        raise HTTPException(status_code=404, detail=f"study {study_id} has no dataset file") from None
    return _cached_case_table(str(path), st.st_mtime_ns, st.st_size)


# ---------------------------------------------------------------------------------- filter language
class CaseQueryError(ValueError):
    """A query parameter of the case table is wrong; ``param`` names it."""

    def __init__(self, param: str, message: str):
        super().__init__(message)
        self.param = param


_OPS = ("<=", ">=", "==", "!=", "<", ">")
_CLAUSE = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*(<=|>=|==|!=|<|>)\s*(.*?)\s*$", re.DOTALL)
_NUMBER = re.compile(r"^[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?$")
_QUANTITY = re.compile(r"^[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?\s*[A-Za-z%µ][A-Za-z0-9%µ/^* .]*$")
_BARE = re.compile(r"^[A-Za-z_][A-Za-z0-9_.\-]*$")
_UNIT_DIMENSION = {
    "m": "length",
    "rad": "angle",
    "s": "time",
    "Hz": "frequency",
    "m/s": "velocity",
    "m/s^2": "acceleration",
    "m/s^3": "jerk",
    "kg": "mass",
    "N/m": "stiffness",
    "N s/m": "damping",
    "kg/m^3": "density",
    "kg m^2": "inertia",
    "1": "dimensionless",
}


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
    if _NUMBER.match(raw):
        return float(raw)
    if _QUANTITY.match(raw):
        from isolab.studies.units import to_si

        problem = quantity_problem(raw)
        if problem is not None:
            raise CaseQueryError("filter", f"{where}: {problem}")

        dimension = _UNIT_DIMENSION.get(table.units[column])
        if table.units[column] == "N":
            return _force(raw, where)
        if dimension is None:
            raise CaseQueryError(
                "filter", f"{where}: {column} has unit {table.units[column]!r}; give a number"
            )
        try:
            return to_si(raw, dimension, f"filter: {column}")
        except ValueError as err:
            raise CaseQueryError("filter", str(err)) from None
    raise CaseQueryError("filter", f"{where}: {column} holds numbers; give a number (SI, or with a unit)")


def _force(raw: str, where: str) -> float:
    from isolab.studies.units import UREG

    try:
        q = UREG.Quantity(raw)
        return float(q.to("N").magnitude)
    except Exception:  # pint raises several kinds of errors on text it cannot read
        raise CaseQueryError("filter", f"{where}: cannot read {raw!r} as a force") from None


def _split_clauses(text: str) -> list[str]:
    """Split at commas outside quotes."""
    parts, current, quote = [], [], None
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


# ------------------------------------------------------------------------------------------- routes
@router.post(
    "",
    status_code=202,
    response_model=StudyAccepted,
    responses={**INVALID, 413: {"model": MessageBody, "description": "request body too large"}},
    summary="Submit a study",
)
async def submit_study(
    request: Request,
    response: Response,
    definition: Annotated[
        dict[str, Any],
        Body(
            description="study definition with an inline scene (scene_file is not read over the API); "
            "quantities in SI or as strings with units ('2 g', '800 mm')",
            openapi_examples={
                "grid": {"summary": "3 isolator types x 2 Y accelerations (6 cases)", "value": EXAMPLE_STUDY},
                "lhs": {
                    "summary": "64-case Latin hypercube over f_vertical and zeta",
                    "value": EXAMPLE_LHS_STUDY,
                },
            },
        ),
    ],
    settings: Settings = Depends(app_settings),
    store: Store = Depends(study_store),
    jobs: JobQueue = Depends(job_queue),
) -> StudyAccepted:
    """Validate the study, store it in the catalog (status queued) and queue it. 202 with its links."""
    accepted = await run_heavy(request, accept_study, definition, settings, store, jobs)
    response.headers["Location"] = accepted.links.self
    return accepted


def accept_study(
    definition: dict[str, Any], settings: Settings, store: Store, jobs: JobQueue
) -> StudyAccepted:
    """Validate a study, store it in the catalog (status queued) and queue it (runs in a worker thread)."""
    from isolab.studies.runner import isolator_types

    study = validate_definition(definition, settings.max_cases)
    n_cases = int(study.n_cases)
    if n_cases > settings.max_cases:
        spec = study.design_spec
        loc = (
            ["body", "design", "samples"]
            if spec.type in ("lhs", "sobol", "random")
            else (["body", "design", "cases"] if spec.type == "list" else ["body", "parameters"])
        )
        raise too_many_cases(n_cases, loc, settings.max_cases)
    sim = study.simulation
    study_id = store.create(
        stored_definition(study),
        name=study.name,
        n_cases=n_cases,
        parameters=list(study.design().names),
        isolator_types=isolator_types(study),
        fidelity=sim.fidelity,
        integrator=sim.integrator,
        dt=sim.dt,
    )
    try:
        jobs.submit(study_id)
    except RuntimeError as err:  # shutting down: the study stays queued and runs at the next start
        raise HTTPException(status_code=503, detail=str(err)) from None
    return StudyAccepted(id=study_id, status="queued", n_cases=n_cases, links=links(study_id))


@router.get("", response_model=StudyList, responses=INVALID, summary="List studies")
def list_studies(
    name: Annotated[str | None, Query(description="exact study name")] = None,
    status: Annotated[StudyStatusName | None, Query(description="study status")] = None,
    isolator_type: Annotated[str | None, Query(description="studies involving this isolator type")] = None,
    created_after: Annotated[
        str | None, Query(description="ISO 8601 time (UTC if no zone), inclusive")
    ] = None,
    created_before: Annotated[
        str | None, Query(description="ISO 8601 time (UTC if no zone), inclusive")
    ] = None,
    limit: Annotated[int, Query(ge=1, le=500)] = 50,
    offset: Annotated[int, Query(ge=0, le=MAX_OFFSET)] = 0,
    store: Store = Depends(study_store),
) -> StudyList:
    """Studies in the catalog, newest first, filtered (all filters must hold)."""
    filters = dict(
        name=name,
        status=status,
        isolator_type=isolator_type,
        created_after=created_after,
        created_before=created_before,
    )
    try:
        rows = store.list(**filters, limit=limit, offset=offset)
        total = store.count(**filters)
    except ValueError as err:
        field_name = str(err).split(":", 1)[0]
        raise invalid(["query", field_name], str(err)) from None
    return StudyList(
        items=[StudySummary(**summary(r)) for r in rows], total=total, limit=limit, offset=offset
    )


@router.get("/{study_id}", response_model=StudyDetail, responses=NOT_FOUND, summary="A study's status")
def get_study(study_id: StudyId, store: Store = Depends(study_store)) -> StudyDetail:
    """Status, progress, times, error and the definition of one study."""
    row = _row(store, study_id)
    return StudyDetail(**summary(row), definition=row["definition"])


@router.delete("/{study_id}", status_code=204, responses=NOT_FOUND, summary="Cancel or delete a study")
def delete_study(
    study_id: StudyId, store: Store = Depends(study_store), jobs: JobQueue = Depends(job_queue)
) -> Response:
    """A queued or running study is cancelled (status cancelled, kept in the catalog); a finished,
    failed or cancelled one is removed with its files."""
    row = _row(store, study_id)
    if row["status"] in ("queued", "running"):
        if not jobs.cancel(study_id):
            store.update(study_id, status="cancelled", finished=utc_now())
    else:
        store.delete(study_id)
    return Response(status_code=204)


@router.get(
    "/{study_id}/dataset",
    response_class=FileResponse,
    responses={
        **NOT_FOUND,
        **NOT_DONE,
        200: {"content": {"application/x-netcdf": {}}, "description": "the study's netCDF4 file"},
    },
    summary="A study's dataset (netCDF)",
)
def get_dataset(study_id: StudyId, store: Store = Depends(study_store)) -> FileResponse:
    """The study's labelled dataset as a netCDF4 file (streamed); 409 until the study is done."""
    row = _row(store, study_id)
    _require_done(row)
    path = store.path(study_id)
    if not path.is_file():
        raise HTTPException(
            status_code=404, detail=f"study {study_id} is done but its dataset file is missing"
        )
    # the study's name is user text: only letters, digits, _ and - reach the suggested file name
    stem = re.sub(r"[^A-Za-z0-9_-]+", "_", row["name"]).strip("_-")[:100] or "study"
    filename = f"{stem}-{study_id}.nc"
    return FileResponse(path, media_type="application/x-netcdf", filename=filename)


@router.get(
    "/{study_id}/cases",
    response_model=CaseTable,
    responses={
        **NOT_FOUND,
        **NOT_DONE,
        **INVALID,
        200: {"content": {"text/csv": {}}, "description": "the table as JSON or CSV"},
    },
    summary="Per-case table (filter, sort, columns)",
)
def get_cases(
    study_id: StudyId,
    filter: Annotated[
        str | None,
        Query(
            description="comma-separated clauses, all must hold: column<op>value, op one of < <= > >= == !=; "
            "values: numbers (SI, or with a unit), true, false, null, text",
            examples=[
                "peak_displacement_y<0.005,liftoff_any==false",
                "isolator_type==air,settling_time<=1.5 s",
            ],
        ),
    ] = None,
    sort: Annotated[
        str | None,
        Query(
            description="columns to sort by, comma-separated; prefix - for descending; missing values last",
            examples=["-peak_displacement_y"],
        ),
    ] = None,
    columns: Annotated[
        str | None,
        Query(
            description="comma-separated columns to return, or 'all' "
            "(default: parameters and the main outputs)"
        ),
    ] = None,
    limit: Annotated[int, Query(ge=1, le=MAX_CASE_ROWS)] = 1000,
    offset: Annotated[int, Query(ge=0, le=MAX_OFFSET)] = 0,
    format: Annotated[Literal["json", "csv"], Query(description="json (default) or csv")] = "json",
    store: Store = Depends(study_store),
) -> Any:
    """One row per case: the varied parameters and the outputs flattened to columns
    (``peak_displacement_y``, ``min_isolator_load_min``, ``liftoff_any``, ``natural_frequency_1``...).
    Unknown columns are refused with 422 naming them."""
    row = _row(store, study_id)
    _require_done(row)
    table = stored_case_table(store, study_id)
    try:
        cols, rows, matched = select_cases(table, filter, sort, columns, limit, offset)
    except CaseQueryError as err:
        raise invalid(["query", err.param], str(err)) from None
    if rows.size * len(cols) > MAX_CASE_CELLS:
        raise invalid(
            ["query", "limit"],
            f"limit: {rows.size} rows x {len(cols)} columns is more than {MAX_CASE_CELLS} values; "
            "ask for fewer rows or columns (offset pages through the rest)",
        )
    values = {c: json_values(table.data[c][rows], table.kinds[c]) for c in cols}
    if format == "csv":
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        writer.writerow(cols)
        for i in range(rows.size):
            writer.writerow([_csv_cell(values[c][i]) for c in cols])
        return Response(
            buf.getvalue(), media_type="text/csv; charset=utf-8", headers={"X-Total-Count": str(matched)}
        )
    out_rows = [{c: values[c][i] for c in cols} for i in range(rows.size)]
    return JSONResponse(
        {
            "study_id": study_id,
            "n_cases": table.n_cases,
            "n_matched": matched,
            "offset": offset,
            "limit": limit,
            "columns": cols,
            "units": {c: table.units[c] for c in cols},
            "rows": out_rows,
        }
    )


# --------------------------------------------------------------------------------- time histories
@dataclass
class CaseHistory:
    """Time histories of one case (SI): arrays trimmed to the samples the run produced."""

    parameters: dict[str, Any]
    status: str
    message: str
    time: np.ndarray  # (T,) s
    displacement: np.ndarray  # (T, 3) m
    rotation: np.ndarray  # (T, 3) rad
    isolator_force: np.ndarray  # (T, n, 3) N
    point_displacement: np.ndarray  # (T, p, 3) m
    isolator_names: list[str]
    point_names: list[str]


def case_history(study: Any, case: int, every: int = 1) -> CaseHistory:
    """Recompute one case with its time histories recorded (runs the engine: call it off the event loop).

    Refused (422) when the case would record more than :data:`MAX_RECORDED_SAMPLES` samples, or return
    more than :data:`MAX_RETURNED_SAMPLES` with every ``every``-th kept."""
    from isolab.engine import STATUS_NAMES, simulate

    sim = study.simulation
    try:
        batch = study.batch([case])
    except ValueError as err:  # a combination of values no scene can have
        raise invalid(["path", "case"], f"case {case} cannot be simulated: {err}") from None
    if sim.dt is not None:
        samples = int(math.ceil(float(batch.duration[0]) / float(sim.dt))) + 1
        if samples > MAX_RECORDED_SAMPLES:
            raise invalid(
                ["path", "case"],
                f"case {case} runs {samples} time steps; time histories are recomputed only for cases of "
                f"at most {MAX_RECORDED_SAMPLES} (a shorter duration or a longer step)",
            )
        if math.ceil(samples / every) > MAX_RETURNED_SAMPLES:
            raise invalid(
                ["query", "every"],
                f"case {case} has {samples} samples; keep at most {MAX_RETURNED_SAMPLES} "
                f"(every >= {math.ceil(samples / MAX_RETURNED_SAMPLES)})",
            )
    result = simulate(
        batch,
        fidelity=sim.fidelity,
        integrator=sim.integrator,
        dt=sim.dt,
        auto_step=sim.auto_step,
        record=[0],
    )
    h = result.history
    n = int(h["n_samples"][0])
    iso, pts = _labels(study)
    return CaseHistory(
        parameters=study.case_values(case),
        status=STATUS_NAMES[int(result.status[0])],
        message=str(result.message[0]),
        time=np.asarray(h["time"][0, :n]),
        displacement=np.asarray(h["displacement"][0, :n]),
        rotation=np.asarray(h["rotation"][0, :n]),
        isolator_force=np.asarray(h["isolator_force"][0, :n]),
        point_displacement=np.asarray(h["point_displacement"][0, :n]),
        isolator_names=iso,
        point_names=pts,
    )


def _case_study(store: Store, study_id: str, case: int) -> Any:
    """The study as its cases run (an accuracy request resolved to the model the runner chose)."""
    row = _row(store, study_id)
    if not 0 <= case < row["n_cases"]:
        raise HTTPException(
            status_code=404, detail=f"study {study_id} has no case {case} (cases 0..{row['n_cases'] - 1})"
        )
    from isolab.studies.accuracy import recorded_choice

    study = study_of(row)
    if study.simulation.request is None:
        return study
    choice = recorded_choice(study, row["fidelity"], row["integrator"], row["dt"])
    return _resolved(json.dumps(row["definition"], sort_keys=True), choice)


@functools.lru_cache(maxsize=16)
def _resolved(definition: str, choice: Any) -> Any:
    from isolab.studies.accuracy import resolved_study

    return resolved_study(_study_from_json(definition), choice)


def _series(a: np.ndarray) -> list[float | None]:
    return [v if math.isfinite(v) else None for v in np.asarray(a, dtype=np.float64).tolist()]


def history_json(study_id: str, case: int, h: CaseHistory, every: int) -> dict[str, Any]:
    s = slice(None, None, every)
    axes, rots = ("x", "y", "z"), ("rx", "ry", "rz")
    return {
        "study_id": study_id,
        "case": case,
        "parameters": h.parameters,
        "status": h.status,
        "message": h.message,
        "units": {
            "time": "s",
            "displacement": "m",
            "rotation": "rad",
            "isolator_force": "N",
            "point_displacement": "m",
        },
        "time": _series(h.time[s]),
        "displacement": {a: _series(h.displacement[s, k]) for k, a in enumerate(axes)},
        "rotation": {r: _series(h.rotation[s, k]) for k, r in enumerate(rots)},
        "isolator_force": {
            iso: {a: _series(h.isolator_force[s, j, k]) for k, a in enumerate(axes)}
            for j, iso in enumerate(h.isolator_names)
        },
        "point_displacement": {
            p: {a: _series(h.point_displacement[s, j, k]) for k, a in enumerate(axes)}
            for j, p in enumerate(h.point_names)
        },
    }


def history_dataset(study_id: str, case: int, h: CaseHistory, every: int) -> xr.Dataset:
    """The histories as a CF-described dataset: ``displacement`` (time, axis), ``base_rotation``
    (time, rotation), ``isolator_force`` (time, isolator, axis), ``point_displacement``
    (time, point, axis)."""
    s = slice(None, None, every)
    ds = xr.Dataset(
        {
            "displacement": (
                ("time", "axis"),
                h.displacement[s],
                {"units": "m", "long_name": "displacement of the machine c.g."},
            ),
            "base_rotation": (
                ("time", "rotation"),
                h.rotation[s],
                {"units": "rad", "long_name": "rotation of the machine base"},
            ),
            "isolator_force": (
                ("time", "isolator", "axis"),
                h.isolator_force[s],
                {"units": "N", "long_name": "dynamic isolator force"},
            ),
            "point_displacement": (
                ("time", "point", "axis"),
                h.point_displacement[s],
                {"units": "m", "long_name": "displacement of a point of interest"},
            ),
        },
        coords={
            "time": ("time", h.time[s], {"units": "s", "long_name": "time"}),
            "axis": ("axis", np.array(["x", "y", "z"]), {"units": "1", "long_name": "floor axis (Z up)"}),
            "rotation": (
                "rotation",
                np.array(["rx", "ry", "rz"]),
                {"units": "1", "long_name": "rotation axis"},
            ),
            "isolator": (
                "isolator",
                np.array(h.isolator_names, dtype=str).reshape(-1),
                {"units": "1", "long_name": "isolator"},
            ),
            "point": (
                "point",
                np.array(h.point_names, dtype=str).reshape(-1),
                {"units": "1", "long_name": "point of interest"},
            ),
        },
    )
    ds.attrs = {
        "Conventions": "CF-1.10",
        "title": f"isolab study {study_id} case {case}",
        "study_id": study_id,
        "case": case,
        "status": h.status,
        "message": h.message,
        "parameters": json.dumps(h.parameters, sort_keys=True),
    }
    return ds


def netcdf_bytes(ds: xr.Dataset) -> bytes:
    with tempfile.TemporaryDirectory(prefix="isolab-") as tmp:
        path = Path(tmp) / "case.nc"
        with NETCDF_LOCK:
            ds.to_netcdf(path, format="NETCDF4", engine="netcdf4")
        return path.read_bytes()


@router.get(
    "/{study_id}/cases/{case}/timeseries",
    response_model=Timeseries,
    responses={
        **NOT_FOUND,
        200: {"content": {"application/x-netcdf": {}}, "description": "time histories as JSON or netCDF"},
    },
    summary="Time histories of one case (recomputed)",
)
async def get_timeseries(
    request: Request,
    study_id: StudyId,
    case: Annotated[int, PathParam(description="case number (the `case` column of the table)")],
    format: Annotated[Literal["json", "netcdf"], Query()] = "json",
    every: Annotated[int, Query(ge=1, le=10_000, description="keep every n-th sample")] = 1,
    store: Store = Depends(study_store),
) -> Any:
    """Recompute one case from the stored definition with its histories recorded: time, c.g.
    displacement, base rotation, isolator forces and point displacements (SI, units in the answer)."""
    study = await run_heavy(request, _case_study, store, study_id, case)
    h = await run_heavy(request, case_history, study, case, every)
    if format == "netcdf":
        data = await run_heavy(request, netcdf_bytes, history_dataset(study_id, case, h, every))
        return Response(
            data,
            media_type="application/x-netcdf",
            headers={"Content-Disposition": f'attachment; filename="{study_id}-case{case}.nc"'},
        )
    content = await run_heavy(request, history_json, study_id, case, h, every)
    return JSONResponse(content)


PNG = {200: {"content": {"image/png": {}}, "description": "a PNG image"}}


@router.get(
    "/{study_id}/cases/{case}/plot.png",
    response_class=Response,
    responses={**NOT_FOUND, **PNG},
    summary="Figures of one case (PNG)",
)
async def get_case_plot(
    request: Request,
    study_id: StudyId,
    case: Annotated[int, PathParam(description="case number")],
    store: Store = Depends(study_store),
) -> Response:
    """C.g. translation (mm), base rotation (mrad) and isolator forces per axis (N) against time, stacked."""
    study = await run_heavy(request, _case_study, store, study_id, case)
    h = await run_heavy(request, case_history, study, case)
    params = ", ".join(f"{k}={plots.format_value(v)}" for k, v in h.parameters.items())
    title = f"{study.name} case {case}" + (f" ({params})" if params else "")
    png = await run_heavy(
        request,
        plots.case_png, h.time, h.displacement, h.rotation, h.isolator_force, h.isolator_names, title
    )
    return Response(png, media_type="image/png")


@router.get(
    "/{study_id}/plot.png",
    response_class=Response,
    responses={**NOT_FOUND, **NOT_DONE, **INVALID, **PNG},
    summary="An output against one or two varied parameters (PNG)",
)
async def get_study_plot(
    request: Request,
    study_id: StudyId,
    y: Annotated[str, Query(description="output column of the case table, e.g. peak_displacement_y")],
    x: Annotated[str, Query(description="a varied parameter, e.g. stage_y_acceleration")],
    x2: Annotated[str | None, Query(description="a second varied parameter: draws a heat map")] = None,
    reduce: Annotated[
        Literal["max", "min", "mean"] | None,
        Query(
            description="how cases that share the plotted parameters combine (default: min for min_* "
            "columns, else max: the worst case)"
        ),
    ] = None,
    store: Store = Depends(study_store),
) -> Response:
    """A line per isolator type when the study varies it (one line otherwise) of ``y`` against ``x``;
    with ``x2`` a heat map per isolator type. Sampled studies give scatter plots."""
    row = await run_in_threadpool(_row, store, study_id)
    _require_done(row)
    table = await run_in_threadpool(stored_case_table, store, study_id)
    for param, name in (("y", y), ("x", x), ("x2", x2)):
        if name is not None and name not in table.data:
            raise invalid(
                ["query", param], f"{param}: unknown column {name!r}; columns: {', '.join(table.names)}"
            )
    for param, name in (("x", x), ("x2", x2)):
        if name is not None and name not in table.parameters:
            raise invalid(
                ["query", param],
                f"{param}: {name!r} is not a varied parameter of this study; "
                f"parameters: {', '.join(table.parameters) or 'none'}",
            )
    if table.kinds[y] == "text":
        raise invalid(["query", "y"], f"y: {y!r} is text; choose a numeric output")
    if x2 is not None and x2 == x:
        raise invalid(["query", "x2"], "x2: must differ from x")
    group = (
        "isolator_type" if "isolator_type" in table.parameters and "isolator_type" not in (x, x2) else None
    )
    how = reduce or ("min" if y.startswith("min_") else "max")
    png = await run_heavy(
        request,
        plots.study_png,
        y=plots.Series(y, table.data[y], table.units[y]),
        x=plots.Series(x, table.data[x], table.units[x]),
        x2=plots.Series(x2, table.data[x2], table.units[x2]) if x2 else None,
        group=plots.Series(group, table.data[group], "") if group else None,
        sampled=table.design_kind == "sampled",
        reduce=how,
        title=row["name"],
    )
    return Response(png, media_type="image/png")
