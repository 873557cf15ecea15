"""Where studies live: one netCDF file per study plus a SQLite catalog to find them.

Layout under ``root``::

    catalog.sqlite               the catalog (table ``studies``), WAL mode
    studies/<id>.nc              a finished study's dataset
    studies/<id>.chunks/<k>.npz  results of chunk k of a study still running (removed once the .nc exists)
    studies/<id>.chunks/plan.npz the case indices of every chunk, so a resumed run splits the same way

A study id is a uuid4 hex string (32 lowercase hex digits); every id is checked before it becomes part of a
path, so no path outside ``root`` can be named. Files are written atomically: to a hidden temporary file in
the same directory, flushed and fsynced, then renamed over the target with ``os.replace``; a write that
fails half-way leaves the previous file untouched and removes its temporary file.

The catalog opens a fresh connection per call, so one :class:`Store` can be shared between threads;
listing and filtering run in SQL and never open a netCDF file.

Writing and reading chunks and writing datasets record their durations in the timing journal when one is
configured (see :func:`isolab.studies.timings.record_timing`).
"""

from __future__ import annotations

import builtins
import contextlib
import datetime as _dt
import json
import os
import re
import shutil
import sqlite3
import tempfile
import threading
import time
import uuid
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from isolab.studies.dataset import netcdf_encoding
from isolab.studies.timings import record_timing

STATUSES = ("queued", "running", "done", "failed", "cancelled")
_ID = re.compile(r"[0-9a-f]{32}")
_JSON_COLUMNS = ("parameters", "isolator_types", "definition")
_COLUMNS = (
    "id",
    "name",
    "status",
    "created",
    "started",
    "finished",
    "n_cases",
    "n_done",
    "n_failed",
    "parameters",
    "isolator_types",
    "fidelity",
    "integrator",
    "dt",
    "error",
    "definition",
)
_UPDATABLE = frozenset(_COLUMNS) - {"id", "created"}

_SCHEMA = """
CREATE TABLE IF NOT EXISTS studies (
    id TEXT PRIMARY KEY,
    name TEXT NOT NULL,
    status TEXT NOT NULL CHECK (status IN ('queued', 'running', 'done', 'failed', 'cancelled')),
    created TEXT NOT NULL,
    started TEXT,
    finished TEXT,
    n_cases INTEGER NOT NULL,
    n_done INTEGER NOT NULL DEFAULT 0,
    n_failed INTEGER NOT NULL DEFAULT 0,
    parameters TEXT NOT NULL DEFAULT '[]',
    isolator_types TEXT NOT NULL DEFAULT '[]',
    fidelity TEXT,
    integrator TEXT,
    dt REAL,
    error TEXT,
    definition TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS studies_created ON studies (created);
CREATE INDEX IF NOT EXISTS studies_name ON studies (name);
CREATE INDEX IF NOT EXISTS studies_status ON studies (status);
"""


class StudyNotFound(KeyError):
    """No study with this id in the catalog (or no dataset file for it)."""


def check_id(study_id: str) -> str:
    """``study_id`` if it is 32 lowercase hex digits, else ValueError (it never reaches a path)."""
    if not isinstance(study_id, str) or not _ID.fullmatch(study_id):
        raise ValueError(f"study_id: {study_id!r} is not a study id (32 lowercase hex digits)")
    return study_id


def utc_now() -> str:
    """Current time, ISO 8601 UTC with microseconds (``2025-01-31T12:00:00.000000+00:00``)."""
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="microseconds")


def _utc_text(value: str | _dt.datetime, field: str) -> str:
    """A time as the catalog stores it (ISO 8601 UTC, microseconds); naive times are taken as UTC."""
    if isinstance(value, str):
        try:
            value = _dt.datetime.fromisoformat(value.replace("Z", "+00:00"))
        except ValueError:
            raise ValueError(f"{field}: {value!r} is not an ISO 8601 time") from None
    if not isinstance(value, _dt.datetime):
        raise ValueError(f"{field}: expected an ISO 8601 time or datetime, got {type(value).__name__}")
    if value.tzinfo is None:
        value = value.replace(tzinfo=_dt.UTC)
    return value.astimezone(_dt.UTC).isoformat(timespec="microseconds")


def _fsync_dir(path: Path) -> None:
    with contextlib.suppress(OSError):
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


@contextlib.contextmanager
def atomic_path(target: Path) -> Iterator[Path]:
    """Yield a hidden temporary path next to ``target``; on success fsync it and rename it over ``target``.

    If the body raises, the temporary file is removed and ``target`` is left as it was.
    """
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        with open(tmp, "rb+") as f:
            os.fsync(f.fileno())
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise
    _fsync_dir(target.parent)


