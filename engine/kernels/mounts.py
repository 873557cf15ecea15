"""The isolators' forces on the base: per floor axis ``F = -K delta - C delta_dot`` about the preloaded
reference state, ``delta`` the displacement of the mount's point of action minus the floor's under it (a
sky-hook mount's damper acts on the absolute velocity of its point instead).

Numba functions on case ``c`` of the kernel parameters ``P`` (``engine.kernels.params.Params``): lever arms
``P.d`` (m, from the c.g.), stiffness ``P.k`` (N/m), damping ``P.cd`` (N s/m), sky-hook share ``P.sky``,
preload ``P.f0`` (N). A mount with its own axes (``P.orient``, ``P.qm``: columns its x, y, z in the floor
frame) has ``P.k``, ``P.cd`` along those axes (:func:`oriented_force`).
"""

from __future__ import annotations

from numba import njit

from isolab.engine.kernels.params import LTV, NONLINEAR
from isolab.engine.kernels.rotations import cross


@njit(cache=True, inline="always")
def mount_offset(level, x, R, d0, d1, d2):
    """Displacement (m) of a material point at ``d`` (m, from the c.g.) due to the base's rotation:
    ``(R - I) d`` at the nonlinear level (``R`` body to floor), ``theta x d`` at the linear ones. Adding
    the c.g. displacement ``u`` gives the point's displacement; minus the floor's, a mount's deflection."""
    if level == NONLINEAR:
        r0 = R[0, 0] * d0 + R[0, 1] * d1 + R[0, 2] * d2 - d0
        r1 = R[1, 0] * d0 + R[1, 1] * d1 + R[1, 2] * d2 - d1
        r2 = R[2, 0] * d0 + R[2, 1] * d1 + R[2, 2] * d2 - d2
        return r0, r1, r2
    return cross(x[3], x[4], x[5], d0, d1, d2)


@njit(cache=True, inline="always")
def diagonal_force(k, cd, c, j, e0, e1, e2, s0, s1, s2):
    """Force (N, floor frame) of isolator ``j`` of case ``c`` on the floor's axes: ``-k e - c s`` along each,
    stiffness ``k[c, j]`` (N/m) and damping ``cd[c, j]`` (N s/m), deflection ``e`` (m) and its rate ``s``
    (m/s) in the floor frame."""
    return (
        -k[c, j, 0] * e0 - cd[c, j, 0] * s0,
        -k[c, j, 1] * e1 - cd[c, j, 1] * s1,
        -k[c, j, 2] * e2 - cd[c, j, 2] * s2,
    )


@njit(cache=True, inline="always")
def oriented_force(Q, k0, k1, k2, c0, c1, c2, e0, e1, e2, s0, s1, s2):
    """Force (N, floor frame) of a mount whose own axes are the columns of ``Q`` (3, 3): stiffness ``k``
    (N/m) and damping ``c`` (N s/m) along those axes, deflection ``e`` (m) and its rate ``s`` (m/s) in
    the floor frame: ``F = -Q (diag(k) Q^T e + diag(c) Q^T s)``."""
    g0 = -k0 * (Q[0, 0] * e0 + Q[1, 0] * e1 + Q[2, 0] * e2)
    g0 -= c0 * (Q[0, 0] * s0 + Q[1, 0] * s1 + Q[2, 0] * s2)
    g1 = -k1 * (Q[0, 1] * e0 + Q[1, 1] * e1 + Q[2, 1] * e2)
    g1 -= c1 * (Q[0, 1] * s0 + Q[1, 1] * s1 + Q[2, 1] * s2)
    g2 = -k2 * (Q[0, 2] * e0 + Q[1, 2] * e1 + Q[2, 2] * e2)
    g2 -= c2 * (Q[0, 2] * s0 + Q[1, 2] * s1 + Q[2, 2] * s2)
    return (
        Q[0, 0] * g0 + Q[0, 1] * g1 + Q[0, 2] * g2,
        Q[1, 0] * g0 + Q[1, 1] * g1 + Q[1, 2] * g2,
        Q[2, 0] * g0 + Q[2, 1] * g1 + Q[2, 2] * g2,
    )


