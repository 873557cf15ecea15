"""Study results as a labelled, CF-described xarray dataset.

A study's cases come back from the engine as one :class:`~engine.results.SimulationResult` (case
dimension first). :func:`to_dataset` lays them out along the study's design: a grid gets one dimension per
varied parameter with its levels as the coordinate (``ds.sel(isolator_type="air", stage_y_mass=1000)``); a
sampled design gets a ``case`` dimension with each parameter as a coordinate along it. The per-case
outputs are the output catalogue's (:data:`isolab.engine.results.OUTPUTS`: name, dimensions, unit and long
name, in its order); they add the dimensions ``axis`` (x, y, z), ``rotation`` (rx, ry, rz: about X pitch,
Y roll, Z yaw), ``isolator``, ``point``, ``mode`` (1..6) and ``dof``.

Every variable and coordinate carries CF ``units`` and ``long_name`` (``"1"`` for dimensionless quantities
and labels); a numeric parameter's coordinate also carries ``display_units`` (the unit the study was written
in, ``"g"`` or ``"%"``, while ``units`` stays SI) and ``scale`` (``linear`` or ``log``), which figures follow.
A case whose ``status`` is not OK has missing values (NaN; ``_FillValue`` on disk) in every
numeric output, never numbers; ``status`` (CF ``flag_values``/``flag_meanings``) and ``message`` say why.
Yes/no outputs (``liftoff``, ``settled``, ``mechanism``) are float32 in memory (1.0 yes, 0.0 no, NaN
missing) and int8 with ``_FillValue`` -1 on disk, so they too can be missing (the store writes them:
:func:`isolab.studies.results.store.netcdf_encoding`).

Results that arrive in chunks (see :mod:`studies.run.fanout`) travel as plain dicts of numpy arrays
(:func:`result_arrays`) and are put back together in case order by :func:`from_chunks`, or, for a study's
stored dataset, read one block of chunks at a time as the file is written
(:func:`isolab.studies.results.streaming.streamed_dataset`: the same dataset, whose memory does not grow with
the number of cases).
"""

from __future__ import annotations

import datetime as _dt
import json
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from isolab.engine.results import (
    AXES,
    DOF_NAMES,
    FAILED,
    FLAG_FIELDS,
    N_MODES,
    OK,
    OUTPUT_FIELDS,
    OUTPUTS,
    ROTATIONS,
    STATUS_NAMES,
    SimulationResult,
    output_shape,
)
from isolab.studies.questions.designs import Design

if TYPE_CHECKING:  # xarray and dask load with the first dataset built: a single case needs neither
    import xarray as xr
CONVENTIONS = "CF-1.10"

_BOOL_ENCODING = {"dtype": "int8", "_FillValue": np.int8(-1)}
_BOOL_FLAGS = {"flag_values": np.array([0, 1], dtype=np.int8), "flag_meanings": "false true"}


# --------------------------------------------------------------------------------------------- chunks
def result_arrays(result: SimulationResult) -> dict[str, np.ndarray]:
    """The per-case outputs of ``result`` as a dict of plain numpy arrays (no pickled objects).

    Keys: ``status`` (int8), ``message`` (unicode array) and every per-case output
    (:data:`~isolab.engine.results.OUTPUT_FIELDS`: bool for the yes/no ones, float64 for the others).
    Time histories are not carried.
    """
    out: dict[str, np.ndarray] = {
        "status": np.asarray(result.status, dtype=np.int8),
        "message": np.asarray([str(m) for m in result.message], dtype=np.str_).reshape(-1),
    }
    for name in OUTPUT_FIELDS:
        out[name] = np.asarray(getattr(result, name), dtype=bool if name in FLAG_FIELDS else np.float64)
    return out


def failed_arrays(n_cases: int, message: str) -> dict[str, np.ndarray]:
    """Arrays of ``n_cases`` FAILED cases that all carry ``message`` (the outputs are left out: missing)."""
    return {
        "status": np.full(n_cases, FAILED, dtype=np.int8),
        "message": np.array([str(message)] * int(n_cases), dtype=np.str_).reshape(-1),
    }


