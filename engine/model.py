"""From a scene batch to the matrices of the linearised model and the kernels' parameter arrays.

All functions are vectorised over the case dimension. Generalised coordinates ``q = [u, theta]``: c.g.
displacement (m) and small rotation about X, Y, Z (rad). Matrices are (C, 6, 6) in SI.

The matrices are numpy alone; the kernels' parameter and work arrays (:func:`params`, :func:`work`) load
``engine.kernels`` (numba) on first use, so that a process that validates scenes or reads results (the
service) never imports it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from isolab.engine.linear_states.block import SlotBlock
from isolab.engine.linear_states.flexible_base import flexible_base_block
from isolab.engine.linear_states.levelling import levelling_block
from isolab.engine.linear_states.mount_branches import mount_relaxation_block
from isolab.engine.linear_states.servo import servo_block
from isolab.engine.scene import SceneBatch

if TYPE_CHECKING:
    from isolab.engine.kernels.params import Params, Work


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrices ``[v]x`` (..., 3, 3) of vectors ``v`` (..., 3): ``[v]x w = v x w``."""
    v = np.asarray(v, dtype=float)
    S = np.zeros(v.shape + (3,))
    S[..., 0, 1], S[..., 0, 2] = -v[..., 2], v[..., 1]
    S[..., 1, 0], S[..., 1, 2] = v[..., 2], -v[..., 0]
    S[..., 2, 0], S[..., 2, 1] = -v[..., 1], v[..., 0]
    return S


def relative_geometry(b: SceneBatch) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Isolator lever arms ``d`` (C, n, 3), stage homes ``rho_h`` (C, m, 3) and points (C, p, 3), all
    relative to the machine c.g., m."""
    cg = b.cg[:, None, :]
    return b.iso_pos - cg, b.stage_home - cg, b.points - cg


def preload(b: SceneBatch) -> np.ndarray:
    """Vertical static load of each isolator at the reference state (C, n), N.

    The rigid base on vertical springs: ``f_j = kz_j (a + b x_j + c y_j)`` with ``a, b, c`` from the three
    statics equations (total weight of machine and stages, and its moments about X and Y with the stages
    at home). Mounts without vertical stiffness share the load as if they were equal.
    """
    d, rho_h, _ = relative_geometry(b)
    w = isolator_tensor(b, b.iso_k)[..., 2, 2] if b.has_orientation else b.iso_k[..., 2].copy()
    none = ~(w > 0).all(axis=1)
    w[none] = 1.0
    basis = np.stack([np.ones_like(d[..., 0]), d[..., 0], d[..., 1]], axis=-1)  # (C, n, 3)
    A = np.einsum("cn,cni,cnj->cij", w, basis, basis)
    g = b.g
    total = (b.mass + b.stage_mass.sum(axis=1)) * g
    mx = g * np.einsum("cm,cm->c", b.stage_mass, rho_h[..., 0])
    my = g * np.einsum("cm,cm->c", b.stage_mass, rho_h[..., 1])
    rhs = np.stack([total, mx, my], axis=-1)
    coef = np.linalg.solve(A, rhs[..., None])[..., 0]
    return w * np.einsum("cni,ci->cn", basis, coef)


def mass_matrix(b: SceneBatch, rho: np.ndarray | None = None) -> np.ndarray:
    """Mass matrix (C, 6, 6) of base plus stages at positions ``rho`` (C, m, 3) (default: home), kg, kg m."""
    _, rho_h, _ = relative_geometry(b)
    rho = rho_h if rho is None else rho
    C = b.n_cases
    M = np.zeros((C, 6, 6))
    mt = b.mass + b.stage_mass.sum(axis=1)
    M[:, 0, 0] = M[:, 1, 1] = M[:, 2, 2] = mt
    S = skew(rho)  # (C, m, 3, 3)
    coup = np.einsum("cm,cmij->cij", b.stage_mass, S)
    M[:, :3, 3:] = -coup
    M[:, 3:, :3] = coup
    M[:, 3:, 3:] = b.inertia + np.einsum("cm,cmki,cmkj->cij", b.stage_mass, S, S)
    return M


def isolator_tensor(b: SceneBatch, k: np.ndarray) -> np.ndarray:
    """Each mount's stiffness or damping as a floor-frame tensor (C, n, 3, 3): ``Q diag(k) Q^T`` with
    ``Q = b.iso_frame`` the mount's own axes and ``k`` (C, n, 3) its values along them (N/m or N s/m)."""
    Q = np.asarray(b.iso_frame, dtype=float)
    return np.einsum("cnik,cnk,cnjk->cnij", Q, np.asarray(k, dtype=float), Q)


