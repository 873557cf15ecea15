"""Stages on a servo (``stages[].servo``): the natural frequency and damping ratio of each stage's
following error, per case (docs/physics.md, "Servo stages").

Given as ``bandwidth`` (Hz, the error's natural frequency) and ``damping_ratio`` (0.7 when omitted), or as
the servo's ``stiffness`` (N/m) and ``damping`` (N s/m, 0 when omitted) along the axis, which become
``w = sqrt(stiffness / M)`` and ``zeta = damping / (2 sqrt(stiffness M))`` with ``M`` the mass the drive
moves (the stage and every stage riding on it, ``engine.linear_states.servo.carried_mass``).
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from isolab.engine.linear_states.servo import carried_mass
from isolab.engine.scene import SceneBatch
from isolab.studies.inputs.schema.scene import Scene
from isolab.studies.inputs.schema.scene_paths import stage_servo

if TYPE_CHECKING:
    from isolab.studies.inputs.precision.base_flexibility import CaseValues

DEFAULT_DAMPING_RATIO = 0.7
"""The following error's damping ratio when a bandwidth is given without one."""


def servo_kind(stage: object) -> str | None:
    """How a stage's servo is given (``"bandwidth"``, ``"stiffness"``) or None: what every scene of one
    batch must share."""
    servo = getattr(stage, "servo", None)
    if servo is None:
        return None
    return "bandwidth" if servo.bandwidth is not None else "stiffness"


def servo_stages(batch: SceneBatch, cases: CaseValues) -> SceneBatch:
    """``batch`` with each servo stage's ``stage_servo_frequency`` (Hz) and ``stage_servo_damping`` read
    per case (a study may vary ``stages.<name>.servo.bandwidth`` and the other figures given); else
    ``batch``."""
    stages = cases.scenes[0].stages
    if all(s.servo is None for s in stages):
        return batch
    C, m = batch.n_cases, batch.n_stages
    freq = np.zeros((C, m))
    zeta = np.zeros((C, m))
    moved = carried_mass(batch)

    def per_case(values: np.ndarray) -> np.ndarray:
        return np.broadcast_to(np.asarray(values, dtype=float), (C,)).copy()

    for i, st in enumerate(stages):
        if st.servo is None:
            continue

        def figure(key: str, default: float, i: int = i, path: str = stage_servo(st.name)) -> np.ndarray:
            def read(s: Scene) -> float:
                value = getattr(s.stages[i].servo, key)
                return default if value is None else float(value)

            return per_case(cases.get(f"{path}.{key}", read))

        if servo_kind(st) == "bandwidth":
            freq[:, i] = figure("bandwidth", np.nan)
            zeta[:, i] = figure("damping_ratio", DEFAULT_DAMPING_RATIO)
        else:
            k = figure("stiffness", np.nan)
            c = figure("damping", 0.0)
            freq[:, i] = np.sqrt(k / moved[:, i]) / (2.0 * np.pi)
            zeta[:, i] = c / (2.0 * np.sqrt(k * moved[:, i]))
    return replace(batch, stage_servo_frequency=freq, stage_servo_damping=zeta)