def from_chunks(
    parts: Mapping[int, Mapping[str, np.ndarray]],
    chunks: Sequence[np.ndarray],
    *,
    n_isolators: int,
    n_points: int,
) -> SimulationResult:
    """Assemble the full result, in case order, from per-chunk arrays.

    Args:
        parts: chunk index ``k`` -> arrays of the cases ``chunks[k]`` (as from :func:`result_arrays`);
            an output a chunk lacks (a chunk whose task failed carries only ``status`` and ``message``)
            is missing for its cases.
        chunks: the case indices of each chunk; together they must cover ``0..N-1`` exactly once.
        n_isolators, n_points: scene shape, to size outputs no chunk carries.

    Raises:
        ValueError: a chunk is missing from ``parts``, the chunks do not partition the cases, or a chunk's
            arrays do not match its size.
    """
    missing = [k for k in range(len(chunks)) if k not in parts]
    if missing:
        raise ValueError(f"parts: chunks {missing} have no results")
    n = int(sum(len(c) for c in chunks))
    all_idx = np.concatenate([np.asarray(c, dtype=np.int64) for c in chunks]) if chunks else np.zeros(0, int)
    if not np.array_equal(np.sort(all_idx), np.arange(n)):
        raise ValueError("chunks: the chunks must cover the cases 0..N-1 exactly once")

    status = np.full(n, FAILED, dtype=np.int8)
    message = [""] * n
    fields: dict[str, np.ndarray] = {}
    for name in OUTPUT_FIELDS:
        trail = output_shape(name, n_isolators, n_points)
        fields[name] = (
            np.zeros((n, *trail), dtype=bool) if name in FLAG_FIELDS else np.full((n, *trail), np.nan)
        )

    for k, idx in enumerate(chunks):
        idx = np.asarray(idx, dtype=np.int64)
        part = chunk_result(parts[k], idx, n_isolators=n_isolators, n_points=n_points, chunk_index=k)
        status[idx] = part.status
        for i, m in zip(idx.tolist(), part.message, strict=True):
            message[i] = m
        for name in OUTPUT_FIELDS:
            if name in parts[k]:
                fields[name][idx] = getattr(part, name)
    return SimulationResult(status=status, message=message, **fields)  # type: ignore[arg-type]


def chunk_result(
    arrays: Mapping[str, np.ndarray],
    indices: np.ndarray,
    *,
    n_isolators: int,
    n_points: int,
    chunk_index: int = 0,
) -> SimulationResult:
    """One chunk's result from its arrays (as from :func:`result_arrays`), for the cases ``indices``; an
    output the arrays lack is missing (NaN, or False for yes/no; the chunk's status is then not OK).

    Raises:
        ValueError: the arrays do not match the chunk's size, or were computed for other cases
            (``parts[<chunk_index>]: ...``).
    """
    k = chunk_index
    idx = np.asarray(indices, dtype=np.int64)
    st = np.asarray(arrays["status"], dtype=np.int8)
    if st.shape != (len(idx),):
        raise ValueError(
            f"parts[{k}]: status has {st.shape[0] if st.ndim else 0} cases, the chunk has {len(idx)}"
        )
    if "indices" in arrays and not np.array_equal(np.asarray(arrays["indices"]), idx):
        raise ValueError(f"parts[{k}]: computed for other cases than chunk {k} holds")
    fields: dict[str, np.ndarray] = {}
    for name in OUTPUT_FIELDS:
        want = (len(idx), *output_shape(name, n_isolators, n_points))
        if name in arrays:
            v = np.asarray(arrays[name])
            if v.shape != want:
                raise ValueError(f"parts[{k}]: {name} has shape {v.shape}, expected {want}")
            fields[name] = v.astype(bool if name in FLAG_FIELDS else np.float64, copy=False)
        else:
            fields[name] = np.zeros(want, dtype=bool) if name in FLAG_FIELDS else np.full(want, np.nan)
    message = [str(m) for m in np.asarray(arrays["message"]).reshape(-1).tolist()]
    if len(message) != len(idx):
        raise ValueError(f"parts[{k}]: message has {len(message)} cases, the chunk has {len(idx)}")
    return SimulationResult(status=st, message=message, **fields)  # type: ignore[arg-type]


# -------------------------------------------------------------------------------------------- dataset
def design_summary(design: Design) -> dict[str, Any]:
    """JSON-able description of a design: kind, names, paths, units, shape and (grid) levels."""
    out: dict[str, Any] = {
        "kind": design.kind,
        "names": list(design.names),
        "paths": {n: design.paths.get(n, "") for n in design.names},
        "units": {n: design.units.get(n, "") for n in design.names},
        "n_cases": design.n_cases,
    }
    if design.kind == "grid":
        out["levels"] = {n: np.asarray(design.levels[n]).tolist() for n in design.names}
    return out