def _isolator_matrix(d: np.ndarray, k: np.ndarray) -> np.ndarray:
    """``sum_j T_j^T K_j T_j`` with ``T_j = [I, -[d_j]x]`` (C, 6, 6); ``k`` is (C, n, 3), the diagonal
    ``K_j = diag(k_j)`` of mounts along the floor's axes, or (C, n, 3, 3), full tensors."""
    C, n, _ = d.shape
    T = np.zeros((C, n, 3, 6))
    T[..., :, :3] = np.eye(3)
    T[..., :, 3:] = -skew(d)
    if k.ndim == 4:
        return np.einsum("cnki,cnkl,cnlj->cij", T, k, T)
    return np.einsum("cnki,cnk,cnkj->cij", T, k, T)


def stiffness_matrix(b: SceneBatch, rho: np.ndarray | None = None) -> np.ndarray:
    """Effective stiffness (C, 6, 6), N/m, N, N m/rad: isolators minus the gravity rocking term.

    The gravity term (when ``b.gravity_stiffness``) is the moment of the vertical preloads and of the stage
    weights that tilt with the base: about ``-(weight x height of the c.g. above the mounts)`` in pitch
    and roll. ``rho`` (C, m, 3) places the stages (default: home).
    """
    d, rho_h, _ = relative_geometry(b)
    rho = rho_h if rho is None else rho
    K = _isolator_matrix(d, isolator_tensor(b, b.iso_k) if b.has_orientation else b.iso_k)
    if b.gravity_stiffness:
        f0 = preload(b)
        F0 = np.zeros(d.shape)
        F0[..., 2] = f0
        G = np.einsum("cnik,cnkj->cij", skew(d), skew(F0))
        gz = np.array([0.0, 0.0, b.g])
        G -= np.einsum("cm,cmik,kj->cij", b.stage_mass, skew(rho), skew(gz))
        K[:, 3:, 3:] -= G
    return K


def damping_matrix(b: SceneBatch) -> np.ndarray:
    """Isolator damping matrix (C, 6, 6), N s/m, N s, N m s/rad."""
    d, _, _ = relative_geometry(b)
    return _isolator_matrix(d, isolator_tensor(b, b.iso_c) if b.has_orientation else b.iso_c)


def placed_positions(b: SceneBatch, s: np.ndarray) -> np.ndarray:
    """Stage positions relative to the c.g. (C, m, 3), m, with each stage at ``s`` (C, m), m, along its
    axis (a stage that rides on another adds its parent's travel)."""
    _, rho_h, _ = relative_geometry(b)
    rho = rho_h.copy()
    for i in range(b.n_stages):
        rho[:, i] += s[:, i, None] * b.stage_axis[:, i]
        p = int(b.stage_parent[i])
        if p >= 0:
            rho[:, i] += rho[:, p] - rho_h[:, p]
    return rho


def final_positions(b: SceneBatch) -> np.ndarray:
    """Stage positions relative to the c.g. once every move is over (C, m, 3), m."""
    return placed_positions(b, b.prof_s[..., -1])


def positions_at(b: SceneBatch, t: np.ndarray) -> np.ndarray:
    """Stage travel (C, m), m, at the per-case times ``t`` (C,), s, where every stage is at rest: the
    start position of the piece that holds ``t`` (of the first piece before the profile starts)."""
    k = (b.prof_t <= np.asarray(t, dtype=float)[:, None, None]).sum(axis=-1) - 1  # (C, m)
    k = np.clip(k, 0, None)
    return np.take_along_axis(np.asarray(b.prof_s, dtype=float), k[..., None], axis=-1)[..., 0]


