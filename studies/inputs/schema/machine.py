"""The machine base: a rigid body given by mass, c.g. and inertia, or as a solid block of granite."""

from __future__ import annotations

from typing import Annotated, cast

import numpy as np
from pydantic import Field, field_validator, model_validator

from isolab.studies.inputs.block import block_properties
from isolab.studies.inputs.schema.fields import (
    MAX_MACHINE_MASS,
    MIN_MACHINE_MASS,
    BaseSize,
    InputModel,
    MachineMass,
    Position,
    PositiveDensity,
    PositiveInertia,
)
from isolab.studies.inputs.schema.scene_paths import (
    MACHINE_BLOCK,
    MACHINE_FLEXIBLE,
    MACHINE_INERTIA,
    MACHINE_INERTIA_DIAGONAL,
)
from isolab.studies.units import Dimensionless, Inertia, Pressure


def _check_principal_moments(moments: np.ndarray, field: str) -> None:
    """Each principal moment of a rigid body is at most the sum of the other two."""
    a, b, c = sorted(float(x) for x in moments)
    if c > (a + b) * (1.0 + 1e-9):
        raise ValueError(
            f"{field}: principal moments {a:.6g}, {b:.6g}, {c:.6g} kg m^2 break the triangle inequality "
            f"({c:.6g} > {a:.6g} + {b:.6g}): no rigid body has them"
        )


class Block(InputModel):
    """A solid rectangular block (the granite base): mass and inertia computed from size and density."""

    size: tuple[BaseSize, BaseSize, BaseSize] = Field(description="[lx, ly, lz], m")
    density: PositiveDensity = Field(description="kg/m^3 (granite: about 2700)")
    corner: Position = Field((0.0, 0.0, 0.0), description="position of the block's minimum corner, m")

    def properties(self) -> tuple[float, np.ndarray, np.ndarray]:
        """Mass (kg), inertia about the c.g. (3, 3) kg m^2 and c.g. (3,) m of the block
        (:func:`studies.inputs.block.block_properties`)."""
        mass, inertia, cg = block_properties(self.size, self.density, self.corner)
        return float(mass), inertia, cg


class Flexible(InputModel):
    """A block base's elastic modes, computed from its size, density and Young's modulus: the free-free
    bending modes along its long and its short side and its first torsion mode, the lowest ``modes`` of
    them (docs/physics.md, "A flexible base")."""

    modes: int = Field(3, ge=1, le=3, description="how many of the lowest elastic modes to keep (1 to 3)")
    young_modulus: Annotated[Pressure, Field(gt=0)] = Field(
        description="Young's modulus of the block's material, Pa (granite: about 50 GPa)"
    )
    damping: Annotated[Dimensionless, Field(ge=0, le=0.5)] = Field(
        0.01, description="modal damping ratio of every elastic mode (granite: 0.005 to 0.02)"
    )
    poisson_ratio: Annotated[Dimensionless, Field(ge=0, lt=0.5)] = Field(
        0.25, description="Poisson's ratio (the torsion mode's shear modulus E / (2 (1 + nu)))"
    )


class Machine(InputModel):
    """The rigid machine base, without its stages.

    Either ``mass``, ``cg`` and one of ``inertia`` (full 3x3 tensor about the c.g., floor axes, products
    allowed) or ``inertia_diagonal``; or a ``block`` (size, density, corner) from which all three follow.
    """

    mass: MachineMass | None = Field(None, description="kg")
    inertia: list[list[Inertia]] | None = Field(None, description="3x3 tensor about the c.g., kg m^2")
    inertia_diagonal: tuple[PositiveInertia, PositiveInertia, PositiveInertia] | None = Field(
        None, description="[Ixx, Iyy, Izz] about the c.g., kg m^2"
    )
    cg: Position | None = Field(None, description="c.g. position, m")
    block: Block | None = None
    flexible: Flexible | None = Field(
        None, description="the block's elastic modes (only with a block; none: a rigid base)"
    )

    @field_validator("inertia")
    @classmethod
    def _inertia_tensor(cls, value: list[list[float]] | None) -> list[list[float]] | None:
        if value is None:
            return value
        tensor = np.asarray(value, dtype=float) if all(len(r) == 3 for r in value) else None
        if tensor is None or tensor.shape != (3, 3):
            raise ValueError(f"{MACHINE_INERTIA}: must be a 3x3 list of lists")
        scale = float(np.max(np.abs(tensor)))
        if not np.allclose(tensor, tensor.T, rtol=0.0, atol=1e-9 * scale):
            raise ValueError(f"{MACHINE_INERTIA}: must be symmetric (I[i][j] == I[j][i])")
        eig = np.linalg.eigvalsh(tensor)
        if not eig[0] > 1e-12 * scale:
            raise ValueError(
                f"{MACHINE_INERTIA}: must be positive definite, principal moments are "
                f"{', '.join(f'{e:.6g}' for e in eig)} kg m^2"
            )
        _check_principal_moments(eig, MACHINE_INERTIA)
        return value

    @field_validator("inertia_diagonal")
    @classmethod
    def _inertia_moments(cls, value: tuple[float, float, float] | None) -> tuple[float, float, float] | None:
        if value is not None:
            _check_principal_moments(np.asarray(value), MACHINE_INERTIA_DIAGONAL)
        return value

    @model_validator(mode="after")
    def _one_description(self) -> Machine:
        direct = {k for k in ("mass", "inertia", "inertia_diagonal", "cg") if getattr(self, k) is not None}
        if self.flexible is not None and self.block is None:
            raise ValueError(
                f"{MACHINE_FLEXIBLE}: the elastic modes are computed from a block's size and density; "
                "describe the base as a block"
            )
        if self.block is not None:
            if direct:
                raise ValueError(
                    "machine: give either block or mass/inertia/cg, not both "
                    f"(got block and {sorted(direct)})"
                )
            mass = self.block.properties()[0]
            if not MIN_MACHINE_MASS <= mass <= MAX_MACHINE_MASS:
                raise ValueError(
                    f"{MACHINE_BLOCK}: size and density give a mass of {mass:.6g} kg, outside the accepted "
                    f"{MIN_MACHINE_MASS:g} kg to {MAX_MACHINE_MASS:g} kg"
                )
            return self
        missing = [k for k in ("mass", "cg") if getattr(self, k) is None]
        if self.inertia is None and self.inertia_diagonal is None:
            missing.append("inertia (or inertia_diagonal)")
        if missing:
            raise ValueError(f"machine: missing {', '.join(missing)} (or describe the base as a block)")
        if self.inertia is not None and self.inertia_diagonal is not None:
            raise ValueError("machine: give inertia or inertia_diagonal, not both")
        return self

    def properties(self) -> tuple[float, np.ndarray, np.ndarray]:
        """Mass (kg), inertia tensor about the c.g. (3, 3) kg m^2 and c.g. (3,) m."""
        if self.block is not None:
            return self.block.properties()
        inertia = (
            np.asarray(self.inertia, dtype=float)
            if self.inertia is not None
            else np.diag(np.asarray(self.inertia_diagonal, dtype=float))
        )
        mass = cast(float, self.mass)  # without a block, _one_description requires mass, cg and an inertia
        return float(mass), inertia, np.asarray(self.cg, dtype=float)
