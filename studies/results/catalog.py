"""The catalog of studies: one SQLite table (``studies``) with a row per study, to find them.

A row holds what a listing needs (name, status, times, case counts, varied parameters, isolator types,
the model the cases ran with, an optimisation's finished and planned generations) and the study's stored
definition, and reads back as a :class:`~isolab.studies.results.records.StudyRecord`; the results themselves
are files (see :mod:`isolab.studies.results.store`). The catalog opens a
fresh connection per call, so one :class:`Catalog` can be shared between threads; listing and filtering
run in SQL. The database is in WAL mode, and opening it adds the columns an older catalog lacks
(migrations).
"""

from __future__ import annotations

import builtins
import contextlib
import datetime as _dt
import json
import re
import sqlite3
import uuid
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

from isolab.studies.results.records import COLUMNS, JSON_COLUMNS, StudyFilter, StudyRecord

CATALOG_FILE = "catalog.sqlite"
"""File name of the catalog under a store's root."""
STATUSES = ("queued", "running", "done", "failed", "cancelled")
STUDY_ID = re.compile(r"[0-9a-f]{32}")
"""A study id: a uuid4 hex string, 32 lowercase hex digits."""
_UPDATABLE = frozenset(COLUMNS) - {"id", "created"}

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
    definition TEXT NOT NULL,
    generation INTEGER,
    generations INTEGER
);
CREATE INDEX IF NOT EXISTS studies_created ON studies (created);
CREATE INDEX IF NOT EXISTS studies_name ON studies (name);
CREATE INDEX IF NOT EXISTS studies_status ON studies (status);
"""


class StudyNotFound(KeyError):
    """No study with this id in the catalog (or no dataset file for it)."""


class CatalogUnavailable(RuntimeError):
    """The catalog cannot be read or written just now (a full disk, an I/O error, a lock held too long);
    the message says why. The service answers 503 with it: try again once the cause is gone."""


# SQLite's words for a catalog that cannot be used now (as opposed to a mistake in a query)
_UNAVAILABLE = ("disk", "full", "i/o", "locked", "unable to open", "readonly")


def check_id(study_id: str) -> str:
    """``study_id`` if it is 32 lowercase hex digits, else ValueError (it never reaches a path)."""
    if not isinstance(study_id, str) or not STUDY_ID.fullmatch(study_id):
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


class Catalog:
    """The SQLite catalog at ``path`` (created, or migrated, when opened)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        with self._connect() as con:
            con.execute("PRAGMA journal_mode=WAL")
            con.executescript(_SCHEMA)
            have = {r["name"] for r in con.execute("PRAGMA table_info(studies)")}
            if "dt" not in have:  # a catalog written before the step was recorded
                con.execute("ALTER TABLE studies ADD COLUMN dt REAL")
            for column in ("generation", "generations"):  # optimisations' progress (null for other designs)
                if column not in have:
                    con.execute(f"ALTER TABLE studies ADD COLUMN {column} INTEGER")
        # One connection stays open (idle) for the catalog's life: SQLite deletes the WAL index
        # (``catalog.sqlite-shm``) when its last connection closes and must allocate it again at the
        # next open, which fails on a full disk and then takes every read down with it. Held open, the
        # index stays allocated and reads keep working while the disk is full.
        self._keeper: sqlite3.Connection | None = sqlite3.connect(self.path, check_same_thread=False)
        self._keeper.execute("SELECT COUNT(*) FROM studies").fetchall()

    def close(self) -> None:
        """Close the connection the catalog holds open (the per-call ones are closed already)."""
        if self._keeper is not None:
            self._keeper.close()
            self._keeper = None

    @contextlib.contextmanager
    def _connect(self) -> Iterator[sqlite3.Connection]:
        try:
            con = sqlite3.connect(self.path, timeout=30.0)
        except sqlite3.OperationalError as err:
            raise _unavailable(self.path, err) from err
        con.row_factory = sqlite3.Row
        try:
            con.execute("PRAGMA busy_timeout=30000")
            with con:  # commits, or rolls back on error
                yield con
        except sqlite3.OperationalError as err:
            if any(word in str(err).lower() for word in _UNAVAILABLE):
                raise _unavailable(self.path, err) from err
            raise
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

    def get(self, study_id: str) -> StudyRecord:
        """The catalog record of a study. Raises StudyNotFound."""
        check_id(study_id)
        with self._connect() as con:
            row = con.execute("SELECT * FROM studies WHERE id = ?", (study_id,)).fetchone()
        if row is None:
            raise StudyNotFound(study_id)
        return _record(row)

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
            if key in JSON_COLUMNS and not isinstance(value, str):
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
        self, where: StudyFilter | None = None, *, limit: int = 50, offset: int = 0
    ) -> builtins.list[StudyRecord]:
        """Catalog records, newest first, filtered in SQL (``where``: every filter given must hold).

        Args:
            where: the filters (see :class:`StudyFilter`); None lists every study.
            limit: at most this many records (1..1000); offset: skip this many first.

        Raises:
            ValueError: ``<field>: reason`` for a status or time that is not one, or a limit or offset out
                of range.
        """
        clauses, args = self._where(where or StudyFilter())
        if not 1 <= int(limit) <= 1000:
            raise ValueError(f"limit: {limit} is outside 1..1000")
        if int(offset) < 0:
            raise ValueError(f"offset: {offset} is negative")
        sql = f"SELECT * FROM studies{clauses} ORDER BY created DESC, rowid DESC LIMIT ? OFFSET ?"
        with self._connect() as con:
            rows = con.execute(sql, (*args, int(limit), int(offset))).fetchall()
        return [_record(r) for r in rows]

    def count(self, where: StudyFilter | None = None) -> int:
        """Number of catalog records matching ``where`` (as :meth:`list` filters them)."""
        clauses, args = self._where(where or StudyFilter())
        with self._connect() as con:
            return int(con.execute(f"SELECT COUNT(*) FROM studies{clauses}", args).fetchone()[0])

    @staticmethod
    def _where(where: StudyFilter) -> tuple[str, tuple[Any, ...]]:
        name, status, isolator_type = where.name, where.status, where.isolator_type
        created_after, created_before = where.created_after, where.created_before
        clauses: builtins.list[str] = []
        args: builtins.list[Any] = []
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
        """Remove a study's row. False if there was none."""
        check_id(study_id)
        with self._connect() as con:
            return con.execute("DELETE FROM studies WHERE id = ?", (study_id,)).rowcount > 0


def _unavailable(path: Path, err: sqlite3.OperationalError) -> CatalogUnavailable:
    text = str(err)
    if "full" in text.lower():
        text = f"no space left on device ({text})"
    return CatalogUnavailable(f"the study catalog {path.name} cannot be used now: {text}")


def _record(row: sqlite3.Row) -> StudyRecord:
    return StudyRecord.from_row({k: row[k] for k in row.keys()})  # noqa: SIM118 (sqlite3.Row)