def travel_positions(b: SceneBatch, max_corners: int = 8) -> list[np.ndarray]:
    """Stage placements (each (C, m, 3), m, relative to the machine c.g.) at the ends of their travel.

    Each stage's travel runs between the least and the largest position its profile reaches at a piece
    start. With ``2^m <= max_corners`` every combination of ends is listed; with more stages, all at one
    end, all at the other, and each stage alone at either end. Empty when no stage travels. The mass and
    stiffness of the time-varying levels change with these placements; the stability guard and the
    tipping check look at each.
    """
    m = b.n_stages
    if m == 0 or b.prof_s.shape[-1] == 0:
        return []
    s_lo = np.minimum(b.prof_s.min(axis=-1), 0.0)  # (C, m); a stage rests at 0 before its profile starts
    s_hi = np.maximum(b.prof_s.max(axis=-1), 0.0)
    if not np.any(s_hi - s_lo > 0):
        return []
    picks: list[list[int | None]]
    if 2**m <= max_corners:
        picks = [[(k >> i) & 1 for i in range(m)] for k in range(2**m)]
    else:
        picks = [[0] * m, [1] * m]
        for i in range(m):
            for end in (0, 1):
                pick: list[int | None] = [None] * m
                pick[i] = end
                picks.append(pick)
    _, rho_h, _ = relative_geometry(b)
    e = b.stage_axis / np.linalg.norm(b.stage_axis, axis=-1, keepdims=True)
    out = []
    for pick in picks:
        s = np.zeros(s_lo.shape)
        for i, side in enumerate(pick):
            if side is not None:
                s[:, i] = (s_hi if side else s_lo)[:, i]
        rho = rho_h + s[..., None] * e
        for i in range(m):
            p = int(b.stage_parent[i])
            if p >= 0:
                rho[:, i] += rho[:, p] - rho_h[:, p]
        out.append(rho)
    return out


def static_offset(b: SceneBatch, fidelity: str, rho: np.ndarray | None = None) -> np.ndarray:
    """Static c.g. displacement and rotation (C, 6), m and rad, with the stages parked at ``rho``
    (C, m, 3), m relative to the c.g. (default: their final positions): ``K q = (change of the weights'
    moment)``; the LTI level keeps its stiffness at home, the others take it with the stages there. Mounts
    that feed the weight shift forward (``iso_ff_weight``) carry their share of it at rest."""
    d, rho_h, _ = relative_geometry(b)
    rho_f = final_positions(b) if rho is None else rho
    K = stiffness_matrix(b, None if fidelity == "lti" else rho_f)
    ds = rho_f - rho_h
    f = np.zeros((b.n_cases, 6))
    f[:, 3] = -b.g * np.einsum("cm,cm->c", b.stage_mass, ds[..., 1])
    f[:, 4] = b.g * np.einsum("cm,cm->c", b.stage_mass, ds[..., 0])
    share = _rest_feedforward(b, f)
    if share is not None:
        f[:, :3] += share.sum(axis=1)
        f[:, 3:] += np.cross(d, share).sum(axis=1)
    q = np.einsum("cij,cj->ci", np.linalg.pinv(K, hermitian=True), f)
    if fidelity == "nonlinear":
        q = static_equilibrium(b, rho_f, q, share)
    return q


def _rest_feedforward(b: SceneBatch, f: np.ndarray) -> np.ndarray | None:
    """Each mount's actuator force at rest (C, n, 3), N, machine axes, under the change ``f`` (C, 6) of the
    stages' weight moment (``f[:, 3:]``, N m), or None when no mount feeds the weight forward: the low-pass
    has settled on the reversed weight moment, ``-f``, and each mount applies its clipped share."""
    weight = np.asarray(b.iso_ff_weight, dtype=float) * np.asarray(b.iso_ff_gain, dtype=float)  # (C, n)
    if not (np.any(weight != 0.0) and b.n_stages):
        return None
    lim = np.asarray(b.iso_ff_limit, dtype=float)[..., None]
    share = np.einsum("cnkq,cq->cnk", feedforward_distribution(b), -f) * weight[..., None]
    return np.clip(share, -lim, lim)


