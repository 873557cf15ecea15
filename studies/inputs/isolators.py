"""Vibration isolator presets and the static load each mount carries.

Vendors describe an isolator by the natural frequency and damping ratio it gives the load it carries,
not by N/m. A preset of a type plus that load gives the stiffness ``k = (load/g) (2 pi f)^2`` and the
damping ``c = 2 zeta sqrt(k load/g)``. With every mount tuned to the same frequency for its own load, a
uniform static sag ``g / (2 pi f)^2`` balances the weight: the base sits level.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from isolab.studies.units import STANDARD_GRAVITY


@dataclass(frozen=True)
class Feedforward:
    """Feedforward of the stages' inertial wrench to an active mount's actuators.

    The stage controller knows its acceleration command; the isolation controller feeds it forward: each
    mount's actuators push on the base with their share of the opposite of the stages' reaction (the
    inertial force ``-sum m a`` and its moment about the c.g.), through a first-order low-pass.

    Attributes:
        gain: fraction of the wrench fed forward, 1 (0: none).
        bandwidth: corner frequency of the low-pass, Hz.
        force_limit: largest actuator force per mount and axis, N (``inf``: none).
        weight: also feed forward the change of the stages' weight moment (a stage that has travelled),
            as a levelling loop would hold it; False: the inertial wrench only.
    """

    gain: float = 1.0
    bandwidth: float = 50.0
    force_limit: float = float("inf")
    weight: bool = False


@dataclass(frozen=True)
class IsolatorPreset:
    """Typical figures of one kind of isolator.

    Attributes:
        f_vertical: natural frequency along Z with its rated load, Hz.
        f_horizontal: natural frequency along X and Y, Hz.
        zeta: viscous damping ratio, 1.
        skyhook: True when the damping acts on the machine's absolute velocity (active control).
        feedforward: the stage-force feedforward of an active mount, or None (passive mounts).
    """

    f_vertical: float
    f_horizontal: float
    zeta: float
    skyhook: bool
    feedforward: Feedforward | None = None


PRESETS: dict[str, IsolatorPreset] = {
    # Active (electronically controlled) isolators: about 1 Hz, heavily damped, sky-hook damping, and the
    # stage controller's acceleration command and position fed forward to the actuators: 95 % of the
    # stages' inertial wrench and of the change of their weight moment (as the system's levelling would
    # hold it: on 1 Hz mounts a travelling stage would otherwise tilt the base far more than its
    # acceleration does) through a 50 Hz low-pass, at most 5 kN per mount and axis (voice-coil or
    # piezo-pneumatic actuators of a few kN).
    "active": IsolatorPreset(
        f_vertical=1.0,
        f_horizontal=1.0,
        zeta=0.4,
        skyhook=True,
        feedforward=Feedforward(gain=0.95, bandwidth=50.0, force_limit=5000.0, weight=True),
    ),
    # Air (pneumatic) mounts: about 3 Hz in both directions, about 10 % damping (orifice damping).
    "air": IsolatorPreset(f_vertical=3.0, f_horizontal=3.0, zeta=0.10, skyhook=False),
    # Passive elastomer pads: about 10 Hz, a few percent damping.
    "elastomer": IsolatorPreset(f_vertical=10.0, f_horizontal=10.0, zeta=0.05, skyhook=False),
}
"""Isolator types and their typical vendor figures (natural frequency under rated load and damping
ratio): active ~1 Hz, air ~3 Hz, elastomer ~10 Hz, as quoted for precision machine bases."""


def mount_labels(count: int) -> list[str]:
    """Labels of a scene's ``count`` isolators, in batch order: ``mount_0``, ``mount_1``, ... (the
    ``isolator`` coordinate of a study's dataset and the keys of its per-isolator outputs)."""
    return [f"mount_{j}" for j in range(int(count))]


CENTRED_SHARE = 0.25
"""A mount within this share of the mounts' half-spread of their centre along an axis is named by the
other axis alone (``left``, ``front``), or ``centre``."""


