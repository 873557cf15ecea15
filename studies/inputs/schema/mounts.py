"""The isolators: a type (preset) with overrides, placed by a layout of four mounts around the c.g. or by
an explicit list, per-axis stiffness and damping, and the feedforward of an active mount."""

from __future__ import annotations

from dataclasses import replace
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import Field, model_validator

from isolab.studies.inputs.catalogues import (
    AXIS_DAMPING,
    Catalogue,
    PerCornerCounts,
    ProductId,
    UnknownProductError,
    product_figures,
    scene_catalogue,
)
from isolab.studies.inputs.isolators import (
    PRESETS,
    CollinearIsolatorsError,
    Feedforward,
    IsolatorPreset,
    load_share,
)
from isolab.studies.inputs.schema.fields import (
    MAX_MOUNT_HEIGHT,
    MAX_MOUNTS,
    DampingRatio,
    InputModel,
    MountFrequency,
    Name,
    NonNegativeDamping,
    NonNegativeStiffness,
    Position,
    PresetName,
    Span,
    tested_range,
    within,
)
from isolab.studies.inputs.schema.scene_paths import AXIS_ALIASES, ISOLATORS
from isolab.studies.units import (
    Angle,
    Area,
    Dimensionless,
    Force,
    Frequency,
    Length,
    Pressure,
    Time,
    Viscosity,
    Volume,
)


def _axis_aliases(value: Any) -> Any:
    """Accept ``horizontal`` (X and Y) and ``vertical`` (Z) for per-axis isolator values."""
    if not isinstance(value, dict):
        return value
    out = {k: v for k, v in value.items() if k not in AXIS_ALIASES}
    for alias, axes in AXIS_ALIASES.items():
        if alias in value:
            clash = [a for a in axes if a in out]
            if clash:
                raise ValueError(f"give {alias} or {'/'.join(clash)}, not both")
            out.update({a: value[alias] for a in axes})
    return out


class AxisStiffness(InputModel):
    """Explicit stiffness per floor axis for every mount, N/m.

    ``horizontal`` sets x and y, ``vertical`` sets z."""

    x: NonNegativeStiffness | None = None
    y: NonNegativeStiffness | None = None
    z: NonNegativeStiffness | None = None

    @model_validator(mode="before")
    @classmethod
    def _aliases(cls, value: Any) -> Any:
        return _axis_aliases(value)


class AxisDamping(InputModel):
    """Explicit damping per floor axis for every mount, N s/m.

    ``horizontal`` sets x and y, ``vertical`` sets z."""

    x: NonNegativeDamping | None = None
    y: NonNegativeDamping | None = None
    z: NonNegativeDamping | None = None

    @model_validator(mode="before")
    @classmethod
    def _aliases(cls, value: Any) -> Any:
        return _axis_aliases(value)


class Layout(InputModel):
    """Four mounts at (cg_x +- span_x/2, cg_y +- span_y/2, cg_z - height) around the machine's c.g."""

    span_x: Span = Field(description="distance between the mounts along X, m")
    span_y: Span = Field(description="distance between the mounts along Y, m")
    height: Annotated[Length, tested_range(-MAX_MOUNT_HEIGHT, MAX_MOUNT_HEIGHT, "length")] = Field(
        description="how far the machine's c.g. sits above the mounts, m"
    )

    def positions(self, cg: np.ndarray) -> np.ndarray:
        """(4, 3) mount positions, m, for a machine c.g. at ``cg`` (m)."""
        sx = np.array([-1.0, 1.0, 1.0, -1.0]) * self.span_x / 2.0
        sy = np.array([-1.0, -1.0, 1.0, 1.0]) * self.span_y / 2.0
        return np.stack([cg[0] + sx, cg[1] + sy, np.full(4, cg[2] - self.height)], axis=-1)


LAYOUT_ORDER = "(-x,-y), (+x,-y), (+x,+y), (-x,+y)"
"""Order of the four mounts of a layout around the c.g."""


