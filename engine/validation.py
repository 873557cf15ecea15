"""Refuse input that cannot describe a physical scene, naming the field and the reason."""

from __future__ import annotations

from dataclasses import fields

import numpy as np
from numpy.typing import ArrayLike

from isolab.engine.scene import SceneBatch, SceneError

MAX_LENGTH = 100.0
"""Largest coordinate (m) any machine this tool models may have."""


def _case(bad: ArrayLike) -> str:
    """`` (case c)`` naming the first case flagged in ``bad`` (C,), or nothing for a scene-level flag."""
    flags = np.asarray(bad)
    where = np.argwhere(flags)
    return f" (case {int(where[0][0])})" if where.size and flags.ndim else ""


FLOOR_COHERENCE = ("correlated", "uncorrelated", "worst_phase")
"""How the floor motions under different mounts combine (``SceneBatch.floor_coherence``)."""


def validate(b: SceneBatch) -> None:
    """Raise ``SceneError`` for the first field of ``b`` that is not finite, has the wrong shape or is
    physically impossible."""
    C = b.n_cases
    if C < 1:
        raise SceneError("cases", "a batch needs at least one case")
    if b.preload_with_base and b.preload_balanced:
        raise SceneError("preload_balanced", "the preload either turns with the base or balances the weights")
    for f in fields(b):
        v = getattr(b, f.name)
        if isinstance(v, np.ndarray) and v.dtype.kind == "f":
            if f.name == "iso_ff_limit":  # +inf: no actuator force limit
                bad = np.isnan(v) | (v == -np.inf)
                if bad.any():
                    raise SceneError(f.name, "must be a number or +inf (no limit)" + _case(bad))
                continue
            bad = ~np.isfinite(v)
            if bad.any():
                raise SceneError(f.name, "must be finite (got NaN or infinity)" + _case(bad))
    n, m = b.n_isolators, b.n_stages
    shapes = {
        "inertia": (C, 3, 3),
        "cg": (C, 3),
        "iso_pos": (C, n, 3),
        "iso_k": (C, n, 3),
        "iso_c": (C, n, 3),
        "iso_skyhook": (C, n),
        "stage_mass": (C, m),
        "stage_home": (C, m, 3),
        "stage_axis": (C, m, 3),
        "stage_parent": (m,),
        "points": (C, b.n_points, 3),
        "floor_amp": (C, 3),
        "floor_freq": (C, 3),
        "floor_phase": (C, 3),
        "floor_band_velocity": (C, 3, 20),
        "duration": (C,),
        "settle_tol": (C,),
        "point_settle_tol": (C, b.n_points),
    }
    if b.floor_coherence not in FLOOR_COHERENCE:
        raise SceneError(
            "floor_coherence", f"{b.floor_coherence!r} is not one of {', '.join(FLOOR_COHERENCE)}"
        )
    for name, shape in shapes.items():
        if np.shape(getattr(b, name)) != shape:
            raise SceneError(name, f"shape {np.shape(getattr(b, name))}, expected {shape}")
    K = b.prof_t.shape[-1] if b.prof_t.ndim == 3 else 0
    for name in ("prof_t", "prof_s", "prof_v", "prof_a", "prof_j"):
        if np.shape(getattr(b, name)) != (C, m, K):
            raise SceneError(name, f"shape {np.shape(getattr(b, name))}, expected {(C, m, K)}")
    if not np.isfinite(b.g) or b.g < 0:
        raise SceneError("g", f"must be a finite, non-negative acceleration, got {b.g}")
    if (b.mass <= 0).any():
        raise SceneError("mass", "must be positive" + _case(b.mass <= 0))
    I = np.asarray(b.inertia)
    if not np.allclose(I, np.swapaxes(I, -1, -2), rtol=1e-9, atol=1e-12 * np.abs(I).max()):
        raise SceneError("inertia", "must be symmetric")
    if (np.linalg.eigvalsh(I).min(axis=-1) <= 0).any():
        raise SceneError("inertia", "must be positive definite")
    if n < 3:
        raise SceneError("iso_pos", f"a base needs at least 3 isolators, got {n}")
    per_mount: dict[str, tuple[int, ...]] = {
        "floor_delay": (C, n)
    }  # checked after the isolator count, which names the cause
    if b.floor_mount_band_velocity is not None:
        per_mount["floor_mount_band_velocity"] = (C, n, 3, 20)
    for name, shape in per_mount.items():
        if np.shape(getattr(b, name)) != shape:
            raise SceneError(name, f"shape {np.shape(getattr(b, name))}, expected {shape}")
    if (b.iso_k < 0).any():
        raise SceneError("iso_k", "stiffness must not be negative" + _case((b.iso_k < 0).any(axis=(1, 2))))
    if (b.iso_c < 0).any():
        raise SceneError("iso_c", "damping must not be negative" + _case((b.iso_c < 0).any(axis=(1, 2))))
    Q = np.asarray(b.iso_frame, dtype=float)
    if Q.shape != (C, n, 3, 3):
        raise SceneError("iso_frame", f"shape {Q.shape}, expected {(C, n, 3, 3)}")
    skewed = np.abs(np.einsum("cnki,cnkj->cnij", Q, Q) - np.eye(3)).max(axis=(2, 3)) > 1e-9
    if skewed.any() or (np.linalg.det(Q) <= 0).any():
        raise SceneError(
            "iso_frame",
            "each mount's axes must be a rotation (orthonormal, right-handed)" + _case(skewed.any(axis=1)),
        )
    if b.has_orientation and (b.has_floor_motion or b.has_floor_spectrum):
        raise SceneError(
            "iso_frame", "mounts with their own axes do not take floor motion or a floor spectrum yet"
        )
    for name in ("iso_ff_gain", "iso_ff_bandwidth", "iso_ff_limit", "iso_ff_weight"):
        if np.shape(getattr(b, name)) != (C, n):
            raise SceneError(name, f"shape {np.shape(getattr(b, name))}, expected {(C, n)}")
    gain, bandwidth, limit = (np.asarray(v) for v in (b.iso_ff_gain, b.iso_ff_bandwidth, b.iso_ff_limit))
    if (gain < 0).any():
        raise SceneError("iso_ff_gain", "feedforward gain must not be negative" + _case(gain < 0))
    slow = (gain != 0) & ~(bandwidth > 0)
    if slow.any():
        raise SceneError(
            "iso_ff_bandwidth", "must be positive where a mount feeds forward" + _case(slow.any(axis=1))
        )
    if (limit <= 0).any():
        raise SceneError(
            "iso_ff_limit", "actuator force limit must be positive" + _case((limit <= 0).any(axis=1))
        )
    for name in ("iso_pos", "stage_home", "points", "cg"):
        v = np.asarray(getattr(b, name))
        if v.size and (np.abs(v) > MAX_LENGTH).any():
            raise SceneError(name, f"coordinates beyond {MAX_LENGTH} m")
    xy = b.iso_pos[..., :2] - b.iso_pos[..., :1, :2]
    # not all on one line: the xy spread must span a plane
    sv = np.linalg.svd(xy, compute_uv=False)
    span = np.abs(b.iso_pos[..., :2]).max(axis=(1, 2)) + 1.0
    if (sv[:, 1] <= 1e-9 * span).any():
        raise SceneError("iso_pos", "isolators all on one line (in plan view): the base would topple")
    if (b.stage_mass < 0).any():
        raise SceneError("stage_mass", "must not be negative")
    if m:
        norm = np.linalg.norm(b.stage_axis, axis=-1)
        if (norm < 1e-12).any():
            raise SceneError("stage_axis", "must not be the zero vector")
        parent = np.asarray(b.stage_parent)
        for i, p in enumerate(parent):
            if not -1 <= p < i:
                raise SceneError(
                    "stage_parent", f"stage {i} rides on {p}: a parent must come before its child"
                )
        if (np.diff(b.prof_t, axis=-1) < 0).any():
            raise SceneError("prof_t", "piece start times must not decrease")
    _check_servo_and_relative(b)
    if (np.asarray(b.duration) <= 0).any():
        raise SceneError("duration", "must be positive")
    if (np.asarray(b.settle_tol) <= 0).any():
        raise SceneError("settle_tol", "must be positive")
    point_tol = np.asarray(b.point_settle_tol)
    if (point_tol <= 0).any():
        raise SceneError("point_settle_tol", "must be positive" + _case((point_tol <= 0).any(axis=1)))
    if (b.floor_freq < 0).any():
        raise SceneError("floor_freq", "must not be negative")
    band = np.asarray(b.floor_band_velocity)
    if not (np.isfinite(band) & (band >= 0)).all():
        raise SceneError("floor_band_velocity", "must be finite and not negative")
    if b.floor_mount_band_velocity is not None and (np.asarray(b.floor_mount_band_velocity) < 0).any():
        raise SceneError("floor_mount_band_velocity", "must not be negative")
    if len(b.floor_t):
        disp = np.asarray(b.floor_disp)
        if disp.shape != (C, 3, len(b.floor_t)):
            raise SceneError("floor_disp", f"shape {disp.shape}, expected {(C, 3, len(b.floor_t))}")
        if (np.diff(b.floor_t) <= 0).any():
            raise SceneError("floor_t", "sample times must increase")


