"""One model's block of the extra linear states, and the lever-arm map the models share."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class SlotBlock(NamedTuple):
    """One model's block of the extra linear states ``z`` (``nz`` of them; ``Params.zA`` ...): ``z' = A z
    + X x + Q acc + S s''`` with ``x`` the base's state (12), ``acc`` its accelerations (6) and ``s''`` the
    stages' accelerations along their axes (m); the base's generalised force gains ``G z`` (and, at the LTI
    level, its accelerations ``Ms s''``); each point's displacement and each mount's deflection ``O[0] z``,
    their rates ``O[1] z``; each mount's force ``F z`` (where the states push through the mounts)."""

    A: np.ndarray
    """(C, nz, nz), 1/s."""
    X: np.ndarray
    """(C, nz, 12)."""
    Q: np.ndarray
    """(C, nz, 6)."""
    S: np.ndarray
    """(C, nz, m)."""
    G: np.ndarray
    """(C, 6, nz), N and N m per unit z."""
    O: np.ndarray
    """(C, 2, nz, 3 p + 3 n)."""
    B: np.ndarray | None = None
    """(C, 6, nz) the base's generalised force per unit ``z'`` (N s, N m s per unit z), or None: a model
    whose states carry inertia the base no longer does (a servo stage's mass along its axis). The LTI level
    folds it into its matrices: ``(M - B Q) acc = f + (G + B A) z + B X x + B S s''``; the LTV level refuses
    it."""
    D: np.ndarray | None = None
    """(C, nz) each row's dead band on its rate (the row's units per second), or None: every row linear. A
    row with a threshold ``D > 0`` (a levelling valve's) has its rate ``r`` replaced by ``sign(r) max(|r| -
    D, 0)`` in the stepping kernels (``engine.kernels.dynamics.slot_rates``); zero keeps a row linear."""
    F: np.ndarray | None = None
    """(C, nz, 3 n) the force each mount exerts on the base per unit ``z``, by axis of the floor frame (N per
    unit z): what a model's states add to the reported isolator forces and loads beyond the mount's static
    spring and damper (a relaxation branch's spring, a levelling valve's added force), or None: they add
    none (a flexible base's modes move the mounts' deflections instead, through ``O``)."""


def arm_map(d: np.ndarray) -> np.ndarray:
    """``T = [I, -[d]x]`` (C, k, 3, 6): a point's displacement ``u + theta x d`` from ``[u, theta]``."""
    T = np.zeros(d.shape[:2] + (3, 6))
    T[..., :, :3] = np.eye(3)
    T[..., 0, 4], T[..., 0, 5] = d[..., 2], -d[..., 1]  # -[d]x: theta x d
    T[..., 1, 3], T[..., 1, 5] = -d[..., 2], d[..., 0]
    T[..., 2, 3], T[..., 2, 4] = d[..., 1], -d[..., 0]
    return T
