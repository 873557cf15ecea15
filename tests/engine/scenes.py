"""Small scenes for engine tests, built directly as arrays (no schema)."""

from __future__ import annotations

import numpy as np

from isolab.engine.scene import GRAVITY, SceneBatch


def box_inertia(mass: float, lx: float, ly: float, lz: float) -> np.ndarray:
    """Inertia tensor of a homogeneous block about its c.g., kg m^2."""
    return np.diag([mass * (ly**2 + lz**2) / 12, mass * (lx**2 + lz**2) / 12, mass * (lx**2 + ly**2) / 12])


def trapezoid_pieces(distance: float, v: float, a: float, start: float = 0.0) -> np.ndarray:
    """Pieces (t, s, v, a, j) of a trapezoidal move, shape (5, 4)."""
    d = abs(distance)
    sg = np.sign(distance) if distance else 1.0
    vp = min(v, np.sqrt(d * a))
    ta = vp / a
    tc = d / vp - ta if vp > 0 else 0.0
    t = start + np.array([0.0, ta, ta + max(tc, 0.0), 2 * ta + max(tc, 0.0)])
    s = sg * np.array([0.0, 0.5 * a * ta**2, 0.5 * a * ta**2 + vp * max(tc, 0.0), d])
    vv = sg * np.array([0.0, vp, vp, 0.0])
    aa = sg * np.array([a, 0.0, -a, 0.0])
    return np.stack([t, s, vv, aa, np.zeros(4)])


def scene(
    n_cases: int = 1,
    mass: float = 10_000.0,
    size: tuple[float, float, float] = (2.6, 4.2, 0.34),
    span: tuple[float, float] = (2.2, 3.6),
    height: float = 0.0,
    k: tuple[float, float, float] = (1e6, 1e6, 2e6),
    c: tuple[float, float, float] = (1e4, 1e4, 2e4),
    skyhook: bool = False,
    stages: list[dict] | None = None,
    points: list[tuple[float, float, float]] | None = None,
    duration: float = 2.0,
    gravity_stiffness: bool = True,
    g: float = GRAVITY,
    floor_amp=(0.0, 0.0, 0.0),
    floor_freq=(0.0, 0.0, 0.0),
) -> SceneBatch:
    """Four identical mounts at (+-span_x/2, +-span_y/2, -height) around the c.g. at the origin.

    ``stages``: dicts with mass, home (3,), axis (3,), pieces (5, K) and optional parent.
    """
    C = n_cases
    sx, sy = span[0] / 2, span[1] / 2
    pos = np.array([[sx, sy, -height], [-sx, sy, -height], [-sx, -sy, -height], [sx, -sy, -height]])
    stages = stages or []
    m = len(stages)
    K = max((s["pieces"].shape[1] for s in stages), default=1)
    prof = np.zeros((5, m, K))
    for i, st in enumerate(stages):
        p = st["pieces"]
        prof[:, i, : p.shape[1]] = p
        if p.shape[1] < K:  # pad with rest pieces at the final position
            prof[0, i, p.shape[1] :] = p[0, -1]
            prof[1, i, p.shape[1] :] = p[1, -1]
    rep = lambda a: np.repeat(np.asarray(a, dtype=float)[None], C, axis=0)  # noqa: E731
    pts = np.array(points or [(0.0, 0.0, 0.0)], dtype=float)
    return SceneBatch(
        mass=np.full(C, mass),
        inertia=rep(box_inertia(mass, *size)),
        cg=np.zeros((C, 3)),
        iso_pos=rep(pos),
        iso_k=rep(np.tile(k, (4, 1))),
        iso_c=rep(np.tile(c, (4, 1))),
        iso_skyhook=np.full((C, 4), skyhook),
        stage_mass=rep([s["mass"] for s in stages]).reshape(C, m),
        stage_home=rep([s["home"] for s in stages]).reshape(C, m, 3),
        stage_axis=rep([s["axis"] for s in stages]).reshape(C, m, 3),
        stage_parent=np.array([s.get("parent", -1) for s in stages], dtype=np.int64),
        prof_t=rep(prof[0]),
        prof_s=rep(prof[1]),
        prof_v=rep(prof[2]),
        prof_a=rep(prof[3]),
        prof_j=rep(prof[4]),
        points=rep(pts),
        floor_amp=rep(floor_amp),
        floor_freq=rep(floor_freq),
        floor_phase=np.zeros((C, 3)),
        duration=np.full(C, duration),
        gravity_stiffness=gravity_stiffness,
        g=g,
    )