def to_dataset(
    result: SimulationResult,
    design: Design,
    *,
    isolator_names: Sequence[str],
    point_names: Sequence[str],
    attrs: Mapping[str, Any] | None = None,
) -> xr.Dataset:
    """Lay the per-case outputs of ``result`` out along ``design`` as a CF-described dataset.

    Args:
        result: outputs of ``design.n_cases`` cases, in the design's case order.
        design: the study's design (grid: one dimension per parameter; sampled: a ``case`` dimension).
        isolator_names: labels of the ``isolator`` dimension (one per isolator of the scene).
        point_names: labels of the ``point`` dimension (one per point of interest).
        attrs: dataset attributes, passed through (dicts and lists become JSON strings, booleans 0/1,
            None is left out). ``design`` given as a dict is merged into the design summary (e.g. the
            seed of a sampled design). Expected: title, study (the definition), engine_version, fidelity,
            integrator, dt. ``Conventions``, ``created`` (ISO 8601 UTC), ``history`` filled unless given.

    Raises:
        ValueError: sizes disagree, a grid cell is missing or repeated, or a parameter name clashes with
            a dimension or variable name.
    """
    import xarray as xr

    n = result.n_cases
    if design.n_cases != n:
        raise ValueError(f"result: {n} cases, but the design has {design.n_cases}")
    n_iso, n_pts = len(isolator_names), len(point_names)
    if np.shape(result.static_isolator_load)[1:] != (n_iso,):
        raise ValueError(
            f"isolator_names: {n_iso} names for {np.shape(result.static_isolator_load)[1:]} "
            "isolators in the result"
        )
    if np.shape(result.peak_point_displacement)[1:2] != (n_pts,):
        raise ValueError(
            f"point_names: {n_pts} names for {np.shape(result.peak_point_displacement)[1]} "
            "points in the result"
        )
    check_parameter_names(design)

    case_dims, case_coords, order = case_layout(design)
    case_shape = tuple(len(case_coords[d][1]) for d in case_dims) if design.kind == "grid" else (n,)

    in_order = np.array_equal(order, np.arange(len(order)))  # a sampled design: no copy to lay out

    def lay_out(a: np.ndarray) -> np.ndarray:
        a = np.asarray(a)
        return (a if in_order else a[order]).reshape(case_shape + a.shape[1:])

    data_vars = _case_variables(result, case_dims, lay_out)
    coords: dict[str, xr.Variable] = {
        name: xr.Variable(dims, values, attrs=a) for name, (dims, values, a) in case_coords.items()
    }
    coords.update(_fixed_coords(isolator_names, point_names))
    ds = xr.Dataset(data_vars, coords=coords)
    ds.attrs = dataset_attrs(design, attrs or {})
    return ds


def check_parameter_names(design: Design) -> None:
    reserved = set(OUTPUTS) | {
        "status",
        "message",
        "axis",
        "rotation",
        "isolator",
        "point",
        "mode",
        "dof",
        "case",
    }
    for name in design.names:
        if name in reserved:
            raise ValueError(f"design.names: parameter {name!r} clashes with a dataset dimension or variable")


def chunk_dataset(
    arrays: Mapping[str, np.ndarray],
    indices: np.ndarray,
    *,
    isolator_names: Sequence[str],
    point_names: Sequence[str],
    criteria: Any = None,
    chunk_index: int = 0,
) -> xr.Dataset:
    """One chunk's cases as a dataset along a ``case`` dimension (no case coordinates, no dataset
    attributes): every per-case variable :func:`to_dataset` stores, with the same values, attributes and
    encodings, plus ``criterion_margin`` and ``meets_criteria`` for a ``criteria`` block
    (:func:`studies.questions.criteria.add_criteria`). ``arrays`` and ``indices`` are as :func:`chunk_result`
    takes them."""
    import xarray as xr

    from isolab.studies.questions.criteria import add_criteria

    result = chunk_result(
        arrays,
        indices,
        n_isolators=len(isolator_names),
        n_points=len(point_names),
        chunk_index=chunk_index,
    )
    ds = xr.Dataset(
        _case_variables(result, ("case",), np.asarray), coords=_fixed_coords(isolator_names, point_names)
    )
    return add_criteria(ds, criteria)


