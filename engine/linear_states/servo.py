"""Stages on a servo: their following errors as a block of extra linear states (docs/physics.md, "Servo
stages")."""

from __future__ import annotations

import numpy as np

from isolab.engine.linear_states.block import SlotBlock
from isolab.engine.scene import SceneBatch, SceneError


def stage_chains(b: SceneBatch) -> np.ndarray:
    """(m, m) bool: ``[i, q]`` when stage ``q`` carries stage ``i`` (``q`` is ``i`` or one it rides on)."""
    m = b.n_stages
    chain = np.zeros((m, m), dtype=bool)
    for i in range(m):
        q = i
        while q >= 0:
            chain[i, q] = True
            q = int(b.stage_parent[q])
    return chain


def carried_mass(b: SceneBatch) -> np.ndarray:
    """(C, m) the mass each stage's drive moves along its axis: its own and every stage's riding on it, kg."""
    return np.einsum("ci,iq->cq", np.asarray(b.stage_mass, dtype=float), stage_chains(b).astype(float))


def servo_block(b: SceneBatch) -> SlotBlock | None:
    """The following errors of the stages on a servo as a block of extra linear states, ``z = [e (s),
    e' (s)]`` (m, m/s; the stage's position along its axis is its profile ``r`` minus ``e``), or None when
    every stage follows its profile exactly (docs/physics.md, "Servo stages"). With ``M_q`` the mass the
    stage's drive moves (:func:`carried_mass`), ``rho_c`` its centre at home and ``b = [n; rho_c x n]``:

        e'' + 2 zeta w e' + w^2 e = r'' + b . acc + sum m_i (n_p . n) r_p'' / M_q - g theta . (e_z x n)

    (the carried stages' own moves along ``n``, and gravity along the tilted axis when the rocking terms
    are on); the base feels the servo force, not ``M_q r''``: its generalised force gains ``B e''`` with
    ``B = M_q b`` (which takes ``M_q b b^T`` off its mass matrix at the LTI level) and the weight moment
    of the error's displacement. A servo stage that rides on another servo stage is refused."""
    servo = b.servo_stages
    s = len(servo)
    if s == 0:
        return None
    C, n, m, p = b.n_cases, b.n_isolators, b.n_stages, b.n_points
    chain = stage_chains(b)
    for q in servo:
        below = [int(a) for a in servo if a != q and chain[q, a]]
        if below:
            raise SceneError(
                "stage_servo_frequency",
                f"stage {int(q)} is on a servo and rides on stage {below[0]}, also on one; put one of them "
                "on a servo",
            )
    rho_h = b.stage_home - b.cg[:, None, :]
    e = b.stage_axis / np.maximum(np.linalg.norm(b.stage_axis, axis=-1, keepdims=True), 1e-300)
    sm = np.asarray(b.stage_mass, dtype=float)
    Mq_all = carried_mass(b)
    w_all = 2.0 * np.pi * np.asarray(b.stage_servo_frequency, dtype=float)
    zeta_all = np.asarray(b.stage_servo_damping, dtype=float)
    kind = np.asarray(b.point_relative)
    ext = np.vstack([chain, np.zeros((1, m), dtype=bool)])  # row -1: the base carries nothing
    tool = ext[np.asarray(b.point_tool_stage)]  # (C, p, m)
    work = ext[np.asarray(b.point_work_stage)]
    A = np.zeros((C, 2 * s, 2 * s))
    X = np.zeros((C, 2 * s, 12))
    Q = np.zeros((C, 2 * s, 6))
    S = np.zeros((C, 2 * s, m))
    G = np.zeros((C, 6, 2 * s))
    Bm = np.zeros((C, 6, 2 * s))
    O = np.zeros((C, 2, 2 * s, 3 * p + 3 * n))
    ez = np.array([0.0, 0.0, 1.0])
    for j, q in enumerate(servo.tolist()):
        r = s + j
        Mq = Mq_all[:, q]
        nq = e[:, q]
        rc = np.einsum("ci,cia->ca", sm * chain[:, q], rho_h) / Mq[:, None]
        bq = np.concatenate([nq, np.cross(rc, nq)], axis=1)  # (C, 6)
        w, zeta = w_all[:, q], zeta_all[:, q]
        A[:, j, r] = 1.0
        A[:, r, j] = -(w**2)
        A[:, r, r] = -2.0 * zeta * w
        Q[:, r] = bq
        S[:, r, q] = 1.0
        for i in np.flatnonzero(chain[:, q]).tolist():
            a = i
            while a != q:  # the carried stages' own moves along this axis
                S[:, r, a] += sm[:, i] * np.einsum("ca,ca->c", e[:, a], nq) / Mq
                a = int(b.stage_parent[a])
        if b.gravity_stiffness:
            X[:, r, 3:6] = -b.g * np.cross(ez, nq)
        Bm[:, :, r] = Mq[:, None] * bq
        G[:, 3, j] += b.g * Mq * nq[:, 1]  # the weight moment of the displacement -e n
        G[:, 4, j] -= b.g * Mq * nq[:, 0]
        for k in range(p):
            sign = (kind[:, k] == 1) * (work[:, k, q].astype(float) - tool[:, k, q].astype(float))
            O[:, 0, j, 3 * k : 3 * k + 3] = sign[:, None] * nq
            O[:, 1, r, 3 * k : 3 * k + 3] = sign[:, None] * nq
            own = (kind[:, k] == 2) & (np.asarray(b.point_tool_stage)[:, k] == q)
            O[:, 0, j, 3 * k] += own
            O[:, 1, r, 3 * k] += own
    return SlotBlock(A, X, Q, S, G, O, Bm)