def y_stage(
    mass: float = 1000.0,
    travel: float = 3.0,
    v: float = 2.0,
    a: float = 2 * GRAVITY,
    home=(0.0, -1.5, 0.3),
    start: float = 0.0,
) -> dict:
    """A stage along +Y doing one trapezoidal move."""
    pieces = trapezoid_pieces(travel, v, a, start)
    return {"mass": mass, "home": home, "axis": (0.0, 1.0, 0.0), "pieces": pieces}


def mount(load: float, freq: float, zeta: float) -> tuple[float, float]:
    """Stiffness (N/m) and damping (N s/m) of a mount of natural frequency ``freq`` (Hz) and damping
    ratio ``zeta`` (1) under ``load`` (kg): ``k = m (2 pi f)^2``, ``c = 2 zeta sqrt(k m)``."""
    k = load * (2 * np.pi * freq) ** 2
    return k, 2 * zeta * np.sqrt(k * load)


def vertical_stage(mass: float, accel: float, home=(0.0, 0.0, 0.0)) -> dict:
    """A stage along +Z accelerating at a constant ``accel`` (m/s^2) from rest at t = 0 (one piece).

    At the c.g. its only effect on the base is the constant vertical force ``-mass * accel`` (N): its weight
    stays on the vertical through the c.g., so the moment of the weight does not change.
    """
    pieces = np.array([[0.0], [0.0], [0.0], [accel], [0.0]])
    return {"mass": mass, "home": home, "axis": (0.0, 0.0, 1.0), "pieces": pieces}


def pieces_array(p) -> np.ndarray:
    """The first case of an ``engine.profiles.Pieces`` as the (5, K) array ``scene`` takes."""
    return np.stack([np.asarray(x, dtype=float)[0] for x in (p.t, p.s, p.v, p.a, p.j)])


ONE_MODE_BASE, ONE_MODE_PUSH, ONE_MODE_W = 1000.0, 10.0, 1000.0
"""The one-mode system: base mass (kg), pushing stage mass (kg) and heave angular frequency (rad/s)."""


def one_mode(zeta: float, n_cases: int = 1) -> SceneBatch:
    """Heave is the one excited mode and the fastest by far (mounts near the c.g. under a wide base, soft
    horizontally): a vertical force through the c.g. from a stage accelerating at 1 m/s^2; heave at
    :data:`ONE_MODE_W` rad/s with damping ratio ``zeta``."""
    mt = ONE_MODE_BASE + ONE_MODE_PUSH
    kz = mt * ONE_MODE_W**2 / 4
    cz = 2 * zeta * np.sqrt(kz * mt / 4)
    return scene(
        n_cases=n_cases,
        mass=ONE_MODE_BASE,
        size=(2.0, 2.0, 0.5),
        span=(0.4, 0.4),
        k=(kz / 100, kz / 100, kz),
        c=(cz / 100, cz / 100, cz),
        stages=[vertical_stage(ONE_MODE_PUSH, 1.0)],
        duration=1.0,
    )


def run_unguarded(
    b: SceneBatch, integrator: str, steps: np.ndarray, n_steps: int
) -> tuple[np.ndarray, np.ndarray]:
    """Run an integrator's kernel directly on the LTI level (no stability guard) at per-case ``steps`` (s):
    (status, peak |u| m)."""
    from isolab.engine import model
    from isolab.engine.integrators import INTEGRATORS
    from isolab.engine.kernels import peaks
    from isolab.engine.kernels.params import LTI

    C = b.n_cases
    P, W = model.params(b), model.work(b)
    O = peaks.allocate(
        C, b.n_points, b.n_isolators, model.static_offset(b, "lti"), b.last_move_end(), b.settle_tol, None, 0
    )
    status = np.zeros(C, dtype=np.int8)
    INTEGRATORS[integrator].run(
        P, LTI, np.asarray(steps, dtype=float), np.full(C, n_steps, dtype=np.int64), O, W, status
    )
    return status, O.u
