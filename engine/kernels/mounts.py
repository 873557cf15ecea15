"""The isolators' forces on the base: per floor axis ``F = -K delta - C delta_dot`` about the preloaded
reference state, ``delta`` the displacement of the mount's point of action minus the floor's under it (a
sky-hook mount's damper acts on the absolute velocity of its point instead).

Numba functions on case ``c`` of the kernel parameters ``P`` (``engine.kernels.params.Params``): lever arms
``P.d`` (m, from the c.g.), stiffness ``P.k`` (N/m), damping ``P.cd`` (N s/m), sky-hook share ``P.sky``,
preload ``P.f0`` (N).
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


@njit(cache=True)
def isolator_forces(P, c, level, x, R, xf, vf, F):
    """Dynamic isolator forces on the machine ``F`` (n, 3) N, floor frame, at state ``x``.

    ``delta = u + (R - I) d - x_floor`` (:func:`mount_offset`); the damper acts on ``delta_dot`` or, for
    a sky-hook mount, on the absolute velocity of the mount point. Linear levels use ``theta x d`` for
    ``(R - I) d``.
    """
    D, k, cd, sky = P.d, P.k, P.cd, P.sky  # bound once: an attribute read counts a reference each time
    n = D.shape[1]
    if level == NONLINEAR:
        off = 7
    else:
        off = 6
    u0, u1, u2 = x[0], x[1], x[2]
    v0, v1, v2 = x[off], x[off + 1], x[off + 2]
    w0, w1, w2 = x[off + 3], x[off + 4], x[off + 5]
    for j in range(n):
        d0, d1, d2 = D[c, j, 0], D[c, j, 1], D[c, j, 2]
        r0, r1, r2 = mount_offset(level, x, R, d0, d1, d2)
        if level == NONLINEAR:
            b0, b1, b2 = cross(w0, w1, w2, d0, d1, d2)
            q0 = R[0, 0] * b0 + R[0, 1] * b1 + R[0, 2] * b2
            q1 = R[1, 0] * b0 + R[1, 1] * b1 + R[1, 2] * b2
            q2 = R[2, 0] * b0 + R[2, 1] * b1 + R[2, 2] * b2
        else:
            q0, q1, q2 = cross(w0, w1, w2, d0, d1, d2)
        rel = 1.0 - sky[c, j]
        F[j, 0] = -k[c, j, 0] * (u0 + r0 - xf[0]) - cd[c, j, 0] * (v0 + q0 - rel * vf[0])
        F[j, 1] = -k[c, j, 1] * (u1 + r1 - xf[1]) - cd[c, j, 1] * (v1 + q1 - rel * vf[1])
        F[j, 2] = -k[c, j, 2] * (u2 + r2 - xf[2]) - cd[c, j, 2] * (v2 + q2 - rel * vf[2])


@njit(cache=True)
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
