"""Vector and rotation maths of the kernels: the cross product of vectors given by their components, and
unit quaternions.

A quaternion ``q = (w, x, y, z)`` turns the body frame into the floor frame; angular rates are body-frame,
rad/s. Numba functions for the equations of motion and the peaks.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def cross(a0, a1, a2, b0, b1, b2):
    """The cross product ``a x b`` of ``a = (a0, a1, a2)`` and ``b = (b0, b1, b2)`` (its unit the product of
    theirs: rad/s x m gives m/s), as three numbers."""
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(cache=True, inline="always")
def quat_matrix(w, x, y, z, R):
    """Rotation matrix (body to floor) of the unit quaternion ``(w, x, y, z)`` into ``R`` (3, 3); its four
    numbers are given, so a state's are read without slicing it."""
    _scaled_matrix(w, x, y, z, 2.0, R)


@njit(cache=True, inline="always")
def direction_matrix(w, x, y, z, R):
    """Rotation matrix (body to floor) of the direction ``q / |q|`` of a quaternion near unit length into
    ``R`` (3, 3): :func:`quat_matrix` with ``2 / |q|^2`` for its 2, so that ``R`` is orthogonal to round-off
    whatever ``|q|``. Within 1e-8 of unit length (an integrator's stage state, the step's end normalised)
    ``1 / |q|^2 = 1 / (1 + e)`` is taken as ``1 - e``, whose error ``e^2`` is below round-off: no division
    on the way to the accelerations."""
    e = w * w + x * x + y * y + z * z - 1.0
    if abs(e) < 1e-8:
        s = 2.0 * (1.0 - e)
    else:
        s = 2.0 / (1.0 + e)
    _scaled_matrix(w, x, y, z, s, R)


@njit(cache=True, inline="always")
def _scaled_matrix(w, x, y, z, s, R):
    """``R`` (3, 3) of the quaternion ``(w, x, y, z)`` with ``s`` for the factor of its products (2 for a
    unit quaternion, ``2 / |q|^2`` for any)."""
    R[0, 0] = 1.0 - s * (y * y + z * z)
    R[0, 1] = s * (x * y - w * z)
    R[0, 2] = s * (x * z + w * y)
    R[1, 0] = s * (x * y + w * z)
    R[1, 1] = 1.0 - s * (x * x + z * z)
    R[1, 2] = s * (y * z - w * x)
    R[2, 0] = s * (x * z - w * y)
    R[2, 1] = s * (y * z + w * x)
    R[2, 2] = 1.0 - s * (x * x + y * y)


@njit(cache=True, fastmath=False)
def quat_step(q, w0, w1, w2, h):
    """Advance ``q`` in place by a constant body rate ``w`` (rad/s) over ``h`` s (exact increment)."""
    wn = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    half = 0.5 * wn * h
    if wn * h < 1e-12:
        dw, dx, dy, dz = 1.0, 0.5 * w0 * h, 0.5 * w1 * h, 0.5 * w2 * h
    else:
        s = np.sin(half) / wn
        dw, dx, dy, dz = np.cos(half), s * w0, s * w1, s * w2
    a0, a1, a2, a3 = q[0], q[1], q[2], q[3]
    q[0] = a0 * dw - a1 * dx - a2 * dy - a3 * dz
    q[1] = a0 * dx + a1 * dw + a2 * dz - a3 * dy
    q[2] = a0 * dy - a1 * dz + a2 * dw + a3 * dx
    q[3] = a0 * dz + a1 * dy - a2 * dx + a3 * dw
    n = np.sqrt(q[0] ** 2 + q[1] ** 2 + q[2] ** 2 + q[3] ** 2)
    for i in range(4):
        q[i] /= n