def _case_variables(
    result: SimulationResult, case_dims: tuple[str, ...], lay_out: Callable[[np.ndarray], np.ndarray]
) -> dict[str, xr.Variable]:
    """Every per-case variable of ``result`` (outputs, ``status``, ``message``) along ``case_dims``, each
    array put there by ``lay_out`` (case order in, the case dimensions' layout out). Outputs of a case
    whose status is not OK are NaN."""
    import xarray as xr

    bad = ~np.asarray(result.status == OK)
    data_vars: dict[str, xr.Variable] = {}
    for name, spec in OUTPUTS.items():  # the catalogue's outputs, in its order
        raw = spec.values(result)
        masked = raw.astype(np.float32) if spec.flag else raw.astype(np.float64, copy=True)
        masked[bad] = np.nan
        var_attrs: dict[str, Any] = {"units": spec.unit, "long_name": spec.long_name}
        if spec.flag:
            var_attrs.update(_BOOL_FLAGS)
        var = xr.Variable(case_dims + spec.dims, lay_out(masked), attrs=var_attrs)
        if spec.flag:
            var.encoding = dict(_BOOL_ENCODING)
        data_vars[name] = var

    data_vars["status"] = xr.Variable(
        case_dims,
        lay_out(np.asarray(result.status, dtype=np.int8)),
        attrs={
            "units": "1",
            "long_name": "outcome of the case",
            "flag_values": np.arange(len(STATUS_NAMES), dtype=np.int8),
            "flag_meanings": " ".join(STATUS_NAMES),
        },
    )
    data_vars["message"] = xr.Variable(
        case_dims,
        lay_out(np.asarray([str(m) for m in result.message], dtype=np.str_).reshape(-1)),
        attrs={"units": "1", "long_name": "why the case is not ok (empty when ok)"},
    )

    return data_vars


def _fixed_coords(isolator_names: Sequence[str], point_names: Sequence[str]) -> dict[str, xr.Variable]:
    """The coordinates of the per-case dimensions: axis, rotation, isolator, point, mode, dof."""
    import xarray as xr

    coords: dict[str, xr.Variable] = {}
    coords["axis"] = xr.Variable("axis", np.array(AXES), {"units": "1", "long_name": "floor axis (Z up)"})
    coords["rotation"] = xr.Variable(
        "rotation",
        np.array(ROTATIONS),
        {"units": "1", "long_name": "rotation axis: rx about X (pitch), ry about Y (roll), rz about Z (yaw)"},
    )
    coords["isolator"] = xr.Variable(
        "isolator",
        np.array([str(s) for s in isolator_names], dtype=np.str_).reshape(-1),
        {"units": "1", "long_name": "isolator"},
    )
    coords["point"] = xr.Variable(
        "point",
        np.array([str(s) for s in point_names], dtype=np.str_).reshape(-1),
        {"units": "1", "long_name": "point of interest"},
    )
    coords["mode"] = xr.Variable(
        "mode",
        np.arange(1, N_MODES + 1, dtype=np.int32),
        {"units": "1", "long_name": "vibration mode number, by ascending natural frequency"},
    )
    coords["dof"] = xr.Variable(
        "dof",
        np.array(DOF_NAMES),
        {
            "units": "1",
            "long_name": "degree of freedom of the base: c.g. translation x, y, z; rotation rx, ry, rz",
        },
    )
    return coords


def case_layout(design: Design):
    """Dimensions, coordinates and case order of the design.

    Returns (case_dims, coords, order): ``coords`` maps a coordinate name to (dims, values, attrs);
    ``order[j]`` is the case stored at flat position ``j`` of the case dimensions.
    """
    n = design.n_cases
    coords: dict[str, tuple[tuple[str, ...], np.ndarray, dict]] = {}

    def param_attrs(name: str, values: np.ndarray) -> dict:
        unit = design.units.get(name, "") or "1"
        path = design.paths.get(name, "")
        long_name = f"study parameter {name}" + (f" (sets {path})" if path else "")
        if values.dtype.kind in "USO":
            return {"units": "1", "long_name": long_name}
        # what figures show it in: the unit it was written in (CF units stay SI) and its range's scale
        shown = design.display_units.get(name) or unit
        return {
            "units": unit,
            "long_name": long_name,
            "display_units": shown,
            "scale": design.scales.get(name, "linear"),
        }

    if design.kind == "grid":
        dims = tuple(design.names)
        shape = design.shape
        if not dims:
            return (), coords, np.zeros(1, dtype=np.int64)
        index = []
        for name in design.names:
            levels = _labels(np.asarray(design.levels[name]))
            values = _labels(np.asarray(design.values[name]))
            lookup = {v: i for i, v in enumerate(levels.tolist())}
            if len(lookup) != len(levels):
                raise ValueError(f"design.levels[{name!r}]: levels repeat")
            try:
                index.append(np.array([lookup[v] for v in values.tolist()], dtype=np.int64))
            except KeyError as err:
                raise ValueError(
                    f"design.values[{name!r}]: value {err.args[0]!r} is not one of its levels"
                ) from None
            coords[name] = ((name,), levels, param_attrs(name, levels))
        flat = np.ravel_multi_index(tuple(index), shape)
        cells = int(np.prod(shape))
        if n != cells or len(np.unique(flat)) != n:
            raise ValueError(f"design: {n} cases do not fill the {shape} grid once each")
        order = np.empty(n, dtype=np.int64)
        order[flat] = np.arange(n)
        return dims, coords, order
    if design.kind == "sampled":
        coords["case"] = (("case",), np.arange(n, dtype=np.int64), {"units": "1", "long_name": "case number"})
        for name in design.names:
            values = _labels(np.asarray(design.values[name]))
            coords[name] = (("case",), values, param_attrs(name, values))
        return ("case",), coords, np.arange(n, dtype=np.int64)
    raise ValueError(f"design.kind: {design.kind!r} is neither 'grid' nor 'sampled'")


