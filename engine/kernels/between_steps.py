"""Peaks between output times: the cubic Hermite interpolant of a quantity through its values and rates at
two output times, and its extremes strictly inside the interval (closed form), solved only where the
cubic's Bernstein control points reach beyond the running peak (``engine.kernels.peaks``,
``engine.integrators.output_map``)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

ONE_THIRD = 1.0 / 3.0


@njit(cache=True, inline="always")
def hermite(p0, m0, p1, m1, h):
    """Coefficients ``(c0, c1, c2, c3)`` of the cubic Hermite interpolant ``c0 + c1 s + c2 s^2 + c3 s^3``,
    ``s = (t - t0) / h`` in [0, 1], of a quantity with values ``p0``, ``p1`` and rates ``m0``, ``m1`` (per
    s) at the ends of an interval of ``h`` s."""
    c1 = h * m0
    c2 = 3.0 * (p1 - p0) - h * (2.0 * m0 + m1)
    c3 = 2.0 * (p0 - p1) + h * (m0 + m1)
    return p0, c1, c2, c3


@njit(cache=True, inline="always")
def cubic_extremes(c0, c1, c2, c3):
    """Smallest and largest value of ``c0 + c1 s + c2 s^2 + c3 s^3`` at its stationary points strictly
    inside 0 < s < 1, in closed form; ``(inf, -inf)`` when it has none there."""
    lo = np.inf
    hi = -np.inf
    a = 3.0 * c3
    b = 2.0 * c2
    s1 = -1.0
    s2 = -1.0
    if abs(a) <= 1e-12 * (abs(b) + abs(c1)):
        if b != 0.0:
            s1 = -c1 / b
    else:
        disc = b * b - 4.0 * a * c1
        if disc >= 0.0:
            q = -0.5 * (b + math.copysign(math.sqrt(disc), b))
            s1 = q / a
            if q != 0.0:
                s2 = c1 / q
    if 0.0 < s1 < 1.0:
        y = c0 + s1 * (c1 + s1 * (c2 + s1 * c3))
        lo = min(lo, y)
        hi = max(hi, y)
    if 0.0 < s2 < 1.0:
        y = c0 + s2 * (c1 + s2 * (c2 + s2 * c3))
        lo = min(lo, y)
        hi = max(hi, y)
    return lo, hi


@njit(cache=True, inline="always")
def interior_abs(c0, c1, c2, c3):
    """Largest |value| of the cubic at its stationary points inside (0, 1); 0 when it has none."""
    lo, hi = cubic_extremes(c0, c1, c2, c3)
    if hi < lo:
        return 0.0
    return max(abs(lo), abs(hi))


@njit(cache=True, inline="always")
def cubic_beyond(c0, c1, c2, c3, peak):
    """Largest |value| of the cubic at its stationary points inside (0, 1) when it may exceed ``peak``
    there, else 0. Its Bernstein control points ``c0``, ``c0 + c1/3``, ``c0 + (2 c1 + c2)/3``, ``c0 + c1 + c2
    + c3`` bound it (convex hull), so the closed-form solve runs only when an inner one exceeds ``peak``
    (which holds the end values): rarely, once a running peak has been reached."""
    b1 = c0 + c1 * ONE_THIRD
    b2 = b1 + (c1 + c2) * ONE_THIRD
    if abs(b1) <= peak and abs(b2) <= peak:
        return 0.0
    return interior_abs(c0, c1, c2, c3)


@njit(cache=True, inline="always")
def interval_peak(p0, m0, p1, m1, h, peak):
    """Largest |value| inside an output interval of ``h`` s of a quantity with values ``p0``, ``p1`` and
    rates ``m0``, ``m1`` at its ends (cubic Hermite interpolant) when it may exceed ``peak`` (which holds the
    end values); 0 when it cannot or its extremes are at the ends."""
    # the inner Bernstein control points first: the cubic stays inside the hull of p0, b1, b2, p1
    b1 = p0 + h * m0 * ONE_THIRD
    b2 = p1 - h * m1 * ONE_THIRD
    if abs(b1) <= peak and abs(b2) <= peak:
        return 0.0
    c0, c1, c2, c3 = hermite(p0, m0, p1, m1, h)
    return interior_abs(c0, c1, c2, c3)


@njit(cache=True, inline="always")
def peak_point(peak, last, c, p, i, value, rate, h, between):
    """Fold a point's displacement ``value`` (m) and its rate (m/s) into its running peak, with the
    extremum between the previous output time and this one."""
    a = max(abs(value), peak[c, p, i])
    if between:
        a = max(a, interval_peak(last[c, p, i, 0], last[c, p, i, 1], value, rate, h, a))
    if a > peak[c, p, i]:
        peak[c, p, i] = a
    last[c, p, i, 0] = value
    last[c, p, i, 1] = rate