class FeedforwardSpec(InputModel):
    """Feedforward of the stages' inertial wrench to an active mount's actuators (docs/physics.md, "Active
    mounts with feedforward"): ``gain`` times the opposite of the stages' reaction, low-passed at
    ``bandwidth``, clipped to ``force_limit`` per mount and axis. ``gain: 0`` turns it off."""

    gain: Annotated[
        Dimensionless, within(0.0, 1.5, "dimensionless", "0 (off) to a 50 % over-compensation")
    ] = Field(1.0, description="fraction of the stages' inertial wrench fed forward, 1")
    bandwidth: Annotated[
        Frequency, within(1.0, 1000.0, "frequency", "the corner of an isolation controller's feedforward")
    ] = Field(50.0, description="corner frequency of the first-order low-pass, Hz")
    force_limit: (
        Annotated[Force, within(1.0, 1e6, "force", "an actuator of 1 N to 1 MN per mount and axis")] | None
    ) = Field(None, description="largest actuator force per mount and axis, N (none: unlimited)")
    weight: bool = Field(
        False,
        description="also feed forward the change of the stages' weight moment (a stage that has travelled); "
        "false: the inertial wrench only",
    )

    def figures(self) -> Feedforward:
        """The engine's figures (SI; an unlimited actuator as ``inf``)."""
        return Feedforward(
            gain=float(self.gain),
            bandwidth=float(self.bandwidth),
            force_limit=float("inf") if self.force_limit is None else float(self.force_limit),
            weight=bool(self.weight),
        )


class Orientation(InputModel):
    """A mount's own axes in the floor frame: a rotation ``angle`` ``about`` a floor axis, or a 3x3
    rotation ``matrix`` whose columns are the mount's x, y, z. The mount's stiffness and damping act
    along its own axes (x, y from ``f_horizontal`` or ``k``/``c`` x, y; z from ``f_vertical`` or z)."""

    about: Literal["x", "y", "z"] | None = Field(None, description="the floor axis the mount is turned about")
    angle: Angle | None = Field(None, description="how far it is turned, rad (e.g. '30 deg')")
    matrix: (
        tuple[tuple[float, float, float], tuple[float, float, float], tuple[float, float, float]] | None
    ) = Field(None, description="rotation matrix, rows in the floor frame; columns: the mount's own axes")

    @model_validator(mode="after")
    def _one_way(self) -> Orientation:
        if (self.matrix is None) == (self.about is None or self.angle is None):
            raise ValueError("orientation: give about and angle, or matrix")
        if self.matrix is not None:
            Q = np.array(self.matrix, dtype=float)
            if np.abs(Q.T @ Q - np.eye(3)).max() > 1e-6 or np.linalg.det(Q) <= 0:
                raise ValueError(
                    "orientation.matrix: must be a rotation (orthonormal columns, determinant +1)"
                )
        return self

    def rotation(self) -> np.ndarray:
        """(3, 3) the mount's own axes (columns) in the floor frame."""
        if self.matrix is not None:
            Q = np.array(self.matrix, dtype=float)
            u, _, vt = np.linalg.svd(Q)  # the nearest exact rotation
            return u @ vt
        c, s = np.cos(float(self.angle or 0.0)), np.sin(float(self.angle or 0.0))
        i = "xyz".index(self.about or "z")
        j, k = (i + 1) % 3, (i + 2) % 3
        Q = np.eye(3)
        Q[j, j] = Q[k, k] = c
        Q[k, j], Q[j, k] = s, -s
        return Q


class Orifice(InputModel):
    """The laminar capillary between an air spring and its reservoir (Hagen-Poiseuille)."""

    area: Annotated[Area, Field(gt=0)] = Field(description="bore cross-section, m^2")
    length: Annotated[Length, Field(gt=0)] = Field(description="bore length, m")
    viscosity: Annotated[Viscosity, Field(gt=0)] = Field(1.81e-5, description="the gas's viscosity, Pa s")
    model: Literal["equivalent", "zener"] = Field(
        "equivalent",
        description="equivalent: a spring and viscous damper matching the orifice at the mount's own "
        "vertical frequency; zener: the standard linear solid with its own state (damping that depends "
        "on frequency; the lti and ltv levels)",
    )


