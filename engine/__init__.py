"""isolab's physics engine: a rigid machine base on vibration isolators, shaken by its own stages.

Plain numpy arrays in (``SceneBatch``), arrays out (``SimulationResult``); Numba kernels run many cases
per call. See ``simulate``.
"""

from importlib.metadata import PackageNotFoundError, version

from isolab.engine.results import STATUS_NAMES, SimulationResult
from isolab.engine.scene import GRAVITY, SceneBatch, SceneError, concat
from isolab.engine.simulate import check_choice, simulate

try:
    __version__ = version("isolab")
    """isolab's version: pyproject.toml's, as installed (the one place it is written)."""
except PackageNotFoundError:  # pragma: no cover - the source tree used without installing it
    __version__ = "0+unknown"

__all__ = [
    "GRAVITY",
    "STATUS_NAMES",
    "SceneBatch",
    "SceneError",
    "SimulationResult",
    "check_choice",
    "concat",
    "simulate",
    "__version__",
]
