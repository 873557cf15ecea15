"""Modal analysis of the base on its isolators, with the stages at home.

Undamped modes from ``K phi = w^2 M phi`` (mass-normalised), modal damping ratios from the diagonal of
``phi^T C phi``, and the kinetic-energy share of each degree of freedom in each mode.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from isolab.engine.results import DOF_NAMES

MECHANISM_RTOL = 1e-9
"""A mode whose ``w^2`` is below this fraction of the largest is a zero-stiffness (mechanism) mode."""
MOTION_NAMES = {"x": "surge", "y": "sway", "z": "heave", "rx": "pitch", "ry": "roll", "rz": "yaw"}
"""The motion of the base along or about each degree of freedom (rotation about X is pitch, about Y roll):
the words a mode is named by."""


@dataclass
class Modes:
    """Modes of ``C`` cases, ascending in frequency.

    Attributes:
        frequency: (C, 6) natural frequencies, Hz (0 for a mechanism or a tipping mode).
        damping_ratio: (C, 6) modal damping ratios, 1 (0 for a mechanism).
        energy: (C, 6, 6) kinetic-energy share of each DOF (last axis) in each mode; rows sum to 1.
        shapes: (C, 6, 6) mass-normalised mode shapes, columns are modes.
        mechanism: (C, 6) True for a zero-stiffness mode.
        tipping: (C,) True where a mode has negative stiffness (the base tips over).
        omega2: (C, 6) eigenvalues w^2, (rad/s)^2.
    """

    frequency: np.ndarray
    damping_ratio: np.ndarray
    energy: np.ndarray
    shapes: np.ndarray
    mechanism: np.ndarray
    tipping: np.ndarray
    omega2: np.ndarray


def modes(M: np.ndarray, K: np.ndarray, C: np.ndarray) -> Modes:
    """Modes of ``M q'' + C q' + K q = 0`` for matrices (C, 6, 6) in SI."""
    L = np.linalg.cholesky(M)
    Linv = np.linalg.inv(L)
    S = Linv @ K @ np.swapaxes(Linv, -1, -2)
    S = 0.5 * (S + np.swapaxes(S, -1, -2))
    w2, V = np.linalg.eigh(S)
    phi = np.swapaxes(Linv, -1, -2) @ V  # mass-normalised: phi^T M phi = I
    scale = np.maximum(np.abs(w2).max(axis=-1, keepdims=True), np.finfo(float).tiny)
    mech = np.abs(w2) <= MECHANISM_RTOL * scale
    tipping = ((w2 < 0) & ~mech).any(axis=-1)
    w = np.sqrt(np.where(mech | (w2 < 0), 0.0, w2))
    cmod = np.einsum("cik,cij,cjk->ck", phi, C, phi)
    with np.errstate(divide="ignore", invalid="ignore"):
        zeta = np.where(w > 0, cmod / (2.0 * np.where(w > 0, w, 1.0)), 0.0)
    Mphi = M @ phi
    share = np.abs(phi * Mphi)  # (C, dof, mode)
    share = share / share.sum(axis=1, keepdims=True)
    return Modes(
        frequency=w / (2 * np.pi),
        damping_ratio=zeta,
        energy=np.swapaxes(share, -1, -2),
        shapes=phi,
        mechanism=mech,
        tipping=tipping,
        omega2=w2,
    )


def motion_mode(energy: np.ndarray, dof: str) -> np.ndarray:
    """(C,) index (0-based, ascending frequency) of the mode in which the degree of freedom ``dof`` (one of
    ``DOF_NAMES``) holds its largest kinetic-energy share, from ``energy`` (C, 6, 6) as :func:`modes` gives
    it: the mode that moves the base most along or about that axis (the lower one on a tie)."""
    return np.argmax(np.asarray(energy)[:, :, DOF_NAMES.index(dof)], axis=1)


def state_matrix(M: np.ndarray, K: np.ndarray, C: np.ndarray) -> np.ndarray:
    """First-order system matrix (C, 12, 12) of ``[q, q']``, 1/s."""
    n = M.shape[0]
    Minv = np.linalg.inv(M)
    A = np.zeros((n, 12, 12))
    A[:, :6, 6:] = np.eye(6)
    A[:, 6:, :6] = -Minv @ K
    A[:, 6:, 6:] = -Minv @ C
    return A


def transmissibility(
    M: np.ndarray,
    K: np.ndarray,
    C: np.ndarray,
    d: np.ndarray,
    k: np.ndarray,
    c_rel: np.ndarray,
    freq: np.ndarray,
) -> np.ndarray:
    """|c.g. displacement / floor displacement| per axis (C, 3) at the floor frequency ``freq`` (C, 3) Hz.

    ``d`` (C, n, 3) isolator lever arms (m), ``k`` (C, n, 3) stiffness (N/m), ``c_rel`` (C, n, 3) the
    damping that acts on the relative velocity (N s/m; zero for sky-hook mounts). The floor moves along one
    axis at a time; the answer is the steady-state amplitude ratio of the c.g. along that axis.
    """
    Cn = M.shape[0]
    T = np.zeros((Cn, 3))
    for a in range(3):
        w = 2 * np.pi * freq[:, a]
        unit = np.zeros(d.shape)
        unit[..., a] = 1.0
        force = (k + 1j * w[:, None, None] * c_rel) * unit
        f = np.zeros((Cn, 6), dtype=complex)
        f[:, :3] = force.sum(axis=1)
        f[:, 3:] = np.cross(d, force).sum(axis=1)
        D = -(w**2)[:, None, None] * M + 1j * w[:, None, None] * C + K
        q = np.linalg.solve(D, f[..., None])[..., 0]
        T[:, a] = np.where(freq[:, a] > 0, np.abs(q[:, a]), 0.0)
    return T