class AirSpring(InputModel):
    """An air spring from its physics: the static load sets the gauge pressure ``p = F / A``, the gas
    gives the vertical stiffness ``n p_abs A^2 / V``. With an ``orifice`` to the reservoir the spring is
    a standard linear solid (slow: spring and reservoir, fast: the spring alone), its loss peaking at the
    orifice's relaxation frequency; the time integration takes its stiffness and damping at the mount's
    own vertical frequency. Without one the reservoir is open to the spring."""

    effective_area: Annotated[Area, Field(gt=0)] = Field(description="effective piston area, m^2")
    volume: Annotated[Volume, Field(gt=0)] = Field(description="gas volume of the spring, m^3")
    reservoir_volume: Annotated[Volume, Field(ge=0)] = Field(0.0, description="reservoir volume, m^3")
    polytropic_exponent: Annotated[Dimensionless, Field(ge=1.0, le=1.67)] = Field(
        1.4, description="1 isothermal, 1.4 adiabatic air"
    )
    max_pressure: Annotated[Pressure, Field(gt=0)] | None = Field(
        None, description="largest gauge pressure the spring is rated for, Pa (none: unchecked)"
    )
    orifice: Orifice | None = None

    @model_validator(mode="after")
    def _orifice_needs_reservoir(self) -> AirSpring:
        if self.orifice is not None and not self.reservoir_volume > 0:
            raise ValueError("air.orifice: an orifice needs a reservoir_volume above 0")
        return self


class LadderBranch(InputModel):
    """One Maxwell branch of an elastomer: a spring in series with a dashpot."""

    stiffness_ratio: Annotated[Dimensionless, Field(gt=0)] = Field(
        description="the branch's spring over the mount's static stiffness on each axis, 1"
    )
    relaxation_time: Annotated[Time, Field(gt=0)] = Field(description="dashpot over spring, s")


class Elastomer(InputModel):
    """An elastomer mount's frequency-dependent stiffness and loss as a Maxwell ladder with a state per
    branch and axis (the lti and ltv levels): fitted to a ``loss_factor`` nearly constant over
    ``[f_low, f_high]`` and a dynamic ``stiffening`` (stiffness at ``f_high`` over that at ``f_low``), or
    given as a ``ladder``. The mount's stiffness from its preset (or ``k``) is the static spring on each of
    its own axes; the ladder replaces its viscous damping (explicit ``c`` stays, in parallel)."""

    loss_factor: Annotated[Dimensionless, Field(gt=0, le=1)] | None = Field(
        None, description="loss factor to hold over the band, 1"
    )
    stiffening: Annotated[Dimensionless, Field(ge=1, le=10)] | None = Field(
        None, description="dynamic stiffness at f_high over that at f_low, 1"
    )
    f_low: Annotated[Frequency, Field(gt=0)] = Field(2.0, description="the band's low end, Hz")
    f_high: Annotated[Frequency, Field(gt=0)] = Field(20.0, description="the band's high end, Hz")
    branches: Annotated[int, Field(ge=1, le=6)] = Field(3, description="Maxwell branches of the fit")
    ladder: list[LadderBranch] | None = Field(
        None, min_length=1, max_length=6, description="the branches themselves instead of a fit"
    )

    @model_validator(mode="after")
    def _fit_or_ladder(self) -> Elastomer:
        fit = self.loss_factor is not None or self.stiffening is not None
        if (self.ladder is None) == (self.loss_factor is None or self.stiffening is None) or (
            self.ladder is not None and fit
        ):
            raise ValueError("elastomer: give loss_factor and stiffening (a fitted ladder), or ladder")
        if not self.f_low < self.f_high:
            raise ValueError(f"elastomer.f_high: must be above f_low ({self.f_low:g} Hz): {self.f_high:g}")
        return self