NETCDF_LOCK = threading.RLock()
"""Held around every netCDF open, read and write of this process: the netCDF-C and HDF5 libraries are not
thread-safe (two threads in them at once, even on different files, can crash the process), and the
service reads and writes datasets from several threads."""


def write_netcdf(ds: xr.Dataset, path: str | Path) -> Path:
    """Write ``ds`` to ``path`` atomically (see :func:`atomic_path`), with :func:`netcdf_encoding`."""
    path = Path(path)
    with atomic_path(path) as tmp, NETCDF_LOCK:
        ds.to_netcdf(tmp, format="NETCDF4", engine="netcdf4", encoding=netcdf_encoding(ds))
    return path


def copy_atomic(source: str | Path, target: str | Path) -> Path:
    """Copy a file to ``target`` atomically."""
    target = Path(target)
    with atomic_path(target) as tmp:
        shutil.copyfile(source, tmp)
    return target


class Store:
    """netCDF files and the SQLite catalog under ``root`` (created if missing)."""

    def __init__(self, root: str | Path, *, catalog: bool = True):
        """Open (or create) the store under ``root``. With ``catalog=False`` only the files are used (a
        Dask worker that saves chunks and writes datasets): nothing is created, the catalog is not
        opened."""
        self.root = Path(root).resolve()
        self.studies_dir = self.root / "studies"
        self.catalog_path = self.root / "catalog.sqlite"
        if not catalog:
            return
        self.studies_dir.mkdir(parents=True, exist_ok=True)
        with self._connect() as con:
            con.execute("PRAGMA journal_mode=WAL")
            con.executescript(_SCHEMA)
            have = {r["name"] for r in con.execute("PRAGMA table_info(studies)")}
            if "dt" not in have:  # a catalog written before the step was recorded
                con.execute("ALTER TABLE studies ADD COLUMN dt REAL")

    # ------------------------------------------------------------------------------------- catalog
    @contextlib.contextmanager
    def _connect(self) -> Iterator[sqlite3.Connection]:
        con = sqlite3.connect(self.catalog_path, timeout=30.0)
        con.row_factory = sqlite3.Row
        try:
            con.execute("PRAGMA busy_timeout=30000")
            with con:  # commits, or rolls back on error
                yield con
        finally:
            con.close()

    def create(
        self,
        definition: Mapping[str, Any] | str,
        name: str,
        n_cases: int,
        parameters: Sequence[str] = (),
        isolator_types: Sequence[str] = (),
        fidelity: str | None = None,
        integrator: str | None = None,
        dt: float | None = None,
        status: str = "queued",
        created: str | _dt.datetime | None = None,
    ) -> str:
        """Add a study to the catalog; returns its new id (uuid4 hex).

        Args:
            definition: the study definition (JSON-able dict, or a JSON string).
            name: study name.
            n_cases: number of cases, >= 0.
            parameters: names of the varied parameters.
            isolator_types: isolator types the study involves.
            fidelity, integrator, dt: the simulation settings (dt in s); for a study that asks for an
                accuracy instead, None until the runner has chosen them.
            status: initial status (one of STATUSES).
            created: creation time (default now), ISO 8601 or datetime; naive times are UTC.
        """
        if status not in STATUSES:
            raise ValueError(f"status: {status!r} is not one of {', '.join(STATUSES)}")
        if int(n_cases) < 0:
            raise ValueError(f"n_cases: {n_cases} is negative")
        study_id = uuid.uuid4().hex
        row = {
            "id": study_id,
            "name": str(name),
            "status": status,
            "created": utc_now() if created is None else _utc_text(created, "created"),
            "n_cases": int(n_cases),
            "n_done": 0,
            "n_failed": 0,
            "parameters": json.dumps(list(parameters)),
            "isolator_types": json.dumps(list(isolator_types)),
            "fidelity": fidelity,
            "integrator": integrator,
            "dt": None if dt is None else float(dt),
            "definition": (definition if isinstance(definition, str) else json.dumps(definition)),
        }
        cols = ", ".join(row)
        marks = ", ".join("?" for _ in row)
        with self._connect() as con:
            con.execute(f"INSERT INTO studies ({cols}) VALUES ({marks})", tuple(row.values()))
        return study_id

    def get(self, study_id: str) -> dict[str, Any]:
        """The catalog row of a study (JSON columns decoded). Raises StudyNotFound."""
        check_id(study_id)
        with self._connect() as con:
            row = con.execute("SELECT * FROM studies WHERE id = ?", (study_id,)).fetchone()
        if row is None:
            raise StudyNotFound(study_id)
        return _decode(row)

    def update(self, study_id: str, **fields: Any) -> None:
        """Set catalog fields of a study (any column but id and created). Raises StudyNotFound.

        Lists/dicts for ``parameters``, ``isolator_types`` and ``definition`` are stored as JSON; times
        (``started``, ``finished``) may be datetimes or ISO 8601 strings.
        """
        check_id(study_id)
        if not fields:
            return
        unknown = sorted(set(fields) - _UPDATABLE)
        if unknown:
            raise ValueError(f"{unknown[0]}: not a catalog field that can be updated")
        if "status" in fields and fields["status"] not in STATUSES:
            raise ValueError(f"status: {fields['status']!r} is not one of {', '.join(STATUSES)}")
        values = {}
        for key, value in fields.items():
            if key in _JSON_COLUMNS and not isinstance(value, str):
                value = json.dumps(value)
            elif key in ("started", "finished") and value is not None:
                value = _utc_text(value, key)
            values[key] = value
        sets = ", ".join(f"{k} = ?" for k in values)
        with self._connect() as con:
            cur = con.execute(f"UPDATE studies SET {sets} WHERE id = ?", (*values.values(), study_id))
            if cur.rowcount == 0:
                raise StudyNotFound(study_id)

    def list(
        self,
        name: str | None = None,
        status: str | None = None,
        isolator_type: str | None = None,
        created_after: str | _dt.datetime | None = None,
        created_before: str | _dt.datetime | None = None,
        limit: int = 50,
        offset: int = 0,
    ) -> builtins.list[dict[str, Any]]:
        """Catalog rows, newest first, filtered in SQL.

        Args:
            name: exact study name.
            status: one of STATUSES.
            isolator_type: studies whose ``isolator_types`` include it.
            created_after, created_before: creation time bounds (inclusive), ISO 8601 or datetime.
            limit: at most this many rows (1..1000); offset: skip this many first.
        """
        where, args = self._where(name, status, isolator_type, created_after, created_before)
        if not 1 <= int(limit) <= 1000:
            raise ValueError(f"limit: {limit} is outside 1..1000")
        if int(offset) < 0:
            raise ValueError(f"offset: {offset} is negative")
        sql = f"SELECT * FROM studies{where} ORDER BY created DESC, rowid DESC LIMIT ? OFFSET ?"
        with self._connect() as con:
            rows = con.execute(sql, (*args, int(limit), int(offset))).fetchall()
        return [_decode(r) for r in rows]

    def count(
        self,
        name: str | None = None,
        status: str | None = None,
        isolator_type: str | None = None,
        created_after: str | _dt.datetime | None = None,
        created_before: str | _dt.datetime | None = None,
    ) -> int:
        """Number of catalog rows matching the same filters as :meth:`list`."""
        where, args = self._where(name, status, isolator_type, created_after, created_before)
        with self._connect() as con:
            return int(con.execute(f"SELECT COUNT(*) FROM studies{where}", args).fetchone()[0])

    @staticmethod
    def _where(name, status, isolator_type, created_after, created_before) -> tuple[str, tuple]:
        clauses: list[str] = []
        args: list[Any] = []
        if name is not None:
            clauses.append("name = ?")
            args.append(str(name))
        if status is not None:
            if status not in STATUSES:
                raise ValueError(f"status: {status!r} is not one of {', '.join(STATUSES)}")
            clauses.append("status = ?")
            args.append(status)
        if isolator_type is not None:
            clauses.append(
                "EXISTS (SELECT 1 FROM json_each(studies.isolator_types) WHERE json_each.value = ?)"
            )
            args.append(str(isolator_type))
        if created_after is not None:
            clauses.append("created >= ?")
            args.append(_utc_text(created_after, "created_after"))
        if created_before is not None:
            clauses.append("created <= ?")
            args.append(_utc_text(created_before, "created_before"))
        return (" WHERE " + " AND ".join(clauses) if clauses else ""), tuple(args)

    def delete(self, study_id: str) -> bool:
        """Remove a study's catalog row, dataset file and chunks. False if there was nothing to remove."""
        check_id(study_id)
        with self._connect() as con:
            found = con.execute("DELETE FROM studies WHERE id = ?", (study_id,)).rowcount > 0
        path = self.path(study_id)
        if path.exists():
            path.unlink()
            found = True
        chunk_dir = self.chunk_dir(study_id)
        if chunk_dir.exists():
            shutil.rmtree(chunk_dir)
            found = True
        return found

    # --------------------------------------------------------------------------------------- files
    def path(self, study_id: str) -> Path:
        """Path of a study's netCDF file (whether or not it exists)."""
        return self.studies_dir / f"{check_id(study_id)}.nc"

    def write_dataset(self, study_id: str, ds: xr.Dataset) -> Path:
        """Write a study's dataset atomically to :meth:`path`."""
        t0 = time.perf_counter()
        path = write_netcdf(ds, self.path(study_id))
        record_timing(
            "write_dataset", study_id=study_id, seconds=time.perf_counter() - t0, bytes=path.stat().st_size
        )
        return path

    def open_dataset(self, study_id: str) -> xr.Dataset:
        """A study's dataset, loaded into memory (the file is closed again). Raises StudyNotFound."""
        path = self.path(study_id)
        if not path.exists():
            raise StudyNotFound(study_id)
        with NETCDF_LOCK, xr.open_dataset(path) as ds:
            return ds.load()

    def dataset_ids(self) -> builtins.list[str]:
        """Ids of the studies that have a dataset file, sorted."""
        return sorted(p.stem for p in self.studies_dir.glob("*.nc") if _ID.fullmatch(p.stem))

    # -------------------------------------------------------------------------------------- chunks
    def chunk_dir(self, study_id: str) -> Path:
        """Directory of a study's per-chunk results."""
        return self.studies_dir / f"{check_id(study_id)}.chunks"

    def save_chunk(self, study_id: str, chunk_index: int, arrays: Mapping[str, np.ndarray]) -> Path:
        """Save one chunk's result arrays atomically as ``<id>.chunks/<k>.npz`` (no pickled objects)."""
        k = _chunk_index(chunk_index)
        path = self.chunk_dir(study_id) / f"{k}.npz"
        t0 = time.perf_counter()
        _save_npz(path, arrays)
        record_timing(
            "save_chunk",
            study_id=study_id,
            chunk=k,
            seconds=time.perf_counter() - t0,
            bytes=path.stat().st_size,
        )
        return path

    def load_chunks(self, study_id: str) -> dict[int, dict[str, np.ndarray]]:
        """Every saved chunk of a study: chunk index -> arrays."""
        t0 = time.perf_counter()
        out: dict[int, dict[str, np.ndarray]] = {}
        for k in self.done_chunks(study_id):
            with np.load(self.chunk_dir(study_id) / f"{k}.npz", allow_pickle=False) as z:
                out[k] = {name: z[name] for name in z.files}
        record_timing("load_chunks", study_id=study_id, n_chunks=len(out), seconds=time.perf_counter() - t0)
        return out

    def done_chunks(self, study_id: str) -> set[int]:
        """Indices of the chunks of a study whose results are saved."""
        d = self.chunk_dir(study_id)
        if not d.is_dir():
            return set()
        return {int(p.stem) for p in d.glob("*.npz") if p.stem.isdigit()}

    def save_chunk_plan(self, study_id: str, chunks: Sequence[np.ndarray]) -> None:
        """Save how a study's cases are split into chunks (so a resumed run splits them the same way)."""
        _save_npz(
            self.chunk_dir(study_id) / "plan.npz",
            {f"c{k}": np.asarray(c, dtype=np.int64) for k, c in enumerate(chunks)},
        )

    def has_chunk_plan(self, study_id: str) -> bool:
        """Whether this process sees the saved chunk split of a study: a Dask worker that does shares the
        store with the runner, and saves chunks and writes the dataset itself."""
        return (self.chunk_dir(study_id) / "plan.npz").is_file()

    def load_chunk_plan(self, study_id: str) -> builtins.list[np.ndarray] | None:
        """The saved chunk split of a study, or None."""
        path = self.chunk_dir(study_id) / "plan.npz"
        if not path.exists():
            return None
        with np.load(path, allow_pickle=False) as z:
            return [z[f"c{k}"] for k in range(len(z.files))]

    def clear_chunks(self, study_id: str) -> None:
        """Remove a study's per-chunk results and plan."""
        d = self.chunk_dir(study_id)
        if d.exists():
            t0 = time.perf_counter()
            shutil.rmtree(d)
            record_timing("clear_chunks", study_id=study_id, seconds=time.perf_counter() - t0)


def _chunk_index(k: Any) -> int:
    if isinstance(k, bool) or not isinstance(k, int | np.integer) or int(k) < 0:
        raise ValueError(f"chunk_index: {k!r} is not a non-negative integer")
    return int(k)


def _save_npz(path: Path, arrays: Mapping[str, np.ndarray]) -> None:
    checked = {}
    for name, value in arrays.items():
        a = np.asarray(value)
        if a.dtype.kind == "O":
            raise ValueError(f"arrays[{name!r}]: object arrays cannot be saved; use a numeric or str dtype")
        checked[str(name)] = a
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        np.savez(f, **checked)  # type: ignore[arg-type]  # numpy's stub types the keywords as flags


def _decode(row: sqlite3.Row) -> dict[str, Any]:
    out = {k: row[k] for k in row.keys()}  # noqa: SIM118 (sqlite3.Row)
    for key in _JSON_COLUMNS:
        if out.get(key) is not None:
            out[key] = json.loads(out[key])
    return out
