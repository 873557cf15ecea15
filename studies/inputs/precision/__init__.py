"""What a precision process sees of the machine's motion: stages on a servo (their following error),
relative points (tool to work) and the base's elastic deflection between them (``machine.flexible``:
``base_flexibility``); :func:`precision_inputs` turns the first two into a batch's arrays,
:func:`flexible_base` the last."""

from __future__ import annotations

from isolab.engine.scene import SceneBatch
from isolab.studies.inputs.precision.base_flexibility import CaseValues, flexible_base
from isolab.studies.inputs.precision.relative_points import point_signature, relative_points
from isolab.studies.inputs.precision.servo import servo_kind, servo_stages

__all__ = ["flexible_base", "point_signature", "precision_inputs", "servo_kind"]


def precision_inputs(batch: SceneBatch, cases: CaseValues) -> SceneBatch:
    """``batch`` with its stages' servos and its relative points, when the scene has them."""
    return relative_points(servo_stages(batch, cases), cases.scenes[0])