class Levelling(InputModel):
    """An air mount's levelling (height-control) valve (docs/isolators.md, "Levelling valves"): it lets air
    in or out at a rate proportional to the mounts' mean height error beyond ``dead_band``, bringing them
    back to their set height within about ``time_constant``. Mounts that name the same ``valve`` are
    plumbed to it (and must give it the same figures); at most three valves level a rigid base."""

    time_constant: Annotated[
        Time, Field(gt=0), within(0.05, 600.0, "time", "a levelling valve's, typically 1 to 10 s")
    ] = Field(description="levelling time constant: the force's rate is the height error times k / this, s")
    dead_band: Annotated[
        Length, Field(ge=0), within(0.0, 0.01, "length", "a valve's dead band, up to 10 mm")
    ] = Field(0.0, description="height error the valve ignores, m (0: none; a dead band needs rk4)")
    valve: Name | None = Field(
        None, description="the valve's name: mounts naming one share it (default: its own)"
    )


class Mount(InputModel):
    """One isolator of an explicit list. Its own values win over the group's: explicit ``k``/``c`` first,
    then its overrides, then its own ``preset``; without a preset of its own it takes the group's
    overrides and preset."""

    position: Position = Field(description="point of action, m")
    model: ProductId | None = Field(
        None, description="a product of the catalogue: its type and figures, unless given here"
    )
    preset: PresetName | None = None
    f_vertical: MountFrequency | None = None
    f_horizontal: MountFrequency | None = None
    zeta: DampingRatio | None = None
    zeta_vertical: DampingRatio | None = Field(None, description="damping ratio along the own z (not zeta)")
    zeta_horizontal: DampingRatio | None = Field(None, description="damping ratio along the own x, y")
    skyhook: bool | None = None
    feedforward: FeedforwardSpec | None = None
    k: tuple[NonNegativeStiffness, NonNegativeStiffness, NonNegativeStiffness] | None = Field(
        None, description="[kx, ky, kz], N/m"
    )
    c: tuple[NonNegativeDamping, NonNegativeDamping, NonNegativeDamping] | None = Field(
        None, description="[cx, cy, cz], N s/m"
    )
    orientation: Orientation | None = Field(None, description="the mount's own axes (default: the floor's)")
    air: AirSpring | None = Field(None, description="an air spring from its physics (vertical, own z axis)")
    elastomer: Elastomer | None = Field(None, description="an elastomer's Maxwell ladder on its own axes")
    levelling: Levelling | None = Field(None, description="an air mount's levelling valve (default: none)")


class PresetTuning(InputModel):
    """The figures of the model of one isolator type this machine would use (vendor data)."""

    f_vertical: MountFrequency | None = None
    f_horizontal: MountFrequency | None = None
    zeta: DampingRatio | None = None
    skyhook: bool | None = None
    feedforward: FeedforwardSpec | None = None


