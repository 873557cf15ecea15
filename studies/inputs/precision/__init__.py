"""What a precision process sees of the machine's motion: stages on a servo (their following error) and
relative points (tool to work); :func:`precision_inputs` turns both into a batch's arrays."""

from __future__ import annotations

from typing import TYPE_CHECKING

from isolab.engine.scene import SceneBatch
from isolab.studies.inputs.precision.relative_points import point_signature, relative_points
from isolab.studies.inputs.precision.servo import servo_kind, servo_stages

if TYPE_CHECKING:
    from isolab.studies.inputs.base_flexibility import CaseValues

__all__ = ["point_signature", "precision_inputs", "servo_kind"]


def precision_inputs(batch: SceneBatch, cases: CaseValues) -> SceneBatch:
    """``batch`` with its stages' servos and its relative points, when the scene has them."""
    return relative_points(servo_stages(batch, cases), cases.scenes[0])
