"""Relative points (``points.<name>: {relative: {tool, work}}``): the tool's and the work's ends as stages
or material points of the base (docs/physics.md, "Relative points").

An end named after a stage is the point that stage carries, at its home c.g.; an end named after a
material point is that point of the base. The batch keeps the tool's position in ``points`` (where a
flexible base's shapes are read), the work's in :func:`work_positions`, and each end's stage (-1: the base)
in ``point_tool_stage`` and ``point_work_stage``.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from isolab.engine.scene import SceneBatch
from isolab.studies.inputs.schema.scene import RelativePoint, Scene


def point_signature(scene: Scene) -> tuple:
    """The points' names and, for a relative point, its ends: what every scene of one batch must share."""
    return tuple(
        (name, (value.relative.tool, value.relative.work) if isinstance(value, RelativePoint) else None)
        for name, value in scene.points.items()
    )


def _end(batch: SceneBatch, scene: Scene, name: str) -> tuple[int, np.ndarray]:
    """An end's stage index (-1: the base) and position (C, 3), m."""
    stages = [s.name for s in scene.stages]
    if name in stages:
        i = stages.index(name)
        return i, np.asarray(batch.stage_home, dtype=float)[:, i]
    j = list(scene.points).index(name)
    return -1, np.asarray(batch.points, dtype=float)[:, j]


def work_positions(batch: SceneBatch, scene: Scene) -> np.ndarray:
    """(C, p, 3) the work end of each relative point, m (zero for a material point)."""
    out = np.zeros(np.shape(batch.points))
    for k, value in enumerate(scene.points.values()):
        if isinstance(value, RelativePoint):
            out[:, k] = _end(batch, scene, value.relative.work)[1]
    return out


def relative_points(batch: SceneBatch, scene: Scene) -> SceneBatch:
    """``batch`` with its relative points (``point_relative`` 1, the tool's position in ``points``, each
    end's stage); ``batch`` itself when the scene has none."""
    if not any(isinstance(v, RelativePoint) for v in scene.points.values()):
        return batch
    C = batch.n_cases
    points = np.array(batch.points, dtype=float)
    kind = np.zeros((C, batch.n_points), dtype=np.int8)
    tool_stage = np.full((C, batch.n_points), -1, dtype=np.int64)
    work_stage = np.full((C, batch.n_points), -1, dtype=np.int64)
    for k, value in enumerate(scene.points.values()):
        if not isinstance(value, RelativePoint):
            continue
        i, where = _end(batch, scene, value.relative.tool)
        points[:, k] = where
        kind[:, k] = 1
        tool_stage[:, k] = i
        work_stage[:, k] = _end(batch, scene, value.relative.work)[0]
    return replace(
        batch, points=points, point_relative=kind, point_tool_stage=tool_stage, point_work_stage=work_stage
    )
