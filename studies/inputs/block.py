"""The machine base as a solid block: its mass, inertia and c.g. from its size and density, and how far a
stage may travel on it.

A homogeneous rectangular block of sides ``lx, ly, lz`` and density ``rho`` has the mass
``m = rho lx ly lz``, the inertia about its c.g. ``I = m diag(ly^2+lz^2, lx^2+lz^2, lx^2+ly^2) / 12`` and
its c.g. at its centre. A stage moving along the unit axis ``a`` may go at most the block's extent along
that axis, ``|a_x| lx + |a_y| ly + |a_z| lz``, from home; without a block (a machine given by mass and
inertia) at most :data:`MAX_TRAVEL`.

The functions take arrays with any leading (case) dimensions, so the schema's check of one scene and the
batch builder's of many cases compute the same numbers.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

MAX_TRAVEL = 20.0
"""Largest stage travel accepted when the machine's size is not known, m."""
TRAVEL_SLACK = 1e-12
"""A move may exceed its travel bound by this fraction (rounding) and still be accepted."""


def block_properties(
    size: ArrayLike, density: ArrayLike, corner: ArrayLike
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mass (...) kg, inertia about the c.g. (..., 3, 3) kg m^2 and c.g. (..., 3) m of solid blocks.

    Args:
        size: (..., 3) sides ``lx, ly, lz``, m.
        density: (...) kg/m^3.
        corner: (..., 3) position of each block's minimum corner, m.
    """
    size = np.asarray(size, dtype=np.float64)
    mass = np.asarray(density, dtype=np.float64) * size.prod(axis=-1)
    sq = size**2
    inertia = np.zeros((*size.shape[:-1], 3, 3))
    inertia[..., 0, 0] = mass * (sq[..., 1] + sq[..., 2]) / 12.0
    inertia[..., 1, 1] = mass * (sq[..., 0] + sq[..., 2]) / 12.0
    inertia[..., 2, 2] = mass * (sq[..., 0] + sq[..., 1]) / 12.0
    return mass, inertia, np.asarray(corner, dtype=np.float64) + size / 2.0


def travel_bound(axis: ArrayLike, block_size: ArrayLike | None) -> np.ndarray:
    """How far (m) a stage moving along the unit ``axis`` (..., 3) may go from home: the extent along it of
    the block of sides ``block_size`` (..., 3, broadcast against ``axis``), or :data:`MAX_TRAVEL` when the
    machine is not a block (None)."""
    if block_size is None:
        return np.full(np.shape(axis)[:-1], MAX_TRAVEL)
    extent = np.asarray(block_size, dtype=np.float64)
    return np.einsum("...i,...i->...", np.abs(np.asarray(axis, dtype=np.float64)), extent)


def beyond_travel(reach: ArrayLike, bound: ArrayLike) -> np.ndarray:
    """True where a stage's farthest distance from home ``reach`` (m) exceeds its travel ``bound`` (m)."""
    return np.asarray(reach) > np.asarray(bound) * (1.0 + TRAVEL_SLACK)