def _check_servo_and_relative(b: SceneBatch) -> None:
    """The servo stages' figures and the relative points' stages."""
    C, m, p = b.n_cases, b.n_stages, b.n_points
    for name, shape in (
        ("stage_servo_frequency", (C, m)),
        ("stage_servo_damping", (C, m)),
        ("point_relative", (C, p)),
        ("point_tool_stage", (C, p)),
        ("point_work_stage", (C, p)),
    ):
        if np.shape(getattr(b, name)) != shape:
            raise SceneError(name, f"shape {np.shape(getattr(b, name))}, expected {shape}")
    f = np.asarray(b.stage_servo_frequency, dtype=float)
    z = np.asarray(b.stage_servo_damping, dtype=float)
    if not (np.isfinite(f).all() and (f >= 0).all()):
        raise SceneError(
            "stage_servo_frequency", "must be finite and not negative" + _case(~(f >= 0).all(axis=1))
        )
    mixed = (f > 0).any(axis=0) & ~(f > 0).all(axis=0)
    if mixed.any():
        raise SceneError(
            "stage_servo_frequency",
            f"stage {int(np.flatnonzero(mixed)[0])} is on a servo in some cases and not in others; give "
            "every case a positive frequency or none",
        )
    if not (np.isfinite(z).all() and (z >= 0).all()):
        raise SceneError(
            "stage_servo_damping", "must be finite and not negative" + _case(~(z >= 0).all(axis=1))
        )
    kind = np.asarray(b.point_relative)
    if not np.isin(kind, (0, 1, 2)).all():
        raise SceneError(
            "point_relative", "must be 0 (a material point), 1 (relative) or 2 (following error)"
        )
    for name in ("point_tool_stage", "point_work_stage"):
        s = np.asarray(getattr(b, name))
        if ((s < -1) | (s >= m)).any():
            raise SceneError(name, f"a stage index must be -1 (the base) or 0..{m - 1}")
