"""What a simulation returns: per-case outputs that carry a status instead of raising."""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

OK = 0
UNSTABLE = 1
"""The integration would be, or went, numerically unstable: no numbers are given."""
TIPPING = 2
"""The scene itself is statically unstable (gravity rocking stiffness beats the mounts)."""
FAILED = 3
"""Anything else went wrong for this case; ``message`` says what."""

STATUS_NAMES = ("ok", "unstable", "tipping", "failed")

DOF_NAMES = ("x", "y", "z", "rx", "ry", "rz")
"""Degrees of freedom of the base: c.g. translation, then rotation about X (pitch), Y (roll), Z (yaw)."""
AXES = DOF_NAMES[:3]
"""Names of the translation axes (the ``axis`` dimension of stored results)."""
ROTATIONS = DOF_NAMES[3:]
"""Names of the rotations about X, Y, Z (the ``rotation`` dimension of stored results)."""
N_MODES = len(DOF_NAMES)
"""Natural modes of the rigid base (one per degree of freedom)."""
ISOLATOR = "isolator"
"""Stands for the number of isolators in an output's trailing shape."""
POINT = "point"
"""Stands for the number of points of interest in an output's trailing shape."""


def _output(*trailing: int | str, flag: bool = False) -> dict[str, Any]:
    """Field metadata of a per-case output: its shape after the case axis (:data:`ISOLATOR` and
    :data:`POINT` stand for the scene's counts) and whether it is a yes/no flag (bool) or a number."""
    return {"trailing": trailing, "flag": flag}