def mount_places(positions: ArrayLike) -> list[str]:
    """Where each mount stands on the base, in words, from its (n, 3) positions (m, floor frame: Y along
    the machine): ``front-left`` for the smallest X and Y of the layout, ``back-right`` for the largest
    (-Y is the front, -X the left), ``front`` or ``left`` for a mount centred along the other axis,
    ``centre`` for one centred along both. Two mounts at one corner are both named by it."""
    xy = np.asarray(positions, dtype=np.float64).reshape(-1, 3)[:, :2]
    if xy.shape[0] == 0:
        return []
    offset = xy - xy.mean(axis=0)
    half = np.maximum(np.abs(offset).max(axis=0), 1e-12)
    places = []
    for dx, dy in offset:
        depth = "" if abs(dy) <= CENTRED_SHARE * half[1] else ("front" if dy < 0 else "back")
        side = "" if abs(dx) <= CENTRED_SHARE * half[0] else ("left" if dx < 0 else "right")
        places.append("-".join(w for w in (depth, side) if w) or "centre")
    return places


class CollinearIsolatorsError(ValueError):
    """The mounts lie on one line (or at one point): they cannot carry a rigid base."""


def load_share(iso_xy: ArrayLike, weight_point_xy: ArrayLike, total_weight: ArrayLike) -> np.ndarray:
    """Vertical static load of each isolator under a rigid base on equal vertical springs, N.

    The least-norm solution of the three statics equations ``sum f = W``, ``sum f x = W x_c``,
    ``sum f y = W y_c``: exact for three mounts, and for more mounts the loads of equal springs under a
    rigid base (linear in the mount position). A weight point far from the mounts' centre gives
    negative loads (a mount in tension).

    Args:
        iso_xy: (..., n, 2) mount positions in the floor plane, m.
        weight_point_xy: (..., 2) where the total weight acts (the composite c.g.), m.
        total_weight: (...) total weight, N.

    Returns:
        (..., n) vertical load per mount, N (positive in compression).

    Raises:
        ValueError: "isolators: all on one line" when the mounts are collinear (or fewer than three).
    """
    p = np.asarray(iso_xy, dtype=np.float64)
    c = np.asarray(weight_point_xy, dtype=np.float64)
    w = np.asarray(total_weight, dtype=np.float64)
    if p.ndim < 2 or p.shape[-1] != 2:
        raise ValueError(f"iso_xy: expected shape (..., n, 2), got {p.shape}")
    n = p.shape[-2]
    if n < 3:
        raise CollinearIsolatorsError(f"isolators: at least 3 are needed to carry a rigid base, got {n}")
    mean = p.mean(axis=-2)
    d = p - mean[..., None, :]
    scatter = np.einsum("...ni,...nj->...ij", d, d)
    det = scatter[..., 0, 0] * scatter[..., 1, 1] - scatter[..., 0, 1] * scatter[..., 1, 0]
    trace = scatter[..., 0, 0] + scatter[..., 1, 1]
    if np.any(~(det > 1e-12 * trace * trace)):
        raise CollinearIsolatorsError(
            "isolators: all on one line (a rigid base needs mounts spanning an area)"
        )
    lam = np.linalg.solve(scatter, (w[..., None] * (c - mean))[..., None])[..., 0]
    return w[..., None] / n + np.einsum("...ni,...i->...n", d, lam)


def stiffness_from_frequency(load: ArrayLike, f: ArrayLike, g: float = STANDARD_GRAVITY) -> np.ndarray:
    """Stiffness that gives natural frequency ``f`` (Hz) to the mass ``load / g`` (load in N), N/m."""
    m = np.asarray(load, dtype=np.float64) / g
    return m * (2.0 * np.pi * np.asarray(f, dtype=np.float64)) ** 2


def damping_from_ratio(
    k: ArrayLike, load: ArrayLike, zeta: ArrayLike, g: float = STANDARD_GRAVITY
) -> np.ndarray:
    """Viscous damping ``2 zeta sqrt(k m)``, m = load / g, N s/m (k in N/m, load in N, zeta in 1)."""
    m = np.asarray(load, dtype=np.float64) / g
    return 2.0 * np.asarray(zeta, dtype=np.float64) * np.sqrt(np.asarray(k, dtype=np.float64) * m)