class Isolators(InputModel):
    """The isolators: a type (``preset``) with optional overrides, placed by a ``layout`` or a ``list``.

    Stiffness and damping of a mount along each floor axis come, in order of precedence, from the mount's
    explicit ``k``/``c``, the group's ``k``/``c`` for that axis, or the preset frequency (X, Y from
    ``f_horizontal``, Z from ``f_vertical``) and ``zeta`` applied to the static load the mount carries;
    ``zeta_vertical`` and ``zeta_horizontal`` (a product's damping per direction) take the place of ``zeta``
    along the mount's own z and x, y, below a listed mount's own ``zeta`` or preset.
    ``tuning`` replaces a type's preset figures by those of the model this machine would use, whenever
    that type is chosen: a study that varies ``preset`` then compares those models, where the group's
    overrides would apply to every type alike. ``feedforward`` (active mounts: the stages' inertial wrench
    fed to the actuators) comes as a whole from the mount's own, its preset's, the group's, or the group
    preset's (on for ``active``, off for ``air`` and ``elastomer``).
    """

    preset: PresetName = "air"
    model: ProductId | None = Field(
        None, description="a product of the catalogue for every mount: its type and figures, unless given"
    )
    catalogue: str | Catalogue | None = Field(
        None,
        description="the catalogue model: names: a shipped one (representative, the default), a file (read "
        "when the scene file is loaded) or the catalogue inline",
    )
    per_corner: PerCornerCounts | None = Field(
        None, description="how many isolators side by side a mount position may take when sized (default [1])"
    )
    tuning: dict[PresetName, PresetTuning] = Field(default_factory=dict)
    f_vertical: MountFrequency | None = None
    f_horizontal: MountFrequency | None = None
    zeta: DampingRatio | None = None
    zeta_vertical: DampingRatio | None = Field(
        None, description="damping ratio along every mount's own z, in place of zeta there"
    )
    zeta_horizontal: DampingRatio | None = Field(
        None, description="damping ratio along every mount's own x and y, in place of zeta there"
    )
    skyhook: bool | None = None
    feedforward: FeedforwardSpec | None = None
    k: AxisStiffness | None = None
    c: AxisDamping | None = None
    orientation: Orientation | None = Field(None, description="every mount's own axes (default: the floor's)")
    air: AirSpring | None = Field(None, description="every mount an air spring from its physics")
    elastomer: Elastomer | None = Field(None, description="every mount an elastomer's Maxwell ladder")
    levelling: Levelling | None = Field(
        None, description="every mount's levelling valve (a mount's own wins; without a valve name: one each)"
    )
    layout: Layout | None = None
    mounts: list[Mount] | None = Field(None, alias="list", max_length=MAX_MOUNTS)

    @model_validator(mode="after")
    def _placement(self) -> Isolators:
        if (self.layout is None) == (self.mounts is None):
            raise ValueError("isolators: give either layout (four mounts around the c.g.) or list, not both")
        if self.mounts is not None:
            if len(self.mounts) < 3:
                raise ValueError(
                    f"isolators: at least 3 are needed to carry a rigid base, got {len(self.mounts)}"
                )
            xy = np.array([m.position[:2] for m in self.mounts])
            try:
                load_share(xy, xy.mean(axis=0), 1.0)
            except CollinearIsolatorsError as err:
                raise ValueError(str(err)) from None
        return self

    @model_validator(mode="after")
    def _products(self) -> Isolators:
        """Apply each ``model:`` (group and listed mounts): the product's type as the preset and its
        figures wherever the block leaves them unset. A scene without ``model:`` is left as it is."""
        named = [(ISOLATORS, self)] + [(f"{ISOLATORS}.list[{j}]", m) for j, m in enumerate(self.listed)]
        if all(block.model is None for _, block in named):
            return self
        catalogue = scene_catalogue(self.catalogue, f"{ISOLATORS}.catalogue")
        for where, block in named:
            if block.model is None:
                continue
            try:
                product = catalogue.product(block.model, f"{where}.model")
            except UnknownProductError as err:
                raise ValueError(str(err)) from None
            figures = product_figures(product)
            if block.zeta is not None:  # the block's own damping ratio wins on every axis
                figures = {k: v for k, v in figures.items() if k not in AXIS_DAMPING}
            if "preset" in block.model_fields_set and block.preset != product.type:
                raise ValueError(
                    f"{where}.preset: product {product.id!r} is {product.type}; leave preset out or give "
                    f"{product.type}"
                )
            for key, value in figures.items():
                if getattr(block, key) is None or key == "preset":
                    setattr(block, key, value)
        return self

    @property
    def count(self) -> int:
        return 4 if self.mounts is None else len(self.mounts)

    @property
    def listed(self) -> list[Mount]:
        """The mounts of a ``list`` placement, in order; empty for a ``layout`` (``_placement`` requires
        exactly one of the two)."""
        return self.mounts if self.mounts is not None else []

    def preset_of(self, name: PresetName) -> IsolatorPreset:
        """The figures of type ``name``: the preset, with this machine's ``tuning`` of it applied."""
        base = PRESETS[name]
        tune = self.tuning.get(name)
        if tune is None:
            return base
        given = {k: getattr(tune, k) for k, v in tune.model_dump().items() if v is not None}
        if "feedforward" in given:
            given["feedforward"] = given["feedforward"].figures()
        return replace(base, **given)