@dataclass
class SimulationResult:
    """Outputs of ``C`` cases.

    A case whose ``status`` is not OK has NaN in ``peak_displacement``, ``peak_rotation``,
    ``peak_point_displacement``, ``peak_isolator_force``, ``min_isolator_load``, ``rms_displacement``,
    ``final_displacement``, ``settling_time``, ``point_settling_time``, ``peak_isolator_deflection``,
    ``max_isolator_load`` and ``transmissibility``, and ``settled`` False. What does
    not depend on integrating its motion stays filled: ``dt`` (the step it was or would have been run
    with), ``static_isolator_load`` and the modal analysis (``natural_frequency``, ``damping_ratio``,
    ``mode_energy``, ``mechanism``), so an unstable or tipping case still shows its modes and preloads.

    Attributes (shapes; units):
        status: (C,) int8, one of OK, UNSTABLE, TIPPING, FAILED.
        message: list of C strings, empty where OK (an OK case the stability guard sub-stepped says so).
        dt: (C,) step actually used, s.
        peak_displacement: (C, 3) peak |c.g. displacement| per axis, m.
        peak_rotation: (C, 3) peak |rotation| about X, Y, Z, rad.
        peak_point_displacement: (C, p, 3) peak |displacement| of each point of interest, m.
        peak_isolator_force: (C, n, 3) peak |dynamic force| of each isolator per axis, N.
        static_isolator_load: (C, n) vertical preload of each isolator at the reference state, N.
        min_isolator_load: (C, n) smallest total vertical load, N (below zero: the mount lifts off).
        rms_displacement: (C, 3) RMS c.g. displacement per axis over the simulation, m.
        final_displacement: (C, 6) static c.g. displacement and rotation with the stages parked at
            their final positions, m and rad.
        settling_time: (C,) time after the last stage move until the c.g. and every point stay within
            ``settle_tol`` of the final static position, s; a lower bound where ``settled`` is False.
        settled: (C,) bool.
        point_settling_time: (C, p) settling time of each point of interest after each stage move,
            worst over the moves, s. The rest intervals are the times every stage is at rest: from the
            end ``t_k`` of a move until the next move of any stage starts or the run ends (``s_k``); a
            run without stage motion has none and gives 0. In interval ``k`` the point's target is its
            static displacement with the stages parked where they rest in that interval
            (``engine.model.rest_offsets``, level-dependent as ``final_displacement``); its settling
            time there is the last output time in ``[t_k, s_k]`` at which the largest per-axis
            |displacement - target| exceeds ``point_settle_tol`` (scene input, default ``settle_tol``),
            minus ``t_k``: 0 if never, the interval's length (a lower bound) if still outside at its
            last output time. The value is the largest over the case's rest intervals.
        peak_isolator_deflection: (C, n, 3) peak |deflection| of each isolator per floor axis from its
            static (reference) state: the displacement of the base at the mount's point of action
            (rotated point at the nonlinear level) minus the floor's there, m. What sizes a mount's
            stroke.
        max_isolator_load: (C, n) largest total vertical load (preload plus dynamic), N.
        natural_frequency: (C, 6) undamped natural frequencies, ascending, Hz (0 for a mechanism, and for
            a mode with negative stiffness: the modes a TIPPING case tips in).
        damping_ratio: (C, 6) modal damping ratio of each mode, 1.
        mode_energy: (C, 6, 6) kinetic-energy share of each DOF (last axis, DOF_NAMES) in each mode.
        mechanism: (C, 6) bool, True for a zero-stiffness (rigid-body) mode.
        transmissibility: (C, 3) |c.g. displacement / floor displacement| per axis at the floor
            frequency (sine floor motion only; 0 where there is none), 1.
        floor_point_velocity: (C, p, 3) largest one-third-octave band RMS velocity (1 to 80 Hz) of each
            point of interest per axis under the scene's floor spectrum, steady state at the ``lti`` level
            (``engine.frequency``), m/s; 0 without a floor spectrum. Needs no time integration: filled
            for unstable and failed cases too, NaN only for a tipping case or one with a mechanism.
        floor_point_velocity_band: (C, p, 3) exact centre of that band, Hz (0 without a floor spectrum).
        history: time histories of recorded cases, or None (see ``simulate(record=...)``).

    The per-case outputs (every field but ``status``, ``message`` and ``history``) are listed, in this
    order, by :data:`OUTPUT_FIELDS`, with their trailing shapes from :func:`output_shape`.
    """

    status: np.ndarray
    message: list[str]
    dt: np.ndarray = field(metadata=_output())
    peak_displacement: np.ndarray = field(metadata=_output(len(AXES)))
    peak_rotation: np.ndarray = field(metadata=_output(len(ROTATIONS)))
    peak_point_displacement: np.ndarray = field(metadata=_output(POINT, len(AXES)))
    peak_isolator_force: np.ndarray = field(metadata=_output(ISOLATOR, len(AXES)))
    static_isolator_load: np.ndarray = field(metadata=_output(ISOLATOR))
    min_isolator_load: np.ndarray = field(metadata=_output(ISOLATOR))
    rms_displacement: np.ndarray = field(metadata=_output(len(AXES)))
    final_displacement: np.ndarray = field(metadata=_output(len(DOF_NAMES)))
    settling_time: np.ndarray = field(metadata=_output())
    settled: np.ndarray = field(metadata=_output(flag=True))
    point_settling_time: np.ndarray = field(metadata=_output(POINT))
    peak_isolator_deflection: np.ndarray = field(metadata=_output(ISOLATOR, len(AXES)))
    max_isolator_load: np.ndarray = field(metadata=_output(ISOLATOR))
    natural_frequency: np.ndarray = field(metadata=_output(N_MODES))
    damping_ratio: np.ndarray = field(metadata=_output(N_MODES))
    mode_energy: np.ndarray = field(metadata=_output(N_MODES, len(DOF_NAMES)))
    mechanism: np.ndarray = field(metadata=_output(N_MODES, flag=True))
    transmissibility: np.ndarray = field(metadata=_output(len(AXES)))
    floor_point_velocity: np.ndarray | None = field(default=None, metadata=_output(POINT, len(AXES)))
    floor_point_velocity_band: np.ndarray | None = field(default=None, metadata=_output(POINT, len(AXES)))
    history: dict[str, np.ndarray] | None = field(default=None)

    def __post_init__(self) -> None:
        # a result assembled without the floor-spectrum outputs has none: zeros (no floor spectrum)
        for name in ("floor_point_velocity", "floor_point_velocity_band"):
            if getattr(self, name) is None:
                c, p = np.shape(self.peak_point_displacement)[:2]
                setattr(self, name, np.zeros((c, p, len(AXES))))

    @property
    def n_cases(self) -> int:
        return int(self.status.shape[0])

    @property
    def ok(self) -> np.ndarray:
        return self.status == OK

    def to_dict(self, case: int = 0) -> dict:
        """One case's outputs as plain JSON-able Python (SI units, keys named for the quantity)."""
        out: dict = {"status": STATUS_NAMES[int(self.status[case])], "message": self.message[case]}
        for name in OUTPUT_FIELDS:
            v = np.asarray(getattr(self, name)[case])
            out[name] = None if v.dtype.kind == "f" and not np.all(np.isfinite(v)) else v.tolist()
        return out


_OUTPUTS = {f.name: f.metadata for f in fields(SimulationResult) if "trailing" in f.metadata}
OUTPUT_FIELDS: tuple[str, ...] = tuple(_OUTPUTS)
"""Names of the per-case outputs of :class:`SimulationResult`, in declaration order (every field but
``status``, ``message`` and ``history``)."""
FLAG_FIELDS: frozenset[str] = frozenset(name for name, meta in _OUTPUTS.items() if meta["flag"])
"""The yes/no (bool) outputs among :data:`OUTPUT_FIELDS`; the others are floats."""


def output_shape(name: str, n_isolators: int, n_points: int) -> tuple[int, ...]:
    """Shape of one case's value of the output ``name`` in a scene of ``n_isolators`` isolators and
    ``n_points`` points of interest (``()`` for a scalar)."""
    size = {ISOLATOR: int(n_isolators), POINT: int(n_points)}
    return tuple(size[d] if isinstance(d, str) else int(d) for d in _OUTPUTS[name]["trailing"])
