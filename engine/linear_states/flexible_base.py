"""A flexible base's elastic modes as a block of extra linear states (docs/physics.md, "A flexible base")."""

from __future__ import annotations

import numpy as np

from isolab.engine.linear_states.block import SlotBlock, arm_map
from isolab.engine.scene import SceneBatch


def flexible_base_block(b: SceneBatch) -> SlotBlock | None:
    """The base's elastic modes as a block of extra linear states, ``z = [eta (k), eta' (k)]`` (modal
    coordinates, m), or None for a rigid base (docs/physics.md, "A flexible base"). Modal superposition:
    ``M_k (eta'' + 2 zeta w eta' + w^2 eta) = Phi_mounts^T F_mounts + Phi_stages^T F_stages`` with the
    mounts' forces from the base's rigid motion plus ``Phi eta`` at their points; the stages' masses load
    the modes at their homes (``M_k = m_k + sum m_s |phi_s|^2``) and their inertial forces along their
    axes drive them; the mounts' modal forces push back on the rigid base."""
    k = b.n_base_modes
    if k == 0:
        return None
    C, n, m, p = b.n_cases, b.n_isolators, b.n_stages, b.n_points
    d = b.iso_pos - b.cg[:, None, :]
    T = arm_map(d)  # (C, n, 3, 6)
    phi_j = np.asarray(b.base_mode_iso, dtype=float)  # (C, n, 3, k)
    phi_s = np.asarray(b.base_mode_stage, dtype=float)
    mk = np.asarray(b.base_mode_mass, dtype=float) + np.einsum("cs,csak,csak->ck", b.stage_mass, phi_s, phi_s)
    w = 2.0 * np.pi * np.asarray(b.base_mode_frequency, dtype=float)
    zeta = np.asarray(b.base_mode_damping, dtype=float)
    kk = np.asarray(b.iso_k, dtype=float)
    cc = np.asarray(b.iso_c, dtype=float)
    K_eq = np.einsum("cnak,cna,cnaj->ckj", phi_j, kk, T)  # (C, k, 6) Phi^T K T
    C_eq = np.einsum("cnak,cna,cnaj->ckj", phi_j, cc, T)
    K_ee = np.einsum("cnak,cna,cnal->ckl", phi_j, kk, phi_j)  # (C, k, k)
    C_ee = np.einsum("cnak,cna,cnal->ckl", phi_j, cc, phi_j)
    own = np.asarray(b.base_mode_mass, dtype=float)
    inv = 1.0 / mk[..., None]
    A = np.zeros((C, 2 * k, 2 * k))
    A[:, :k, k:] = np.eye(k)
    A[:, k:, :k] = -inv * (K_ee + np.einsum("ck,kl->ckl", own * w**2, np.eye(k)))
    A[:, k:, k:] = -inv * (C_ee + np.einsum("ck,kl->ckl", 2.0 * own * zeta * w, np.eye(k)))
    X = np.zeros((C, 2 * k, 12))
    X[:, k:, :6] = -inv * K_eq
    X[:, k:, 6:] = -inv * C_eq
    # a stage's inertial force -m_i a_rel,i at its home; a_rel,i = sum over its chain of s''_q e_q
    e = b.stage_axis / np.maximum(np.linalg.norm(b.stage_axis, axis=-1, keepdims=True), 1e-300)
    S = np.zeros((C, 2 * k, m))
    for i in range(m):
        q = i
        while q >= 0:
            S[:, k:, q] -= b.stage_mass[:, i, None] * np.einsum("cak,ca->ck", phi_s[:, i], e[:, q]) / mk
            q = int(b.stage_parent[q])
    G = np.zeros((C, 6, 2 * k))
    G[:, :, :k] = -np.swapaxes(K_eq, 1, 2)
    G[:, :, k:] = -np.swapaxes(C_eq, 1, 2)
    shapes = np.concatenate(
        [np.asarray(b.base_mode_point, dtype=float).reshape(C, 3 * p, k), phi_j.reshape(C, 3 * n, k)], axis=1
    )  # (C, 3 p + 3 n, k)
    O = np.zeros((C, 2, 2 * k, 3 * p + 3 * n))
    O[:, 0, :k] = np.swapaxes(shapes, 1, 2)
    O[:, 1, k:] = np.swapaxes(shapes, 1, 2)
    return SlotBlock(A, X, np.zeros((C, 2 * k, 6)), S, G, O)
