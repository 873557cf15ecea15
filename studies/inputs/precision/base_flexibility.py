"""A block base's elastic modes from its size, density and Young's modulus (``machine.flexible``).

Three modes of a free-free rectangular block, the thickness ``h`` vertical (docs/physics.md, "A flexible
base"):

- bending along the long side ``L``: the free-free Euler-Bernoulli beam, ``beta L = 4.7300``,
  ``f = (beta L)^2 / (2 pi L^2) sqrt(E I / (rho A))`` with ``I / A = h^2 / 12``, vertical displacement
  ``w = cosh(beta x) + cos(beta x) - sigma (sinh(beta x) + sin(beta x))`` and, plane sections turning with
  it, ``-(z - z_c) w'`` along the side (so a stage's horizontal force above the neutral plane bends it);
- the same across the short side;
- the first torsion mode about the long axis: ``f = 1 / (2 L) sqrt(G J / (rho I_p))``, ``G = E / (2 (1 +
  nu))``, Saint-Venant's ``J = k b h^3`` (``k = 1/3 - 0.21 (h/b) (1 - (h/b)^4 / 12)``), ``I_p = b h (b^2 +
  h^2) / 12``; the section turns by ``cos(pi x / L)``.

The ``modes`` lowest are kept. Each shape is scaled to a largest displacement of 1 at the block's corners
(the modal coordinate is the worst corner's deflection, m), and its modal mass is ``rho int |phi|^2 dV``
(a midpoint rule on the block).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any, Protocol

import numpy as np

from isolab.engine.scene import SceneBatch
from isolab.studies.inputs.precision.relative_points import work_positions
from isolab.studies.inputs.schema.scene_paths import (
    BLOCK_CORNER,
    BLOCK_DENSITY,
    BLOCK_SIZE,
    FLEXIBLE_DAMPING,
    FLEXIBLE_POISSON_RATIO,
    FLEXIBLE_YOUNG_MODULUS,
)

BETA_L = 4.730040744862704
"""The first root of ``cos(x) cosh(x) = 1``: the free-free beam's first bending mode."""
_SIGMA = (np.cosh(BETA_L) - np.cos(BETA_L)) / (np.sinh(BETA_L) - np.sin(BETA_L))
GRID = (24, 24, 6)
"""Midpoint-rule cells along x, y, z for the modal masses."""


class CaseValues(Protocol):
    """How the batch builder reads one input for every case (its overrides first)."""

    scenes: Any

    def get(self, path: str, read: Any) -> np.ndarray: ...

    def vec(self, path: str, read: Any) -> np.ndarray: ...


def beam_shape(xi: np.ndarray) -> np.ndarray:
    """The free-free beam's first bending shape at ``xi = x / L`` in [0, 1] (2 at both ends)."""
    b = BETA_L * np.asarray(xi, dtype=float)
    return np.cosh(b) + np.cos(b) - _SIGMA * (np.sinh(b) + np.sin(b))


def beam_slope(xi: np.ndarray) -> np.ndarray:
    """``d(beam_shape)/d xi`` at ``xi = x / L``."""
    b = BETA_L * np.asarray(xi, dtype=float)
    return BETA_L * (np.sinh(b) - np.sin(b) - _SIGMA * (np.cosh(b) + np.cos(b)))


def bending_frequency(
    length: np.ndarray, thickness: np.ndarray, density: np.ndarray, young: np.ndarray
) -> np.ndarray:
    """First free-free bending frequency of a beam of ``length`` and ``thickness`` (m), ``density``
    (kg/m^3), Young's modulus ``young`` (Pa), bending about its width, Hz."""
    return BETA_L**2 / (2.0 * np.pi * length**2) * np.sqrt(young * thickness**2 / (12.0 * density))


def torsion_frequency(
    length: np.ndarray,
    width: np.ndarray,
    thickness: np.ndarray,
    density: np.ndarray,
    young: np.ndarray,
    poisson: np.ndarray,
) -> np.ndarray:
    """First free-free torsion frequency of a bar of rectangular section (Saint-Venant), Hz."""
    b = np.maximum(width, thickness)
    h = np.minimum(width, thickness)
    r = h / b
    J = (1.0 / 3.0 - 0.21 * r * (1.0 - r**4 / 12.0)) * b * h**3
    Ip = b * h * (b**2 + h**2) / 12.0
    G = young / (2.0 * (1.0 + poisson))
    return np.sqrt(G * J / (density * Ip)) / (2.0 * length)


