"""The dotted paths of a scene's inputs, written once.

A path follows the scene file's own keys, with stage and point names and list indices as segments
(``stages.y.profile.acceleration``, ``isolators.list.2.position``); the components of a vector input are
``<path>.0`` to ``<path>.2``. The parameter paths a study may vary (:mod:`studies.inputs.parameters`), the
per-case overrides the batch builder reads (:mod:`studies.inputs.scenes`) and the errors that name an input
(here and in the models) are all spelled from the names below. In an error, the ``i``-th entry of the
stage list is :func:`stage_entry` (``stages[1].parent``).
"""

from __future__ import annotations

MACHINE_MASS = "machine.mass"
MACHINE_CG = "machine.cg"
MACHINE_INERTIA = "machine.inertia"
MACHINE_INERTIA_DIAGONAL = "machine.inertia_diagonal"
MACHINE_BLOCK = "machine.block"
BLOCK_SIZE = f"{MACHINE_BLOCK}.size"
BLOCK_DENSITY = f"{MACHINE_BLOCK}.density"
BLOCK_CORNER = f"{MACHINE_BLOCK}.corner"
"""The machine base: given by mass, c.g. and inertia, or as a block (size, density, corner)."""
MACHINE_FLEXIBLE = "machine.flexible"
FLEXIBLE_MODES = f"{MACHINE_FLEXIBLE}.modes"
FLEXIBLE_YOUNG_MODULUS = f"{MACHINE_FLEXIBLE}.young_modulus"
FLEXIBLE_DAMPING = f"{MACHINE_FLEXIBLE}.damping"
FLEXIBLE_POISSON_RATIO = f"{MACHINE_FLEXIBLE}.poisson_ratio"
"""A block base's elastic modes (its Young's modulus and modal damping may vary in a study)."""

ISOLATORS = "isolators"
ISOLATOR_PRESET = f"{ISOLATORS}.preset"
ISOLATOR_MODEL = f"{ISOLATORS}.model"
"""A product of the scene's catalogue for every mount: a choice a comparison of products varies (its
levels are the catalogue's ids; the product decides the type and figures)."""
MOUNT_FIGURES = ("f_vertical", "f_horizontal", "zeta")
"""The preset figures the isolator group and each listed mount may override (``isolators.zeta``,
``isolators.list.2.zeta``)."""
EXPLICIT_VALUES = ("k", "c")
"""Explicit stiffness and damping: per floor axis for every mount (``isolators.k.z``), or a vector of one
listed mount (``isolators.list.2.k.2``)."""
AXIS_ALIASES: dict[str, tuple[str, ...]] = {"horizontal": ("x", "y"), "vertical": ("z",)}
"""Keys that stand for several floor axes in the per-axis values of the isolator group."""
LAYOUT_SPAN_X = f"{ISOLATORS}.layout.span_x"
LAYOUT_SPAN_Y = f"{ISOLATORS}.layout.span_y"
LAYOUT_HEIGHT = f"{ISOLATORS}.layout.height"

FLOOR_SINE_KEYS = ("amplitude", "frequency", "phase")
"""The vectors of a sine floor (``floor.sine.amplitude``)."""
SIMULATION_DURATION = "simulation.duration"
SIMULATION_SETTLE_TOLERANCE = "simulation.settle_tolerance"
"""The only inputs of the simulation block a study may vary (the rest is shared by every case)."""


def components(vector: str) -> list[str]:
    """The paths of the three components of a vector input: ``machine.cg`` -> ``machine.cg.0`` .. ``.2``."""
    return [f"{vector}.{i}" for i in range(3)]


def isolator_group(key: str) -> str:
    """A value the isolator group sets for every mount: ``isolators.<key>`` (``isolators.f_vertical``)."""
    return f"{ISOLATORS}.{key}"


def group_axis(kind: str, axis: str) -> str:
    """Explicit stiffness or damping (``kind`` k or c) of every mount along ``axis`` (x, y, z or an
    alias): ``isolators.k.z``."""
    return f"{ISOLATORS}.{kind}.{axis}"


def mount(j: int) -> str:
    """Mount ``j`` of an explicit list: ``isolators.list.<j>``."""
    return f"{ISOLATORS}.list.{j}"


LEVELLING = "levelling"
"""An air mount's levelling valve: ``isolators.levelling`` (every mount), ``isolators.list.<j>.levelling``
(one mount)."""
LEVELLING_KEYS = ("time_constant", "dead_band")
"""The numbers of a levelling valve a study may vary (its ``valve`` name is structure)."""


def stage(name: str) -> str:
    """The stage called ``name``: ``stages.<name>``."""
    return f"stages.{name}"


def stage_profile(name: str) -> str:
    """The motion profile of the stage called ``name``: ``stages.<name>.profile``."""
    return f"{stage(name)}.profile"


SERVO_KEYS = ("bandwidth", "damping_ratio", "stiffness", "damping")
"""The numbers of a stage's servo (``stages.<name>.servo.bandwidth``): a study may vary each one given."""


def stage_servo(name: str) -> str:
    """The servo of the stage called ``name``: ``stages.<name>.servo``."""
    return f"{stage(name)}.servo"


SHAPER_KEYS = ("frequency", "damping")
"""The numbers of a profile's input shaper a study may vary (its ``type`` is categorical)."""


def profile_shaper(name: str) -> str:
    """The input shaper of the stage called ``name``: ``stages.<name>.profile.shaper``."""
    return f"{stage_profile(name)}.shaper"


def profile_segment(name: str, k: int) -> str:
    """Segment ``k`` of a sequence profile: ``stages.<name>.profile.segments.<k>``."""
    return f"{stage_profile(name)}.segments.{k}"


def point(name: str) -> str:
    """The point of interest called ``name`` (a position vector): ``points.<name>``."""
    return f"points.{name}"


def relative_point(name: str) -> str:
    """The relative point called ``name`` (tool to work): ``points.<name>.relative``."""
    return f"{point(name)}.relative"


def floor_sine(key: str) -> str:
    """A vector of the sine floor (one of :data:`FLOOR_SINE_KEYS`): ``floor.sine.<key>``."""
    return f"floor.sine.{key}"


def stage_entry(i: int) -> str:
    """The ``i``-th entry of the scene's stage list as errors name it: ``stages[<i>]``."""
    return f"stages[{i}]"
