"""A batch of cases of one scene shape, as plain numpy arrays.

Every array has the case dimension first (``C`` cases). The scene *shape* (number of isolators ``n``,
stages ``m``, points of interest ``p``, motion-profile pieces ``K`` and floor samples ``F``) is shared by
all cases of a batch; the values may differ per case. All quantities are SI and expressed in the floor
frame XYZ (Z up) at the reference state: static equilibrium with every stage at home.

Motion profiles are piecewise polynomials in time, stored per stage as ``K`` pieces. Piece ``k`` starts at
``prof_t[..., k]`` with position ``prof_s``, velocity ``prof_v``, acceleration ``prof_a`` and constant jerk
``prof_j``; it holds until the next piece starts, the last piece forever. Start times are
non-decreasing; zero-length pieces are allowed (a triangular move keeps an empty cruise piece), so the
piece start times are the exact breakpoints an integrator may land steps on.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

GRAVITY = 9.80665
"""Standard gravity, m/s^2."""


class SceneError(ValueError):
    """Input that cannot describe a physical scene. ``field`` names the offending input."""

    def __init__(self, field: str, reason: str):
        super().__init__(f"{field}: {reason}")
        self.field = field
        self.reason = reason


@dataclass
class SceneBatch:
    """``C`` cases of one scene shape. See the module docstring for conventions.

    Attributes (shapes; units):
        mass: (C,) machine base mass without the stages, kg.
        inertia: (C, 3, 3) machine inertia tensor about its own c.g., floor axes, kg m^2.
        cg: (C, 3) machine c.g. position, m.
        iso_pos: (C, n, 3) isolator points of action, m.
        iso_k: (C, n, 3) isolator stiffness along floor X, Y, Z, N/m.
        iso_c: (C, n, 3) isolator viscous damping along floor X, Y, Z, N s/m.
        iso_skyhook: (C, n) True where the damping acts on the absolute velocity (active, sky-hook).
        stage_mass: (C, m) moving mass of each stage, kg.
        stage_home: (C, m, 3) stage c.g. at home, m.
        stage_axis: (C, m, 3) unit travel direction, fixed in the machine.
        stage_parent: (m,) index of the stage this one rides on, -1 for the machine; parents come first.
        prof_t, prof_s, prof_v, prof_a, prof_j: (C, m, K) piece start time s, position m, velocity m/s,
            acceleration m/s^2, jerk m/s^3 of each stage's travel along its axis.
        points: (C, p, 3) points of interest (material points of the machine), m.
        floor_amp: (C, 3) amplitude of a sinusoidal floor displacement per axis, m.
        floor_freq: (C, 3) its frequency, Hz.
        floor_phase: (C, 3) its phase, rad: x_f = amp sin(2 pi f t + phase).
        floor_t: (F,) sample times of a recorded floor displacement, s (F = 0: none).
        floor_disp: (C, 3, F) recorded floor displacement per axis, m, linearly interpolated,
            held at its last value after the last sample, zero before the first.
        floor_band_velocity: (C, 3, 20) the floor's RMS velocity per axis in the one-third-octave bands
            of 1 to 80 Hz (``engine.frequency.BAND_CENTRES``), m/s; all zero (the default) when the
            scene gives no floor spectrum. Steady state only: the time integration does not see it.
        floor_mount_band_velocity: (C, n, 3, 20) the floor's band RMS velocity under each mount, m/s, when
            the mounts stand on different floor spectra; None (the default): ``floor_band_velocity`` under
            every mount.
        floor_delay: (C, n) delay of the floor motion under each mount (a travelling wave), s; zeros
            (the default): the floor moves at once under every mount.
        floor_coherence: how the floor motions under different mounts combine in the frequency response:
            ``correlated`` (the default; in phase up to ``floor_delay``), ``uncorrelated`` (their powers add)
            or ``worst_phase`` (per frequency, the phases that maximise each point's response).
        duration: (C,) simulated time, s.
        settle_tol: (C,) settling tolerance on c.g. and point displacement, m.
        point_settle_tol: (C, p) settling tolerance of each point of interest after each stage move
            (``point_settling_time``), m; defaults to ``settle_tol`` for every point.
        gravity_stiffness: include the rocking stiffness of preload and weights that tilt with the base.
        g: gravitational acceleration, m/s^2.
        iso_ff_gain: (C, n) gain of each mount's feedforward of the stages' inertial wrench, 1 (0: none,
            the default; docs/physics.md, "Active mounts with feedforward").
        iso_ff_bandwidth: (C, n) corner frequency of each mount's first-order feedforward low-pass, Hz
            (positive where the gain is not 0).
        iso_ff_limit: (C, n) force limit of each mount's actuator, per axis, N (``inf``: none, the default).
        iso_ff_weight: (C, n) True where the mount also feeds forward the change of the stages' weight
            moment (a stage that has travelled), not only their inertial wrench (default False).
        preload_with_base: the nonlinear level's preloads turn with the base (mounts that tilt with it)
            instead of staying vertical in the floor frame (the default, False).
        preload_balanced: the nonlinear level's preloads balance the weights (with the stages at home) in
            every attitude: no rocking stiffness from them, only the stages' travel tilts the base (default
            False; not together with ``preload_with_base``).
        iso_frame: (C, n, 3, 3) each mount's own axes in the floor frame (columns: the mount's x, y, z; a
            rotation). ``iso_k`` and ``iso_c`` act along these axes, so the mount's stiffness in the floor
            frame is ``Q diag(k) Q^T``. Default: the identity (the floor's axes).
        base_mode_frequency: (C, k) the base's elastic modes' free-free natural frequencies, Hz (k = 0, the
            default: a rigid base; docs/physics.md, "A flexible base").
        base_mode_damping: (C, k) their modal damping ratios.
        base_mode_mass: (C, k) their modal masses, kg (the shapes' scale: ``m_k = int rho |phi_k|^2 dV``).
        base_mode_iso: (C, n, 3, k) each mode's shape at the mounts' points of action (displacement per unit
            modal coordinate, floor axes).
        base_mode_stage: (C, m, 3, k) at the stages' homes (where their reactions enter the base).
        base_mode_point: (C, p, 3, k) at the points of interest (of a relative point: at its tool minus at
            its work).
        stage_servo_frequency: (C, m) the natural frequency of each stage's following error under its
            servo, Hz (0, the default: the stage follows its profile exactly; docs/physics.md, "Servo
            stages"). A stage is on a servo in every case of a batch or in none.
        stage_servo_damping: (C, m) the damping ratio of that error, 1.
        point_relative: (C, p) int8: 0 a material point of the base (the default); 1 a relative point, the
            motion of a tool relative to a work point as the process sees it (in the machine's frame, minus
            the commanded relative motion: docs/physics.md, "Relative points"); 2 a stage's following error
            (added by ``simulate`` for each servo stage, read along X).
        point_tool_stage: (C, p) int64: the stage a relative point's tool rides on (-1: the base); for a
            following-error point, its stage.
        point_work_stage: (C, p) int64: the stage its work point rides on (-1: the base).
        iso_branch_k: (C, n, 3, B) each mount's relaxation branches along its own axes, N/m: a spring
            ``k_b`` in series with a dashpot, in parallel with ``iso_k`` (an air mount's orifice, an
            elastomer's Maxwell ladder; docs/physics.md, "Mounts with internal states"). B = 0, the
            default: none. A branch whose stiffness is 0 in every case carries no state.
        iso_branch_tau: (C, n, 3, B) their relaxation times ``c_b / k_b``, s (positive where ``k_b > 0``).
        iso_valve: (C, n) int64: the levelling valve each mount is plumbed to (-1, the default: none;
            docs/isolators.md, "Levelling valves"); the same in every case. Mounts with the same index share
            one valve, at most three valves.
        iso_level_time: (C, n) the levelling time constant of each mount's valve, s (the same for the mounts
            of one valve; ignored without one).
        iso_level_band: (C, n) its dead band on the mounts' mean height, m (0: none, the default).
    """

    mass: np.ndarray
    inertia: np.ndarray
    cg: np.ndarray
    iso_pos: np.ndarray
    iso_k: np.ndarray
    iso_c: np.ndarray
    iso_skyhook: np.ndarray
    stage_mass: np.ndarray
    stage_home: np.ndarray
    stage_axis: np.ndarray
    stage_parent: np.ndarray
    prof_t: np.ndarray
    prof_s: np.ndarray
    prof_v: np.ndarray
    prof_a: np.ndarray
    prof_j: np.ndarray
    points: np.ndarray
    floor_amp: np.ndarray
    floor_freq: np.ndarray
    floor_phase: np.ndarray
    floor_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    floor_disp: np.ndarray | None = None
    floor_band_velocity: np.ndarray | None = None
    floor_mount_band_velocity: np.ndarray | None = None
    floor_delay: np.ndarray | None = None
    floor_coherence: str = "correlated"
    duration: np.ndarray | None = None
    settle_tol: np.ndarray | None = None
    point_settle_tol: np.ndarray | None = None
    gravity_stiffness: bool = True
    g: float = GRAVITY
    iso_ff_gain: np.ndarray | None = None
    iso_ff_bandwidth: np.ndarray | None = None
    iso_ff_limit: np.ndarray | None = None
    iso_ff_weight: np.ndarray | None = None
    preload_with_base: bool = False
    preload_balanced: bool = False
    iso_frame: np.ndarray | None = None
    base_mode_frequency: np.ndarray | None = None
    base_mode_damping: np.ndarray | None = None
    base_mode_mass: np.ndarray | None = None
    base_mode_iso: np.ndarray | None = None
    base_mode_stage: np.ndarray | None = None
    base_mode_point: np.ndarray | None = None
    stage_servo_frequency: np.ndarray | None = None
    stage_servo_damping: np.ndarray | None = None
    point_relative: np.ndarray | None = None
    point_tool_stage: np.ndarray | None = None
    point_work_stage: np.ndarray | None = None
    iso_branch_k: np.ndarray | None = None
    iso_branch_tau: np.ndarray | None = None
    iso_valve: np.ndarray | None = None
    iso_level_time: np.ndarray | None = None
    iso_level_band: np.ndarray | None = None

    def __post_init__(self) -> None:
        c = np.shape(self.mass)[0] if np.ndim(self.mass) else 1
        n = np.shape(self.iso_pos)[1] if np.ndim(self.iso_pos) == 3 else 0
        if self.iso_ff_gain is None:
            self.iso_ff_gain = np.zeros((c, n))
        if self.iso_ff_bandwidth is None:
            self.iso_ff_bandwidth = np.zeros((c, n))
        if self.iso_ff_limit is None:
            self.iso_ff_limit = np.full((c, n), np.inf)
        if self.iso_ff_weight is None:
            self.iso_ff_weight = np.zeros((c, n), dtype=bool)
        if self.floor_disp is None:
            self.floor_disp = np.zeros((c, 3, len(self.floor_t)))
        if self.floor_band_velocity is None:
            self.floor_band_velocity = np.zeros((c, 3, 20))
        if self.floor_delay is None:
            self.floor_delay = np.zeros((c, n))
        if self.duration is None:
            self.duration = np.full(c, 5.0)
        if self.settle_tol is None:
            self.settle_tol = np.full(c, 10e-6)
        if self.iso_frame is None:
            self.iso_frame = np.broadcast_to(np.eye(3), (c, n, 3, 3)).copy()
        if self.point_settle_tol is None:
            tol = np.asarray(self.settle_tol, dtype=float)
            p = np.shape(self.points)[1] if np.ndim(self.points) == 3 else 0
            self.point_settle_tol = np.repeat(tol.reshape(-1, 1), p, axis=1)
        self._base_mode_defaults(c, n)
        self._servo_defaults(c)
        for name in ("iso_branch_k", "iso_branch_tau"):  # no relaxation branch unless the scene gives one
            if getattr(self, name) is None:
                setattr(self, name, np.zeros((c, n, 3, 0)))
        if self.iso_valve is None:
            self.iso_valve = np.full((c, n), -1, dtype=np.int64)
        if self.iso_level_time is None:
            self.iso_level_time = np.zeros((c, n))
        if self.iso_level_band is None:
            self.iso_level_band = np.zeros((c, n))

    def _servo_defaults(self, c: int) -> None:
        """Every stage following its profile exactly and every point a material point, unless the scene
        says otherwise."""
        m = np.shape(self.stage_mass)[1] if np.ndim(self.stage_mass) == 2 else 0
        p = np.shape(self.points)[1] if np.ndim(self.points) == 3 else 0
        for name, value in (
            ("stage_servo_frequency", np.zeros((c, m))),
            ("stage_servo_damping", np.zeros((c, m))),
            ("point_relative", np.zeros((c, p), dtype=np.int8)),
            ("point_tool_stage", np.full((c, p), -1, dtype=np.int64)),
            ("point_work_stage", np.full((c, p), -1, dtype=np.int64)),
        ):
            if getattr(self, name) is None:
                setattr(self, name, value)

    @property
    def servo_stages(self) -> np.ndarray:
        """The indices of the stages on a servo (``stage_servo_frequency`` > 0), ascending."""
        f = np.asarray(self.stage_servo_frequency, dtype=float)
        return np.flatnonzero((f > 0).any(axis=0)) if f.ndim == 2 else np.zeros(0, dtype=np.int64)

    @property
    def has_relative_points(self) -> bool:
        """True when some point of interest is not a material point of the base."""
        return bool(np.any(np.asarray(self.point_relative) != 0))

    def _base_mode_defaults(self, c: int, n: int) -> None:
        """A rigid base (no elastic mode) unless the scene gives one."""
        k = np.shape(self.base_mode_frequency)[1] if self.base_mode_frequency is not None else 0
        m = np.shape(self.stage_mass)[1] if np.ndim(self.stage_mass) == 2 else 0
        p = np.shape(self.points)[1] if np.ndim(self.points) == 3 else 0
        for name, shape in (
            ("base_mode_frequency", (c, k)),
            ("base_mode_damping", (c, k)),
            ("base_mode_mass", (c, k)),
            ("base_mode_iso", (c, n, 3, k)),
            ("base_mode_stage", (c, m, 3, k)),
            ("base_mode_point", (c, p, 3, k)),
        ):
            if getattr(self, name) is None:
                setattr(self, name, np.zeros(shape) if name != "base_mode_mass" else np.ones(shape))

    @property
    def n_base_modes(self) -> int:
        """The number of the base's elastic modes (0: rigid)."""
        return int(np.asarray(self.base_mode_frequency).shape[1])

    @property
    def has_mount_branches(self) -> bool:
        """True when some mount has a relaxation branch (``iso_branch_k`` > 0)."""
        return bool(np.any(np.asarray(self.iso_branch_k) > 0))

    @property
    def has_floor_spectrum(self) -> bool:
        return bool(np.any(np.asarray(self.floor_band_velocity) != 0.0))

    @property
    def has_mount_floor(self) -> bool:
        """True when the floor differs between mounts or its coherence is not the uniform floor's."""
        return (
            self.floor_mount_band_velocity is not None
            or bool(np.any(np.asarray(self.floor_delay) != 0.0))
            or self.floor_coherence != "correlated"
        )

    @property
    def n_cases(self) -> int:
        return int(self.mass.shape[0])

    @property
    def n_isolators(self) -> int:
        return int(self.iso_pos.shape[1])

    @property
    def n_stages(self) -> int:
        return int(self.stage_mass.shape[1])

    @property
    def n_points(self) -> int:
        return int(self.points.shape[1])

    @property
    def has_feedforward(self) -> bool:
        """True when some mount feeds the stages' inertial wrench forward (a gain other than 0)."""
        return bool(np.any(np.asarray(self.iso_ff_gain) != 0.0))

    @property
    def has_orientation(self) -> bool:
        """True when some mount's own axes are not the floor's (``iso_frame`` other than the identity)."""
        return bool(np.any(np.asarray(self.iso_frame) != np.eye(3)))

    @property
    def has_floor_motion(self) -> bool:
        return bool(np.any(self.floor_amp != 0.0) or (len(self.floor_t) and np.any(self.floor_disp != 0.0)))

    def take(self, index: np.ndarray | slice | list[int]) -> SceneBatch:
        """The cases at ``index`` as a new batch (scene-level fields are shared)."""
        shared = {
            "stage_parent",
            "floor_t",
            "gravity_stiffness",
            "g",
            "preload_with_base",
            "preload_balanced",
            "floor_coherence",
        }
        kw: dict[str, Any] = {}
        for f in fields(self):
            v = getattr(self, f.name)
            kw[f.name] = v if f.name in shared or v is None else np.asarray(v)[index]
        return replace(self, **kw)

    def last_move_end(self) -> np.ndarray:
        """(C,) time at which every stage has come to rest for good, s."""
        t = self.prof_t
        if not t.shape[-1]:
            return np.zeros(self.n_cases)
        moving = (self.prof_v != 0.0) | (self.prof_a != 0.0) | (self.prof_j != 0.0)
        # a piece that moves ends where the next piece starts
        ends = np.concatenate([t[..., 1:], t[..., -1:]], axis=-1)
        last = np.where(moving, ends, 0.0).max(axis=-1)  # (C, m)
        return last.max(axis=-1) if last.shape[-1] else np.zeros(self.n_cases)

    def rest_intervals(self) -> tuple[np.ndarray, np.ndarray]:
        """The time intervals in which every stage is at rest after a move, per case.

        Interval ``k`` runs from ``t_k``, the end of a move (no stage moves from there on), to ``s_k``, the
        start of the next move of any stage, or ``+inf`` after the last move (the run's end closes it).
        The rest before the first move is not one (nothing has moved yet); a case without stage motion,
        or whose last piece moves for ever, has none after its last move. Gaps between moves shorter than
        ``1e-12`` s (relative to the time) are not rests: those moves run into each other.

        Returns:
            ``bounds`` (C, K, 2): ``t_k`` and ``s_k``, s, padded with NaN past each case's count;
            ``count`` (C,) int64: the number of rest intervals of each case (K = max(count, 1)).
        """
        C = self.n_cases
        t = np.asarray(self.prof_t, dtype=float)
        if t.ndim != 3 or t.shape[1] == 0 or t.shape[2] == 0:
            return np.full((C, 1, 2), np.nan), np.zeros(C, dtype=np.int64)
        moving = (self.prof_v != 0.0) | (self.prof_a != 0.0) | (self.prof_j != 0.0)
        # a moving piece runs until the next piece starts; a moving last piece for ever
        ends = np.concatenate([t[..., 1:], np.full(t.shape[:-1] + (1,), np.inf)], axis=-1)
        start = np.where(moving, t, np.inf).reshape(C, -1)
        end = np.where(moving, ends, -np.inf).reshape(C, -1)
        order = np.argsort(start, axis=1, kind="stable")
        start = np.take_along_axis(start, order, axis=1)
        reach = np.maximum.accumulate(np.take_along_axis(end, order, axis=1), axis=1)  # motion up to here
        after = np.concatenate([start[:, 1:], np.full((C, 1), np.inf)], axis=1)  # the next move's start
        gap = 1e-12 * np.maximum(1.0, np.abs(np.where(np.isfinite(reach), reach, 0.0)))
        rest = np.isfinite(start) & np.isfinite(reach) & (after > reach + gap)
        count = rest.sum(axis=1).astype(np.int64)
        bounds = np.full((C, max(int(count.max()), 1), 2), np.nan)
        for c in np.flatnonzero(count):
            bounds[c, : count[c], 0] = reach[c, rest[c]]
            bounds[c, : count[c], 1] = after[c, rest[c]]
        return bounds, count


def concat(batches: list[SceneBatch]) -> SceneBatch:
    """Join batches of the same scene shape along the case dimension."""
    first = batches[0]
    shared = {"stage_parent", "floor_t", "gravity_stiffness", "g", "preload_with_base", "preload_balanced"}
    shared.add("floor_coherence")
    kw = {}
    for f in fields(first):
        if f.name in shared:
            kw[f.name] = getattr(first, f.name)
        elif f.name == "floor_mount_band_velocity":
            kw[f.name] = _mount_floor(batches)
        else:
            kw[f.name] = np.concatenate([np.asarray(getattr(b, f.name)) for b in batches], axis=0)
    return replace(first, **kw)


def _mount_floor(batches: list[SceneBatch]) -> np.ndarray | None:
    """The joined ``floor_mount_band_velocity`` (None when no batch has one; a batch without one has its
    ``floor_band_velocity`` under every mount)."""
    if all(b.floor_mount_band_velocity is None for b in batches):
        return None
    parts = []
    for b in batches:
        v = b.floor_mount_band_velocity
        if v is None:
            v = np.repeat(np.asarray(b.floor_band_velocity)[:, None], b.n_isolators, axis=1)
        parts.append(np.asarray(v))
    return np.concatenate(parts, axis=0)