@njit(cache=True, inline="always")
def mount_force(level, x, R, xf, vf, c, j, k, cd, sky, orient, qm, d0, d1, d2, r0, r1, r2):
    """Dynamic force (N, floor frame) of isolator ``j`` of case ``c`` at state ``x``, its point at ``d``
    (m, from the c.g.) moved by ``r`` (m, :func:`mount_offset`): ``-K delta - C delta_dot`` with
    ``delta = u + r - x_floor``; the damper acts on ``delta_dot`` or, for a sky-hook mount, on the absolute
    velocity of the mount point. ``k``, ``cd``, ``sky``, ``qm`` are ``Params``' arrays (or views of them),
    ``orient`` says whether some mount has its own axes (:func:`oriented_force`)."""
    off = 7 if level == NONLINEAR else 6
    u0, u1, u2 = x[0], x[1], x[2]
    v0, v1, v2 = x[off], x[off + 1], x[off + 2]
    w0, w1, w2 = x[off + 3], x[off + 4], x[off + 5]
    if level == NONLINEAR:
        b0, b1, b2 = cross(w0, w1, w2, d0, d1, d2)
        q0 = R[0, 0] * b0 + R[0, 1] * b1 + R[0, 2] * b2
        q1 = R[1, 0] * b0 + R[1, 1] * b1 + R[1, 2] * b2
        q2 = R[2, 0] * b0 + R[2, 1] * b1 + R[2, 2] * b2
    else:
        q0, q1, q2 = cross(w0, w1, w2, d0, d1, d2)
    rel = 1.0 - sky[c, j]
    e0, e1, e2 = u0 + r0 - xf[0], u1 + r1 - xf[1], u2 + r2 - xf[2]
    s0, s1, s2 = v0 + q0 - rel * vf[0], v1 + q1 - rel * vf[1], v2 + q2 - rel * vf[2]
    if orient:
        return oriented_force(
            qm[c, j],
            k[c, j, 0],
            k[c, j, 1],
            k[c, j, 2],
            cd[c, j, 0],
            cd[c, j, 1],
            cd[c, j, 2],
            e0,
            e1,
            e2,
            s0,
            s1,
            s2,
        )
    return diagonal_force(k, cd, c, j, e0, e1, e2, s0, s1, s2)


@njit(cache=True, fastmath=False)
def isolator_forces(P, c, level, x, R, xf, vf, F):
    """Dynamic isolator forces on the machine ``F`` (n, 3) N, floor frame, at state ``x``
    (:func:`mount_force` of each mount).

    ``delta = u + (R - I) d - x_floor`` (:func:`mount_offset`); linear levels use ``theta x d`` for
    ``(R - I) d``.
    """
    D, k, cd, sky = P.d, P.k, P.cd, P.sky  # bound once: an attribute read counts a reference each time
    orient, qm = P.orient, P.qm
    for j in range(D.shape[1]):
        d0, d1, d2 = D[c, j, 0], D[c, j, 1], D[c, j, 2]
        r0, r1, r2 = mount_offset(level, x, R, d0, d1, d2)
        F[j, 0], F[j, 1], F[j, 2] = mount_force(
            level, x, R, xf, vf, c, j, k, cd, sky, orient, qm, d0, d1, d2, r0, r1, r2
        )


@njit(cache=True, fastmath=False)
def linear_mounts(P, c, x, xf, vf, R, F, out):
    """Generalised force ``out`` (6,) N, N m of the isolators at the linear levels (and the rocking moment
    of their preloads that tilt with the base, ``P.gstiff``) at state ``x`` and floor motion ``xf``, ``vf``
    (3,): linear in ``(x, xf, vf)``. ``F`` (n, 3) scratch; ``R`` unused."""
    isolator_forces(P, c, LTV, x, R, xf, vf, F)
    for q in range(6):
        out[q] = 0.0
    for j in range(P.d.shape[1]):
        F0, F1, F2 = F[j, 0], F[j, 1], F[j, 2]
        out[0] += F0
        out[1] += F1
        out[2] += F2
        d0, d1, d2 = P.d[c, j, 0], P.d[c, j, 1], P.d[c, j, 2]
        m0, m1, m2 = cross(d0, d1, d2, F0, F1, F2)
        if P.gstiff:
            # d x (-theta x F0) with F0 = (0, 0, f0)
            tf0, tf1, tf2 = cross(x[3], x[4], x[5], 0.0, 0.0, P.f0[c, j])
            n0, n1, n2 = cross(d0, d1, d2, -tf0, -tf1, -tf2)
            m0 += n0
            m1 += n1
            m2 += n2
        out[3] += m0
        out[4] += m1
        out[5] += m2
