"""What a simulation returns: per-case outputs that carry a status instead of raising."""

from __future__ import annotations

from dataclasses import dataclass, field

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


@dataclass
class SimulationResult:
    """Outputs of ``C`` cases. Values of a case whose ``status`` is not OK are NaN.

    Attributes (shapes; units):
        status: (C,) int8, one of OK, UNSTABLE, TIPPING, FAILED.
        message: list of C strings, empty where OK.
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
        natural_frequency: (C, 6) undamped natural frequencies, ascending, Hz (0 for a mechanism).
        damping_ratio: (C, 6) modal damping ratio of each mode, 1.
        mode_energy: (C, 6, 6) kinetic-energy share of each DOF (last axis, DOF_NAMES) in each mode.
        mechanism: (C, 6) bool, True for a zero-stiffness (rigid-body) mode.
        transmissibility: (C, 3) |c.g. displacement / floor displacement| per axis at the floor
            frequency (sine floor motion only; 0 where there is none), 1.
        history: time histories of recorded cases, or None (see ``simulate(record=...)``).
    """

    status: np.ndarray
    message: list[str]
    dt: np.ndarray
    peak_displacement: np.ndarray
    peak_rotation: np.ndarray
    peak_point_displacement: np.ndarray
    peak_isolator_force: np.ndarray
    static_isolator_load: np.ndarray
    min_isolator_load: np.ndarray
    rms_displacement: np.ndarray
    final_displacement: np.ndarray
    settling_time: np.ndarray
    settled: np.ndarray
    natural_frequency: np.ndarray
    damping_ratio: np.ndarray
    mode_energy: np.ndarray
    mechanism: np.ndarray
    transmissibility: np.ndarray
    history: dict[str, np.ndarray] | None = field(default=None)

    @property
    def n_cases(self) -> int:
        return int(self.status.shape[0])

    @property
    def ok(self) -> np.ndarray:
        return self.status == OK

    def to_dict(self, case: int = 0) -> dict:
        """One case's outputs as plain JSON-able Python (SI units, keys named for the quantity)."""
        out: dict = {"status": STATUS_NAMES[int(self.status[case])], "message": self.message[case]}
        for name in (
            "dt",
            "peak_displacement",
            "peak_rotation",
            "peak_point_displacement",
            "peak_isolator_force",
            "static_isolator_load",
            "min_isolator_load",
            "rms_displacement",
            "final_displacement",
            "settling_time",
            "settled",
            "natural_frequency",
            "damping_ratio",
            "mode_energy",
            "mechanism",
            "transmissibility",
        ):
            v = np.asarray(getattr(self, name)[case])
            out[name] = None if v.dtype.kind == "f" and not np.all(np.isfinite(v)) else v.tolist()
        return out
