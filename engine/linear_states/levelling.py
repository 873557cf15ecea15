"""Levelling valves of air mounts as a block of extra linear states (docs/isolators.md, "Levelling valves";
docs/physics.md, "Levelling valves")."""

from __future__ import annotations

import numpy as np

from isolab.engine.linear_states.block import SlotBlock, arm_map
from isolab.engine.scene import SceneBatch, SceneError

MAX_VALVES = 3
"""The most valves a rigid base takes: three set its heave, roll and pitch; a fourth would fight them."""
LEVELLING_LEVELS = ("lti", "ltv")
"""The levels that model levelling valves."""
LEVELLING_INTEGRATORS = ("rk4", "exact")
"""The integrators that step them without a dead band."""
DEAD_BAND_INTEGRATORS = ("rk4",)
"""The integrators that step a dead band (a nonlinearity: the exact integrator's maps are linear)."""


def valve_groups(b: SceneBatch) -> list[np.ndarray]:
    """The mounts on each valve (``SceneBatch.iso_valve``, the same in every case), valves in ascending
    order of their index: a list of mount index arrays, empty when no mount has a valve."""
    v = np.asarray(b.iso_valve)
    if v.ndim != 2 or v.shape[0] == 0:
        return []
    return [np.flatnonzero(v[0] == k) for k in np.unique(v[0][v[0] >= 0]).tolist()]


def check_levelling(b: SceneBatch, fidelity: str, integrator: str) -> None:
    """Refuse levelling valves (``iso_valve``) where they are not modelled, naming the input and the
    levels and integrators that model them; more than :data:`MAX_VALVES` valves; and valves together with
    a floor motion or a flexible base."""
    groups = valve_groups(b)
    if not groups:
        return
    field = "iso_valve"
    if len(groups) > MAX_VALVES:
        raise SceneError(
            field,
            f"{len(groups)} levelling valves over-determine the base's heave, roll and pitch (the valves "
            f"would fight and the load split is indeterminate); use at most {MAX_VALVES}: plumb two mounts "
            "to one valve (three-point levelling)",
        )
    if fidelity not in LEVELLING_LEVELS:
        raise SceneError(
            field,
            f"levelling valves are modelled at the {' and '.join(LEVELLING_LEVELS)} levels, not {fidelity!r}",
        )
    if integrator not in LEVELLING_INTEGRATORS:
        raise SceneError(
            field,
            f"levelling valves are integrated by {' or '.join(LEVELLING_INTEGRATORS)}, not {integrator!r}",
        )
    if integrator not in DEAD_BAND_INTEGRATORS and np.any(np.asarray(b.iso_level_band) > 0):
        raise SceneError(
            "iso_level_band",
            f"a levelling valve's dead band is a nonlinearity that {integrator!r} (linear maps) does not "
            f"step; integrate with {' or '.join(DEAD_BAND_INTEGRATORS)}, or give a dead band of 0",
        )
    if b.has_floor_motion:
        raise SceneError(field, "levelling valves are not modelled together with a floor motion (not yet)")
    if b.n_base_modes > 0:
        raise SceneError(
            field,
            "levelling valves are not modelled together with a flexible base (base_mode_frequency; not yet: "
            "the valve would sense and push the base's modes at its mounts)",
        )


def levelling_block(b: SceneBatch) -> SlotBlock | None:
    """The levelling valves' added forces as a block of extra linear states, ``z = [F_v]`` (N, one per
    valve), or None when no mount has a valve. With ``h_v`` the mean vertical deflection (base up
    positive, m) of the mounts on valve ``v`` from the base's rigid state, ``k_v`` their vertical
    stiffness summed (N/m) and ``tau`` the valve's levelling time constant (s):

        F_v' = -(k_v / tau) DB(h_v, d),    DB(u, d) = sign(u) max(|u| - d, 0)

    with ``d`` the valve's dead band (m; zero: linear). ``F_v`` is shared equally by the valve's mounts and
    acts upward on the base at each mount's point (force and moment through ``G``; each mount's share is
    part of its reported force and load). The dead band is the
    threshold ``D`` of the row's rate, ``(k_v / tau) d`` (N/s), applied by the stepping kernels
    (``engine.kernels.dynamics.slot_rates``)."""
    groups = valve_groups(b)
    if not groups:
        return None
    C, n, m, p = b.n_cases, b.n_isolators, b.n_stages, b.n_points
    V = len(groups)
    T = arm_map(b.iso_pos - b.cg[:, None, :])  # (C, n, 3, 6)
    Q = np.asarray(b.iso_frame, dtype=float)
    kz = np.einsum("cnk,cnk->cn", Q[:, :, 2, :] ** 2, np.asarray(b.iso_k, dtype=float))  # floor z-z
    tau = np.asarray(b.iso_level_time, dtype=float)
    band = np.asarray(b.iso_level_band, dtype=float)
    X = np.zeros((C, V, 12))
    G = np.zeros((C, 6, V))
    D = np.zeros((C, V))
    F = np.zeros((C, V, n, 3))  # each mount's share of its valve's force, upward: part of its reported force
    for v, mounts in enumerate(groups):
        first = int(mounts[0])
        gain = kz[:, mounts].sum(axis=1) / tau[:, first]  # k_v / tau, N/(m s)
        rows = T[:, mounts, 2, :].mean(axis=1)  # (C, 6): h_v per unit [u, theta]
        X[:, v, :6] = -gain[:, None] * rows
        G[:, :, v] = rows
        D[:, v] = gain * band[:, first]
        F[:, v, mounts, 2] = 1.0 / mounts.size
    zero = np.zeros
    return SlotBlock(
        zero((C, V, V)),
        X,
        zero((C, V, 6)),
        zero((C, V, m)),
        G,
        zero((C, 2, V, 3 * p + 3 * n)),
        None,
        D,
        F.reshape(C, V, 3 * n),
    )