def _raw_shapes(points: np.ndarray, size: np.ndarray, corner: np.ndarray) -> np.ndarray:
    """Unscaled displacements (C, q, 3, 3) of the three modes (long bending, short bending, torsion) at
    ``points`` (C, q, 3), m."""
    long_x = size[:, 0] >= size[:, 1]  # (C,)
    a1 = np.where(long_x, 0, 1)
    a2 = 1 - a1
    rel = points - corner[:, None, :]
    C = points.shape[0]
    rows = np.arange(C)
    xi1 = rel[rows, :, a1] / size[rows, a1][:, None]  # (C, q) along the long side
    xi2 = rel[rows, :, a2] / size[rows, a2][:, None]
    out = np.zeros(points.shape + (3,))
    # bending: the vertical deflection w, and plane sections turning with it, -(z - z_c) w' along the side
    height = rel[..., 2] - 0.5 * size[:, None, 2]
    out[..., 2, 0] = beam_shape(xi1)
    out[..., 2, 1] = beam_shape(xi2)
    out[rows, :, a1, 0] = -height * beam_slope(xi1) / size[rows, a1][:, None]
    out[rows, :, a2, 1] = -height * beam_slope(xi2) / size[rows, a2][:, None]
    # torsion about the long centre line: theta(x) e_long x r_perp
    centre = corner + 0.5 * size
    r = points - centre[:, None, :]
    e = np.zeros((C, 3))
    e[rows, a1] = 1.0
    r_perp = r - np.einsum("cq,ci->cqi", np.einsum("cqi,ci->cq", r, e), e)
    theta = np.cos(np.pi * xi1)
    out[..., 2] = theta[..., None] * np.cross(e[:, None, :], r_perp)
    return out


def block_modes(
    size: np.ndarray, density: np.ndarray, corner: np.ndarray, young: np.ndarray, poisson: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The three modes of each case's block: frequencies (C, 3) Hz, the shapes' scale (C, 3) (1 over the
    largest corner displacement) and modal masses (C, 3) kg of the scaled shapes. ``size`` (C, 3) and
    ``corner`` (C, 3) m, ``density`` (C,) kg/m^3, ``young`` (C,) Pa, ``poisson`` (C,)."""
    size = np.asarray(size, dtype=float)
    corner = np.asarray(corner, dtype=float)
    L1 = size[:, :2].max(axis=1)
    L2 = size[:, :2].min(axis=1)
    h = size[:, 2]
    freq = np.stack(
        [
            bending_frequency(L1, h, density, young),
            bending_frequency(L2, h, density, young),
            torsion_frequency(L1, L2, h, density, young, poisson),
        ],
        axis=1,
    )
    corners = corner[:, None, :] + size[:, None, :] * np.array(
        [[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], dtype=float
    )
    peak = np.linalg.norm(_raw_shapes(corners, size, corner), axis=2).max(axis=1)  # (C, 3)
    scale = 1.0 / peak
    axes = [(np.arange(n) + 0.5) / n for n in GRID]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    cells = corner[:, None, :] + grid[None] * size[:, None, :]
    phi = _raw_shapes(cells, size, corner) * scale[:, None, None, :]
    volume = size.prod(axis=1)
    mass = (density * volume)[:, None] * (phi**2).sum(axis=2).mean(axis=1)
    return freq, scale, mass


def flexible_base(batch: SceneBatch, cases: CaseValues) -> SceneBatch:
    """``batch`` with its block base's elastic modes when the scene asks for them (``machine.flexible``),
    read per case (a study may vary ``machine.flexible.young_modulus`` and ``.damping``); else ``batch``."""
    flexible = cases.scenes[0].machine.flexible
    if flexible is None:
        return batch
    C = batch.n_cases

    def per_case(values: np.ndarray) -> np.ndarray:
        return np.broadcast_to(np.asarray(values, dtype=float), (C,)).copy()

    size = np.broadcast_to(cases.vec(BLOCK_SIZE, lambda s: s.machine.block.size), (C, 3))
    corner = np.broadcast_to(cases.vec(BLOCK_CORNER, lambda s: s.machine.block.corner), (C, 3))
    density = per_case(cases.get(BLOCK_DENSITY, lambda s: s.machine.block.density))
    young = per_case(cases.get(FLEXIBLE_YOUNG_MODULUS, lambda s: s.machine.flexible.young_modulus))
    damping = per_case(cases.get(FLEXIBLE_DAMPING, lambda s: s.machine.flexible.damping))
    poisson = per_case(cases.get(FLEXIBLE_POISSON_RATIO, lambda s: s.machine.flexible.poisson_ratio))
    freq, scale, mass = block_modes(size, density, corner, young, poisson)
    keep = np.argsort(freq, axis=1)[:, : flexible.modes]  # (C, k) the lowest, per case
    rows = np.arange(C)[:, None]

    def shapes(points: np.ndarray) -> np.ndarray:
        if points.shape[1] == 0:
            return np.zeros((C, 0, 3, keep.shape[1]))
        phi = _raw_shapes(np.asarray(points, dtype=float), size, corner) * scale[:, None, None, :]
        return np.take_along_axis(phi, keep[:, None, None, :], axis=3)

    point_shapes = shapes(np.asarray(batch.points, dtype=float))
    if batch.has_relative_points:  # a relative point moves by the shapes' difference between tool and work
        relative = (np.asarray(batch.point_relative) == 1)[..., None, None]
        point_shapes = point_shapes - relative * shapes(work_positions(batch, cases.scenes[0]))
    return replace(
        batch,
        base_mode_frequency=freq[rows, keep],
        base_mode_damping=np.repeat(damping[:, None], keep.shape[1], axis=1),
        base_mode_mass=mass[rows, keep],
        base_mode_iso=shapes(np.asarray(batch.iso_pos, dtype=float)),
        base_mode_stage=shapes(np.asarray(batch.stage_home, dtype=float)),
        base_mode_point=point_shapes,
    )
