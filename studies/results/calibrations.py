"""Calibration jobs on disk, beside the studies of a store's root.

Layout under ``root``::

    calibrations/<id>/request.json   the request body as submitted (what a restart runs again)
    calibrations/<id>/job.json       status, times, the cost estimate, progress, the error of a failed one
    calibrations/<id>/result.json    the answer, once done

An id is a uuid4 hex string (32 lowercase hex digits, checked before it becomes part of a path). Every file
is written atomically (:func:`isolab.studies.results.store.atomic_path`); a job deleted while its answer
arrives stays deleted (writes go only to a job directory that exists).
"""

from __future__ import annotations

import contextlib
import json
import shutil
import threading
import uuid
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from isolab.studies.results.catalog import check_id, utc_now
from isolab.studies.results.store import atomic_path

CALIBRATIONS_DIR = "calibrations"
"""The folder of calibration jobs under a store's root."""
JOB_STATUSES = ("queued", "running", "done", "failed")
"""Where a calibration job is (a cancelled one is deleted)."""
UNFINISHED_JOBS = ("queued", "running")
"""Statuses a service start takes up again."""


class CalibrationNotFound(KeyError):
    """No calibration job with this id (or a malformed id)."""

    def __str__(self) -> str:
        return f"no calibration with id {self.args[0]!r}"


class CalibrationStore:
    """The calibration jobs of a data directory (``<root>/calibrations/``); safe to share between threads."""

    def __init__(self, root: str | Path):
        self.root = Path(root) / CALIBRATIONS_DIR
        self._lock = threading.Lock()

    def _dir(self, job_id: str) -> Path:
        try:
            return self.root / check_id(job_id)
        except ValueError:
            raise CalibrationNotFound(job_id) from None

    def _write(self, path: Path, data: Any) -> None:
        with atomic_path(path) as tmp:
            tmp.write_text(json.dumps(data), encoding="utf-8")

    def create(self, request: Mapping[str, Any], estimate: Mapping[str, Any]) -> dict[str, Any]:
        """Store a new job (status ``queued``) of ``request`` with its cost ``estimate``; its record."""
        job_id = uuid.uuid4().hex
        folder = self.root / job_id
        folder.mkdir(parents=True)
        self._write(folder / "request.json", dict(request))
        job = {
            "id": job_id,
            "status": "queued",
            "created": utc_now(),
            "started": None,
            "finished": None,
            "estimate": dict(estimate),
            "progress": {"engine_calls": 0, "cases": 0},
            "error": None,
        }
        self._write(folder / "job.json", job)
        return job

    def get(self, job_id: str) -> dict[str, Any]:
        """The job's record (``id``, ``status``, times, ``estimate``, ``progress``, ``error``)."""
        path = self._dir(job_id) / "job.json"
        try:
            return dict(json.loads(path.read_text(encoding="utf-8")))
        except (FileNotFoundError, NotADirectoryError, json.JSONDecodeError):
            raise CalibrationNotFound(job_id) from None

    def update(
        self, job_id: str, when: tuple[str, ...] | None = None, **fields: Any
    ) -> dict[str, Any] | None:
        """Set ``fields`` of the job's record (only while its status is one of ``when``, when given); None
        (and nothing written) when the job is gone or not in those statuses."""
        with self._lock:
            try:
                job = self.get(job_id)
            except CalibrationNotFound:
                return None
            if when is not None and job["status"] not in when:
                return None
            job.update(fields)
            self._write(self._dir(job_id) / "job.json", job)
            return job

    def request(self, job_id: str) -> dict[str, Any]:
        """The request body the job was submitted with."""
        try:
            return dict(json.loads((self._dir(job_id) / "request.json").read_text(encoding="utf-8")))
        except (FileNotFoundError, NotADirectoryError, json.JSONDecodeError):
            raise CalibrationNotFound(job_id) from None

    def finish(self, job_id: str, answer: Mapping[str, Any], **fields: Any) -> bool:
        """Store the job's answer and mark it ``done`` (with ``fields``); False when the job is gone."""
        with self._lock:
            folder = self._dir(job_id)
            if not (folder / "job.json").is_file():
                return False
            self._write(folder / "result.json", dict(answer))
        return self.update(job_id, status="done", finished=utc_now(), **fields) is not None

    def result(self, job_id: str) -> dict[str, Any] | None:
        """The answer of a done job (None before)."""
        path = self._dir(job_id) / "result.json"
        with contextlib.suppress(FileNotFoundError, NotADirectoryError):
            return dict(json.loads(path.read_text(encoding="utf-8")))
        return None

    def delete(self, job_id: str) -> bool:
        """Remove the job and its files; False when there was none."""
        with self._lock:
            folder = self._dir(job_id)
            if not folder.is_dir():
                return False
            shutil.rmtree(folder, ignore_errors=True)
            return True

    def ids(self, statuses: tuple[str, ...] | None = None) -> list[str]:
        """Ids of the stored jobs (of ``statuses`` only, when given), oldest first."""
        if not self.root.is_dir():
            return []
        jobs = []
        for folder in self.root.iterdir():
            with contextlib.suppress(CalibrationNotFound):
                job = self.get(folder.name)
                if statuses is None or job["status"] in statuses:
                    jobs.append(job)
        return [j["id"] for j in sorted(jobs, key=lambda j: (j["created"], j["id"]))]
