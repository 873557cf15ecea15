"""What a study is, how its cases are drawn and fanned out, and how its results are stored.

Imports :mod:`isolab.engine`; nothing here imports the web service. The service reaches the engine only
through this package: the names below are the engine's, re-exported for it.
"""

from typing import Any

from isolab.engine import STATUS_NAMES, SceneError, __version__
from isolab.engine.results import AXES, DOF_NAMES, OUTPUTS, ROTATIONS, OutputSpec


def __getattr__(name: str) -> Any:
    if name in ("simulate", "general_observer_called"):  # the engine's kernels load on first use
        import isolab.engine

        return getattr(isolab.engine, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "AXES",
    "DOF_NAMES",
    "OUTPUTS",
    "ROTATIONS",
    "STATUS_NAMES",
    "OutputSpec",
    "SceneError",
    "__version__",
    "general_observer_called",
    "simulate",
]
