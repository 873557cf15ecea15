"""What the catalog holds of a study (:class:`StudyRecord`), how listings pick studies (:class:`StudyFilter`),
and what a study's own record says about it (:func:`isolator_types`).

A record is typed (``record.status``, ``record.n_done``) and reads, too, as the catalog row it is
(``record["status"]``, ``dict(record)``: the columns, JSON columns decoded), for code that reads rows by
column. The service turns records into its answers at its edge.
"""

from __future__ import annotations

import datetime as _dt
import json
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from isolab.studies.inputs.study import Study


@dataclass(frozen=True)
class StudyRecord(Mapping[str, Any]):
    """One study's row of the catalog.

    Attributes:
        id: the study id (32 lowercase hex digits).
        name: the study's name.
        status: queued, running, done, failed or cancelled.
        created, started, finished: ISO 8601 UTC times (started and finished None until they happen).
        n_cases: cases planned (an optimisation: its budget); n_done, n_failed: cases done so far, and
            those of them that did not end ok.
        parameters: names of the varied parameters.
        isolator_types: the isolator types the study involves.
        fidelity, integrator, dt: the model its cases run with (dt in s); None until chosen for a study
            that asks for an accuracy instead.
        error: why the study failed, or None.
        definition: the stored definition (validated, SI, defaults filled in).
        generation, generations: an optimisation's finished and planned generations (None otherwise).
    """

    id: str
    name: str
    status: str
    created: str
    started: str | None
    finished: str | None
    n_cases: int
    n_done: int
    n_failed: int
    parameters: list[str]
    isolator_types: list[str]
    fidelity: str | None
    integrator: str | None
    dt: float | None
    error: str | None
    definition: dict[str, Any]
    generation: int | None = None
    generations: int | None = None

    @classmethod
    def from_row(cls, row: Mapping[str, Any]) -> StudyRecord:
        """The record of a catalog row (its columns by name; JSON columns as text or decoded)."""
        values: dict[str, Any] = {name: row.get(name) for name in COLUMNS}
        for name in JSON_COLUMNS:
            if isinstance(values[name], str):
                values[name] = json.loads(values[name])
        for name in ("parameters", "isolator_types"):
            values[name] = list(values[name] or [])
        return cls(**values)

    # a record reads as its catalog row: record["status"], dict(record)
    def __getitem__(self, key: str) -> Any:
        if key not in COLUMNS:
            raise KeyError(key)
        return getattr(self, key)

    def __iter__(self) -> Iterator[str]:
        return iter(COLUMNS)

    def __len__(self) -> int:
        return len(COLUMNS)


COLUMNS: tuple[str, ...] = tuple(f.name for f in fields(StudyRecord))
"""The catalog's columns, in table order (the fields of :class:`StudyRecord`)."""
JSON_COLUMNS = ("parameters", "isolator_types", "definition")
"""Columns stored as JSON text."""


@dataclass(frozen=True)
class StudyFilter:
    """Which studies a listing holds: every filter given must hold (None: any).

    Attributes:
        name: the exact study name.
        status: one of the catalog's statuses.
        isolator_type: studies whose ``isolator_types`` include it.
        created_after, created_before: creation time bounds (inclusive), ISO 8601 or datetime; naive
            times are UTC.
    """

    name: str | None = None
    status: str | None = None
    isolator_type: str | None = None
    created_after: str | _dt.datetime | None = None
    created_before: str | _dt.datetime | None = None


def isolator_types(study: Study) -> list[str]:
    """Isolator types (presets) a study involves: the values of every varied preset, plus the scene's
    own group and per-mount presets where no parameter replaces them."""
    design = study.design()
    scene = study.scene
    assert scene is not None  # a validated study has its scene
    iso = scene.isolators
    varied = {t.path: name for t, name in zip(study.targets, design.names, strict=True)}
    types = {
        str(v)
        for path, name in varied.items()
        if path.endswith("preset")
        for v in np.unique(design.values[name])
    }
    group_used = iso.mounts is None or any(m.preset is None for m in iso.mounts)
    if group_used and "isolators.preset" not in varied:
        types.add(str(iso.preset))
    for j, mount in enumerate(iso.mounts or []):
        if mount.preset is not None and f"isolators.list.{j}.preset" not in varied:
            types.add(str(mount.preset))
    return sorted(types)
