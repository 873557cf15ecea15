"""isolab's physics engine: a rigid machine base on vibration isolators, shaken by its own stages.

Plain numpy arrays in (``SceneBatch``), arrays out (``SimulationResult``); Numba kernels run many cases
per call. See ``simulate``.
"""

from engine.results import STATUS_NAMES, SimulationResult
from engine.scene import GRAVITY, SceneBatch, SceneError, concat
from engine.simulate import check_choice, simulate

__version__ = "0.1.0"

__all__ = [
    "GRAVITY", "STATUS_NAMES", "SceneBatch", "SceneError", "SimulationResult", "check_choice", "concat",
    "simulate", "__version__",
]