def _labels(values: np.ndarray) -> np.ndarray:
    """Categorical values as a unicode array; numbers as float64 (int64 if all integral ints)."""
    if values.dtype.kind in "USO":
        return values.astype(np.str_)
    if values.dtype.kind in "iu":
        return values.astype(np.int64)
    if values.dtype.kind == "b":
        return values.astype(np.int8)
    return values.astype(np.float64)


def dataset_attrs(design: Design, attrs: Mapping[str, Any]) -> dict[str, Any]:
    created = _dt.datetime.now(_dt.UTC).replace(microsecond=0).isoformat().replace("+00:00", "Z")
    summary = design_summary(design)
    given = dict(attrs)
    extra_design = given.pop("design", None)
    if isinstance(extra_design, Mapping):
        summary.update(extra_design)
    elif isinstance(extra_design, str):
        summary.update(json.loads(extra_design))
    created = str(given.get("created", created))
    out: dict[str, Any] = {
        "Conventions": CONVENTIONS,
        "title": "isolab study",
        "history": f"{created} created by isolab",
        "created": created,
        "design": summary,
    }
    out.update(given)
    return {k: v for k, v in ((k, netcdf_attr(v)) for k, v in out.items()) if v is not None}


def netcdf_attr(value: Any) -> Any:
    """A value netCDF can hold as an attribute: dicts/lists as JSON, booleans as 0/1, datetimes ISO 8601."""
    if value is None:
        return None
    if isinstance(value, bool | np.bool_):
        return int(value)
    if isinstance(value, _dt.datetime):
        return value.isoformat()
    if isinstance(value, Mapping | list | tuple):
        return json.dumps(value, default=_json_default)
    if isinstance(value, np.generic):
        return value.item()
    return value


def _json_default(value: Any) -> Any:
    if isinstance(value, np.ndarray | np.generic):
        return value.tolist()
    if isinstance(value, _dt.datetime):
        return value.isoformat()
    return str(value)


# ------------------------------------------------------------------------------------- error estimate
ERROR_ESTIMATE_PREFIX = "error_estimate_"


def add_error_estimate(
    ds: xr.Dataset,
    values: Mapping[str, float],
    *,
    worst_case: Mapping[str, int | None],
    cases: Sequence[int],
    excluded: Mapping[int, str],
    method: str,
    meaning: Mapping[str, str],
    units: Mapping[str, str],
) -> xr.Dataset:
    """``ds`` with the study's measured error: one scalar variable ``error_estimate_<output>`` per output
    (``units``, ``long_name`` from ``meaning``, ``case``: the study case where the largest error was found,
    -1 when none could be compared) and the attributes ``error_estimate_cases`` (the sampled cases),
    ``error_estimate_excluded`` (case -> why it could not be compared) and ``error_estimate_method``.
    A NaN value means no sampled case could be compared."""
    out = ds.copy()
    for name, value in values.items():
        case = worst_case.get(name)
        out[ERROR_ESTIMATE_PREFIX + name] = (  # (dimensions, value, attributes): a variable
            (),
            np.float64(value),
            {
                "units": units.get(name, "1"),
                "long_name": f"{meaning.get(name, name)}, over the sampled cases against the reference level",
                "case": np.int64(-1 if case is None else case),
            },
        )
    out.attrs["error_estimate_cases"] = json.dumps([int(c) for c in cases])
    out.attrs["error_estimate_excluded"] = json.dumps({str(int(k)): str(v) for k, v in excluded.items()})
    out.attrs["error_estimate_method"] = str(method)
    return out


def error_estimate(ds: xr.Dataset) -> dict[str, float]:
    """The measured error a stored study carries: output -> largest error found (see
    :func:`add_error_estimate`); empty for a dataset without one."""
    return {
        str(name)[len(ERROR_ESTIMATE_PREFIX) :]: float(ds[name])
        for name in ds.data_vars
        if str(name).startswith(ERROR_ESTIMATE_PREFIX)
    }