def vector_cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a x b`` of vectors (..., 3), broadcast: ``np.cross``'s products and differences, bit for bit,
    without its axis handling (the static equilibrium's Newton iteration takes about a hundred)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def rotation_matrices(phi: np.ndarray) -> np.ndarray:
    """Rotation matrices (C, 3, 3) of the rotation vectors ``phi`` (C, 3), rad (Rodrigues' formula)."""
    phi = np.asarray(phi, dtype=float)
    a = np.linalg.norm(phi, axis=-1)[:, None, None]
    S = skew(phi)
    small = a < 1e-8
    s1 = np.where(small, 1.0 - a**2 / 6.0, np.sin(a) / np.where(small, 1.0, a))
    s2 = np.where(small, 0.5 - a**2 / 24.0, (1.0 - np.cos(a)) / np.where(small, 1.0, a) ** 2)
    return np.eye(3) + s1 * S + s2 * (S @ S)


def static_residual(
    b: SceneBatch,
    rho: np.ndarray,
    q: np.ndarray,
    share: np.ndarray | None,
    preloads: np.ndarray | None = None,
) -> np.ndarray:
    """The nonlinear level's generalised force at rest (C, 6): the net force on the base (floor frame, N)
    and moment about its c.g. (body frame, N m), with the c.g. displaced by ``q[:, :3]`` (m), the base
    turned by the rotation vector ``q[:, 3:]`` (rad), the stages parked at ``rho`` (C, m, 3) and the mounts'
    actuators at rest pushing ``share`` (C, n, 3) (or None). Zero at the static equilibrium. The same forces
    as the nonlinear kernel's (``engine.kernels.dynamics.nonlinear_acc``) with every rate zero and no floor
    motion. ``preloads`` (C, n), N, is :func:`preload` of ``b``, when the caller has it."""
    d, _, _ = relative_geometry(b)
    R = rotation_matrices(q[:, 3:])
    off = np.einsum("cij,cnj->cni", R, d) - d
    u = q[:, None, :3] + off  # (C, n, 3) each mount's deflection, floor frame
    if b.has_orientation:  # a mount turned on its own axes: its full stiffness tensor Q diag(k) Q^T
        F = -np.einsum("cnij,cnj->cni", isolator_tensor(b, b.iso_k), u)
    else:
        F = -b.iso_k * u
    p = preload(b) if preloads is None else preloads  # (C, n)
    force = F.sum(axis=1)
    if b.preload_with_base:
        force += (p[..., None] * (R[:, None, :, 2] - np.array([0.0, 0.0, 1.0]))).sum(axis=1)
        G = np.einsum("cji,cnj->cni", R, F)
        G[..., 2] += p
    else:
        T = F.copy()
        T[..., 2] += p
        G = np.einsum("cji,cnj->cni", R, T)
    moment = vector_cross(d, G).sum(axis=1)
    SR = np.einsum("cm,cmi->ci", b.stage_mass, rho)
    if b.preload_balanced:
        # the preloads and the home weights cancel in every attitude: take out their moment V x R^T e_z
        _, rho_h, _ = relative_geometry(b)
        V = np.einsum("cn,cni->ci", p, d) - b.g * np.einsum("cm,cmi->ci", b.stage_mass, rho_h)
        moment -= vector_cross(V, R[:, 2, :])
    moment += vector_cross(SR, -b.g * R[:, 2, :])  # the stages' weight, R^T (0, 0, -g) in the body
    if share is not None:
        force += np.einsum("cij,cj->ci", R, share.sum(axis=1))
        moment += vector_cross(d, share).sum(axis=1)
    return np.concatenate([force, moment], axis=1)


def static_equilibrium(
    b: SceneBatch, rho: np.ndarray, q0: np.ndarray, share: np.ndarray | None, tol: float = 1e-14
) -> np.ndarray:
    """The nonlinear level's static c.g. displacement and rotation vector (C, 6), m and rad, with the
    stages parked at ``rho`` (C, m, 3): Newton's method on :func:`static_residual` from the linear offset
    ``q0`` (C, 6), with a central-difference Jacobian. A case whose iteration does not converge (a base
    that tips) keeps ``q0``."""
    q = np.array(q0, dtype=float)
    C = q.shape[0]
    done = np.zeros(C, dtype=bool)
    # the residual at q and at its twelve central-difference neighbours in one call: 13 copies of the
    # batch, one after the other (each case's arithmetic is the same as alone)
    every = np.tile(np.arange(C), 13)
    b13, rho13, p13 = b.take(every), rho[every], preload(b)[every]
    share13 = None if share is None else share[every]
    e = 1e-6 * np.eye(6)[:, None, :]  # (6, 1, 6): coordinate k moved by 1e-6
    qs = np.empty((13, C, 6))
    for _ in range(30):
        qs[0], qs[1::2], qs[2::2] = q, q + e, q - e
        rs = static_residual(b13, rho13, qs.reshape(13 * C, 6), share13, p13).reshape(13, C, 6)
        r = rs[0]
        J = np.moveaxis((rs[1::2] - rs[2::2]) / 2e-6, 0, 2)  # (C, 6, 6): column k from coordinate k
        try:
            step = np.linalg.solve(J, -r[..., None])[..., 0]
        except np.linalg.LinAlgError:
            step = np.einsum("cij,cj->ci", np.linalg.pinv(J), -r)
        step[done] = 0.0
        q += step
        done |= np.abs(step).max(axis=1) <= tol * np.maximum(1.0, np.abs(q).max(axis=1))
        if done.all():
            break
    bad = ~np.isfinite(q).all(axis=1) | (np.abs(q[:, :3]).max(axis=1) > 1.0) | ~done
    q[bad] = np.asarray(q0)[bad]
    return q


def rest_offsets(b: SceneBatch, fidelity: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rest intervals after each stage move (``SceneBatch.rest_intervals``) and the static
    displacement the base settles to in each.

    Returns ``bounds`` (C, K, 2), s, and ``count`` (C,) as ``rest_intervals`` gives them, and ``target``
    (C, K, 6), m and rad: :func:`static_offset` with the stages parked where they rest in the interval
    (zero past a case's count).
    """
    bounds, count = b.rest_intervals()
    C, K, _ = bounds.shape
    target = np.zeros((C, K, 6))
    for k in range(K):
        has = count > k
        if not has.any():
            continue
        t0, t1 = bounds[:, k, 0], bounds[:, k, 1]
        when = np.where(has, np.where(np.isfinite(t1), 0.5 * (t0 + t1), t0), 0.0)
        rho = placed_positions(b, positions_at(b, when))
        target[has, k] = static_offset(b, fidelity, rho)[has]
    return bounds, count, target


def point_rest_offsets(b: SceneBatch, offset: np.ndarray) -> np.ndarray:
    """What the nonlinear level's static displacement of each point of interest adds to the linearised
    ``u + theta x p`` of the static ``offset`` (..., C, 6) (m, rad; ``theta`` a rotation vector):
    ``(R - I) p - theta x p`` (..., C, p, 3), m, second order in the rotation."""
    _, _, pts = relative_geometry(b)
    pts = np.where((np.asarray(b.point_relative) == 0)[..., None], pts, 0.0)  # a relative point: no arm
    q = np.asarray(offset, dtype=float)
    flat = q.reshape(-1, q.shape[-2], 6)
    out = np.zeros(flat.shape[:2] + (b.n_points, 3))
    for i in range(flat.shape[0]):
        R = rotation_matrices(flat[i, :, 3:])
        out[i] = np.einsum("cij,cpj->cpi", R, pts) - pts - np.cross(flat[i, :, None, 3:], pts)
    return out.reshape(q.shape[:-1] + (b.n_points, 3))


def feedforward_distribution(b: SceneBatch) -> np.ndarray:
    """Each mount's share of a wrench (C, n, 3, 6): the least-norm actuator forces (machine axes, N) that
    apply a wrench ``[F, M]`` (N, N m, moment about the c.g.) through the mounts that feed forward (gain
    not 0): ``D = pinv(B)``, ``B = [[1, ...], [[d_j]x, ...]]`` over those mounts; zero rows for the others.
    With fewer than three such mounts (or all on one line) some wrenches cannot be applied: the least-squares
    share applies the nearest one."""
    d, _, _ = relative_geometry(b)
    C, n = b.n_cases, b.n_isolators
    on = np.asarray(b.iso_ff_gain) != 0.0
    B = np.zeros((C, 6, n, 3))
    B[:, :3] = np.eye(3)[None, :, None, :]
    B[:, 3:] = np.moveaxis(skew(d), 1, 2)  # (C, 3, n, 3): moment row i, mount j, force axis k
    B *= on[:, None, :, None]
    D = np.linalg.pinv(B.reshape(C, 6, 3 * n), rcond=1e-12)  # (C, 3n, 6)
    return D.reshape(C, n, 3, 6)


SLOT_MODELS = (flexible_base_block, servo_block, mount_relaxation_block, levelling_block)
"""The models of the extra linear states, in the order of their blocks in ``z``: each a function of the
batch that returns its ``SlotBlock`` or None when the scene does not use it."""


def linear_slot(b: SceneBatch) -> SlotBlock:
    """Every model's block of the extra linear states, joined block-diagonally (``nz = 0`` when the scene
    uses none: the kernels then run exactly as without them)."""
    blocks = [blk for blk in (model(b) for model in SLOT_MODELS) if blk is not None]
    C, m, n, p = b.n_cases, b.n_stages, b.n_isolators, b.n_points
    nz = sum(blk.A.shape[1] for blk in blocks)
    A = np.zeros((C, nz, nz))
    X = np.zeros((C, nz, 12))
    Q = np.zeros((C, nz, 6))
    S = np.zeros((C, nz, m))
    G = np.zeros((C, 6, nz))
    O = np.zeros((C, 2, nz, 3 * p + 3 * n))
    B = np.zeros((C, 6, nz)) if any(blk.B is not None for blk in blocks) else None
    D = np.zeros((C, nz))
    F = np.zeros((C, nz, 3 * n))
    at = 0
    for blk in blocks:
        z = slice(at, at + blk.A.shape[1])
        A[:, z, z] = blk.A
        X[:, z] = blk.X
        Q[:, z] = blk.Q
        S[:, z] = blk.S
        G[:, :, z] = blk.G
        O[:, :, z] = blk.O
        if blk.B is not None and B is not None:
            B[:, :, z] = blk.B
        if blk.D is not None:
            D[:, z] = blk.D
        if blk.F is not None:
            F[:, z] = blk.F
        at = z.stop
    return SlotBlock(A, X, Q, S, G, O, B, D, F)


def slot_static(
    b: SceneBatch, fidelity: str, q0: np.ndarray, rho: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The static state with the extra linear states (C, 6) and (C, nz): the rigid static offset ``q0``
    (C, 6) (:func:`static_offset`, stages at ``rho``) corrected for the states' coupling, from ``K q - G z
    = K q0`` and ``A z + X[:, :, :6] q = 0`` (every rate and acceleration zero)."""
    slot = linear_slot(b)
    nz = slot.A.shape[1]
    if nz == 0:
        return q0, np.zeros((b.n_cases, 0))
    rho_f = final_positions(b) if rho is None else rho
    K = stiffness_matrix(b, None if fidelity == "lti" else rho_f)
    C = b.n_cases
    L = np.zeros((C, 6 + nz, 6 + nz))
    L[:, :6, :6] = K
    L[:, :6, 6:] = -slot.G
    L[:, 6:, :6] = slot.X[:, :, :6]
    L[:, 6:, 6:] = slot.A
    rhs = np.zeros((C, 6 + nz))
    rhs[:, :6] = np.einsum("cij,cj->ci", K, q0)
    sol = np.einsum("cij,cj->ci", np.linalg.pinv(L), rhs)
    return sol[:, :6], sol[:, 6:]


def slot_state_matrix(P: Params) -> np.ndarray:
    """The LTI level's state matrix with the extra linear states (C, 12 + nz, 12 + nz), 1/s: ``x' = A x``
    without forcing (for the stability guard and the fastest mode)."""
    C, nz = P.zA.shape[0], P.zA.shape[1]
    A = np.zeros((C, 12 + nz, 12 + nz))
    A[:, :6, 6:12] = np.eye(6)
    A[:, 6:12, :6] = P.a21
    A[:, 6:12, 6:12] = P.a22
    A[:, 6:12, 12:] = P.zM
    A[:, 12:, :12] = P.zX
    A[:, 12:, 12:] = P.zA
    A[:, 12:, :] += P.zQ @ A[:, 6:12, :]
    return A


def params(b: SceneBatch) -> Params:
    """The kernels' parameter arrays for a batch (see ``engine.kernels.params.Params``)."""
    from isolab.engine.kernels.feedforward import feedforward_transients
    from isolab.engine.kernels.structs import kernel_struct

    P = _params(b)
    if P.ffon:
        KP, KW = kernel_struct(P), kernel_struct(work(b))
        for c in range(b.n_cases):
            feedforward_transients(KP, c, KW)
    return P


def _feedforward_breakpoints(b: SceneBatch) -> np.ndarray:
    """Per case the sorted distinct piece start times of every stage (C, B), s, padded with +inf: where
    the stages' wrench changes polynomial (the feedforward filter's stretches)."""
    t = np.asarray(b.prof_t, dtype=float).reshape(b.n_cases, -1)
    rows = [np.unique(r) for r in t]
    B = max((len(r) for r in rows), default=0)
    out = np.full((b.n_cases, max(B, 1)), np.inf)
    for c, r in enumerate(rows):
        out[c, : len(r)] = r
    return out


def _params(b: SceneBatch) -> Params:
    from isolab.engine.kernels.params import Params

    d, rho_h, pts = relative_geometry(b)
    M = mass_matrix(b)
    K = stiffness_matrix(b)
    Cm = damping_matrix(b)
    minv = np.linalg.inv(M)
    f64 = np.ascontiguousarray
    ffon = bool(b.has_feedforward and b.n_stages)
    n = b.n_isolators
    fftb = _feedforward_breakpoints(b) if ffon else np.full((b.n_cases, 1), np.inf)
    slot = linear_slot(b)
    a21, a22, zG, sM = -minv @ K, -minv @ Cm, slot.G, np.zeros((b.n_cases, 6, 0))
    if slot.B is not None:
        # states that carry inertia the base no longer does (a servo stage): M acc = f + G z + B z' with
        # z' = A z + X x + Q acc + S s'' folds into (M - B Q) acc = f + (G + B A) z + B X x + B S s''
        minv = np.linalg.inv(M - slot.B @ slot.Q)
        BX = slot.B @ slot.X
        a21 = minv @ (-K + BX[:, :, :6])
        a22 = minv @ (-Cm + BX[:, :, 6:])
        zG = slot.G + slot.B @ slot.A
        sM = minv @ (slot.B @ slot.S)
    pr = np.asarray(b.point_relative) == 0
    return Params(
        mass=f64(b.mass, dtype=float),
        mtot=f64(b.mass + b.stage_mass.sum(axis=1), dtype=float),
        inertia=f64(b.inertia, dtype=float),
        d=f64(d),
        k=f64(b.iso_k, dtype=float),
        cd=f64(b.iso_c, dtype=float),
        sky=f64(b.iso_skyhook, dtype=float),
        f0=f64(preload(b)),
        sm=f64(b.stage_mass, dtype=float),
        rho_h=f64(rho_h),
        e=f64(b.stage_axis / np.linalg.norm(b.stage_axis, axis=-1, keepdims=True))
        if b.n_stages
        else f64(b.stage_axis, dtype=float),
        parent=f64(b.stage_parent, dtype=np.int64),
        pt=f64(b.prof_t, dtype=float),
        ps=f64(b.prof_s, dtype=float),
        pv=f64(b.prof_v, dtype=float),
        pa=f64(b.prof_a, dtype=float),
        pj=f64(b.prof_j, dtype=float),
        pts=f64(np.where(pr[..., None], pts, 0.0)),
        famp=f64(b.floor_amp, dtype=float),
        fomega=f64(2 * np.pi * np.asarray(b.floor_freq, dtype=float)),
        fphase=f64(b.floor_phase, dtype=float),
        ft=f64(b.floor_t, dtype=float),
        fd=f64(b.floor_disp, dtype=float),
        a21=f64(a21),
        a22=f64(a22),
        minv=f64(minv),
        g=float(b.g),
        gstiff=bool(b.gravity_stiffness),
        ffon=ffon,
        ffg=f64(b.iso_ff_gain, dtype=float),
        ffw=f64(2 * np.pi * np.asarray(b.iso_ff_bandwidth, dtype=float)),
        fflim=f64(b.iso_ff_limit, dtype=float),
        ffD=f64(feedforward_distribution(b)) if ffon else np.zeros((b.n_cases, n, 3, 6)),
        fftb=fftb,
        ffA=np.zeros((b.n_cases, n, fftb.shape[1], 6)),
        ffwt=f64(b.iso_ff_weight, dtype=float),
        pbase=2 if b.preload_balanced else int(bool(b.preload_with_base)),
        orient=b.has_orientation,
        qm=f64(b.iso_frame, dtype=float),
        zA=f64(slot.A),
        zX=f64(slot.X),
        zQ=f64(slot.Q),
        zS=f64(slot.S),
        zG=f64(zG),
        zM=f64(minv @ zG),
        sM=f64(sM),
        zO=f64(slot.O),
        zF=f64(slot.F),
        zdb=f64(slot.D),
        pr=f64(pr, dtype=float),
    )


def work(b: SceneBatch) -> Work:
    """Scratch arrays for one case at a time. They keep terms of the ``Params`` they serve (packed per
    case, per time; ``engine.kernels.cached_terms.time_terms``): one ``Work`` serves one ``Params``."""
    from isolab.engine.kernels.cached_terms import CM_WIDTH
    from isolab.engine.kernels.params import Work

    m, n = b.n_stages, b.n_isolators
    return Work(
        rho=np.zeros((m, 3)),
        vr=np.zeros((m, 3)),
        ar=np.zeros((m, 3)),
        jr=np.zeros((m, 3)),
        xf=np.zeros(3),
        vf=np.zeros(3),
        acc=np.zeros(6),
        f=np.zeros(6),
        R=np.eye(3),
        F=np.zeros((n, 3)),
        Fa=np.zeros((n, 3)),
        ffx=np.zeros((8, 6)),
        ffy=np.zeros(6),
        ffs=np.zeros(24),
        # the accelerations' time-only terms and their key (case, level, time, mass matrix positive
        # definite, pieces; case -1: none yet), and the packed case
        # (``engine.kernels.cached_terms.time_terms``)
        key=np.concatenate([[-1.0, -1.0, np.nan, 0.0], np.zeros(m)]),
        tc=np.zeros((20, 3)),
        cc=np.concatenate([[-1.0], np.zeros(24)]),
        cs=np.zeros((m, 8 + 5 * b.prof_t.shape[-1])),
        cm=np.zeros((n, CM_WIDTH + (9 if b.has_orientation else 0))),
        cK=np.zeros((12 + linear_slot(b).A.shape[1], 6)),
        sw=np.zeros((m, 9)),
    )
