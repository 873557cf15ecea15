"""The mounts' relaxation branches (an air mount's orifice, an elastomer's Maxwell ladder) as a block of
extra linear states (docs/physics.md, "Mounts with internal states"; the laws: ``engine.mount_laws``)."""

from __future__ import annotations

import numpy as np

from isolab.engine.linear_states.block import SlotBlock
from isolab.engine.mount_laws import branch_states
from isolab.engine.scene import SceneBatch


def mount_relaxation_block(b: SceneBatch) -> SlotBlock | None:
    """The mounts' relaxation branches as a block of extra linear states, one per branch and axis, or None
    when no mount has one. State ``w`` (m): a branch's series spring deflection, ``w' = delta' - w / tau``
    with ``delta = e . (u + theta x d)`` the mount's deflection along its own axis ``e`` (arm ``d`` from the
    c.g.); its force ``-k_b w e`` acts on the base at the mount and is part of the mount's reported force.
    Nothing is added to the points' or mounts' displacements (the branch moves inside the mount)."""
    j, a, k = branch_states(b)
    nz = j.size
    if nz == 0:
        return None
    C, m, p, n = b.n_cases, b.n_stages, b.n_points, b.n_isolators
    kb = np.asarray(b.iso_branch_k, dtype=float)[:, j, a, k]  # (C, nz)
    tau = np.asarray(b.iso_branch_tau, dtype=float)[:, j, a, k]
    tau = np.where(kb > 0, tau, 1.0)  # a branch absent in a case: a state that nothing drives or feels
    e = np.swapaxes(np.asarray(b.iso_frame, dtype=float)[:, j, :, a], 0, 1)  # (C, nz, 3) its own axis
    arm = (np.asarray(b.iso_pos, dtype=float) - np.asarray(b.cg, dtype=float)[:, None, :])[:, j]
    row = np.concatenate([e, np.cross(arm, e)], axis=-1)  # (C, nz, 6): delta = row . [u, theta]
    A = np.zeros((C, nz, nz))
    A[:, np.arange(nz), np.arange(nz)] = -1.0 / tau
    X = np.zeros((C, nz, 12))
    X[:, :, 6:] = row
    G = -np.swapaxes(row * kb[..., None], 1, 2)  # (C, 6, nz)
    F = np.zeros((C, nz, n, 3))  # the branch's force -k_b w e, part of its mount's
    F[:, np.arange(nz), j, :] = -kb[..., None] * e
    return SlotBlock(
        A,
        X,
        np.zeros((C, nz, 6)),
        np.zeros((C, nz, m)),
        G,
        np.zeros((C, 2, nz, 3 * p + 3 * n)),
        F=F.reshape(C, nz, 3 * n),
    )
