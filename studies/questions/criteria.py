"""Design criteria: what the machine must achieve at its points of interest and on its mounts.

A scene or a study may carry a ``criteria:`` block, keyed by point of interest, plus ``isolators`` for the
mounts, with limits in units::

    criteria:
      tool:
        displacement: 10 um                     # peak |displacement| of the point, any axis, whole run
        settle: {within: 5 um, after: 0.5 s}    # back within 5 um of rest at most 0.5 s after each move
        velocity: VC-C                          # floor-induced velocity, one-third-octave bands
      isolators: {no_liftoff: true, max_force: 20 kN, max_deflection: 5 mm}

Each criterion is judged per case from the stored outputs (:func:`add_criteria`):

=================================  ===============================================  =====================
criterion                          value judged                                     margin (positive: met)
=================================  ===============================================  =====================
``<point>.displacement``           ``peak_point_displacement``, largest axis         1 - value / limit
``<point>.settle``                 ``point_settling_time`` to ``within``             1 - value / ``after``
``<point>.velocity``               ``floor_point_velocity``, largest axis and band   1 - value / VC level
``isolators.no_liftoff``           ``min_isolator_load / static_isolator_load``,     value
                                   smallest mount
``isolators.max_force``            ``max_isolator_load`` (static + dynamic           1 - value / limit
                                   vertical load), largest mount
``isolators.max_deflection``       ``peak_isolator_deflection``, largest mount/axis  1 - value / limit
=================================  ===============================================  =====================

Margins are fractions of the limit (unit 1), so criteria of different kinds compare on one scale: 0.2 means
20 % to spare, -0.5 means 50 % over. ``no_liftoff``'s margin is the share of its preload the most unloaded
mount keeps. A case that did not end ``ok`` has no margins (NaN) and does not meet its criteria.

``settle`` is judged after every move: within each interval in which all stages rest, the point must stay
within ``within`` of its static position for that interval from ``after`` past the move's end (see
``point_settling_time`` in :mod:`isolab.engine.results`); the engine measures each point's settling time to
its own ``within`` (the scene's ``settle_tolerance`` for points without a settle criterion).
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING, Annotated, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from isolab.studies.units import Force, Length, Time, readable_unit

if TYPE_CHECKING:  # xarray loads where a dataset is judged, not where a scene is read
    import xarray as xr

VC_NAMES = ("VC-A", "VC-B", "VC-C", "VC-D", "VC-E", "VC-F", "VC-G")
"""The generic vibration criteria a ``velocity`` criterion may name (levels:
:mod:`isolab.studies.questions.floor`)."""

ISOLATORS = "isolators"
"""The key of the mounts' criteria in a ``criteria:`` block (every other key names a point)."""

_PositiveLength = Annotated[Length, Field(gt=0)]
_PositiveTime = Annotated[Time, Field(gt=0)]
_PositiveForce = Annotated[Force, Field(gt=0)]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", populate_by_name=True)


class SettleCriterion(_Model):
    """Back within ``within`` of the rest position at most ``after`` past the end of each move."""

    within: _PositiveLength = Field(description="allowed distance from the rest position, m")
    after: _PositiveTime = Field(description="time allowed after each move ends, s")


class PointCriteria(_Model):
    """Limits at one point of interest."""

    displacement: _PositiveLength | None = Field(
        None, description="largest peak |displacement| of the point on any axis over the run, m"
    )
    settle: SettleCriterion | None = None
    velocity: str | None = Field(
        None, description="generic vibration criterion the floor-induced velocity must meet: VC-A .. VC-G"
    )

    @field_validator("velocity")
    @classmethod
    def _vc_name(cls, value: str | None) -> str | None:
        if value is None:
            return value
        name = str(value).strip().upper().replace(" ", "-")
        if name not in VC_NAMES:
            raise ValueError(f"unknown vibration criterion {value!r}; choose one of {', '.join(VC_NAMES)}")
        return name


class IsolatorCriteria(_Model):
    """Limits on every mount."""

    no_liftoff: bool = Field(False, description="no mount may lose its whole preload")
    max_force: _PositiveForce | None = Field(
        None, description="largest total vertical load (static + dynamic) on any mount, N"
    )
    max_deflection: _PositiveLength | None = Field(
        None, description="largest peak deflection of any mount on any axis from its static state, m"
    )


class Criteria(_Model):
    """A ``criteria:`` block: ``isolators`` for the mounts, any other key a point of interest."""

    model_config = ConfigDict(extra="allow", populate_by_name=True)

    isolators: IsolatorCriteria | None = None

    @model_validator(mode="after")
    def _points(self) -> Criteria:
        extra = dict(self.__pydantic_extra__ or {})
        for key, value in extra.items():
            if isinstance(value, PointCriteria):
                continue
            try:
                extra[key] = PointCriteria.model_validate(value)
            except ValidationError as err:
                e = err.errors()[0]
                loc = [str(x) for x in e["loc"]]
                msg = e["msg"].removeprefix("Value error, ")
                if loc and msg.startswith(f"{loc[-1]}: "):
                    msg = msg[len(loc[-1]) + 2 :]
                raise ValueError(f"criteria.{'.'.join([key, *loc])}: {msg}") from None
        self.__pydantic_extra__ = extra
        return self

    @property
    def points(self) -> dict[str, PointCriteria]:
        """Point name -> its criteria, in the order written."""
        return dict(self.__pydantic_extra__ or {})

    def names(self) -> list[str]:
        """The criteria's names in order (``tool_displacement``, ..., ``isolators_no_liftoff``, ...)."""
        return [c.name for c in judged_criteria(self)]

    def check_points(self, points: Iterable[str], has_floor_spectrum: bool) -> None:
        """Refuse criteria at points the scene lacks, and a velocity criterion without a floor spectrum.

        Raises:
            ValueError: ``criteria.<key>...: reason``.
        """
        known = list(points)
        for name, pc in self.points.items():
            if name not in known:
                choices = ", ".join(known) if known else "the scene has none; add them under points"
                raise ValueError(
                    f"criteria.{name}: no point of interest named {name!r} (points: {choices}); "
                    f"the mounts' criteria go under {ISOLATORS!r}"
                )
            if pc.velocity is not None and not has_floor_spectrum:
                raise ValueError(
                    f"criteria.{name}.velocity: judging {pc.velocity} needs the floor's vibration: "
                    "give floor.spectrum in the scene"
                )

    def settle_tolerances(self) -> dict[str, float]:
        """Point name -> the ``within`` of its settle criterion, m (the engine's per-point tolerance)."""
        return {n: pc.settle.within for n, pc in self.points.items() if pc.settle is not None}


class Criterion:
    """One judged criterion: its name, the limit (SI) and unit, and how it reads a dataset."""

    def __init__(self, name: str, limit: float, unit: str, description: str):
        self.name, self.limit, self.unit, self.description = name, float(limit), unit, description

    def __repr__(self) -> str:
        return f"Criterion({self.name!r}, {self.limit!r} {self.unit})"


def judged_criteria(criteria: Criteria) -> list[Criterion]:
    """The criteria of a block, one per limit, in the order written (points, then the mounts)."""
    out = []
    for point, pc in criteria.points.items():
        if pc.displacement is not None:
            out.append(
                Criterion(f"{point}_displacement", pc.displacement, "m", f"peak displacement of {point}")
            )
        if pc.settle is not None:
            unit, scale = readable_unit("m", pc.settle.within)
            out.append(
                Criterion(
                    f"{point}_settle",
                    pc.settle.after,
                    "s",
                    f"{point} back within {pc.settle.within / scale:.3g} {unit} of rest after each move",
                )
            )
        if pc.velocity is not None:
            from isolab.studies.questions.floor import VC_LEVELS

            out.append(
                Criterion(
                    f"{point}_velocity",
                    VC_LEVELS[pc.velocity],
                    "m/s",
                    f"floor-induced one-third-octave velocity of {point} within {pc.velocity}",
                )
            )
    iso = criteria.isolators
    if iso is not None:
        if iso.no_liftoff:
            out.append(Criterion("isolators_no_liftoff", 0.0, "N", "no mount loses its whole preload"))
        if iso.max_force is not None:
            out.append(Criterion("isolators_max_force", iso.max_force, "N", "largest total mount load"))
        if iso.max_deflection is not None:
            out.append(
                Criterion("isolators_max_deflection", iso.max_deflection, "m", "largest mount deflection")
            )
    return out


def _value(ds: xr.Dataset, criterion: Criterion) -> xr.DataArray:
    """The per-case quantity a criterion judges, in its unit."""
    name = criterion.name
    if name == "isolators_no_liftoff":
        return (ds["min_isolator_load"] / ds["static_isolator_load"]).min("isolator", skipna=False)
    if name == "isolators_max_force":
        return ds["max_isolator_load"].max("isolator", skipna=False)
    if name == "isolators_max_deflection":
        return ds["peak_isolator_deflection"].max(["isolator", "axis"], skipna=False)
    point, kind = name.rsplit("_", 1)
    if kind == "displacement":
        return ds["peak_point_displacement"].sel(point=point, drop=True).max("axis", skipna=False)
    if kind == "settle":
        return ds["point_settling_time"].sel(point=point, drop=True)
    return ds["floor_point_velocity"].sel(point=point, drop=True).max("axis", skipna=False)


def margins(ds: xr.Dataset, criteria: Criteria) -> xr.DataArray:
    """Each case's margin to each criterion (dims: the case dims, then ``criterion``), unit 1, positive
    where met; NaN for a case that did not end ``ok``."""
    import xarray as xr

    judged = judged_criteria(criteria)
    parts = []
    for c in judged:
        v = _value(ds, c)
        parts.append(v if c.name == "isolators_no_liftoff" else 1.0 - v / c.limit)
    if not parts:
        case_dims = ds["status"].dims
        shape = tuple(ds.sizes[d] for d in case_dims) + (0,)
        return xr.DataArray(np.zeros(shape), dims=(*case_dims, "criterion"))
    da = xr.concat(parts, dim="criterion", coords="minimal", compat="override")
    da = da.transpose(*ds["status"].dims, "criterion")
    return da.where(ds["status"] == 0)


def add_criteria(ds: xr.Dataset, criteria: Criteria | None) -> xr.Dataset:
    """``ds`` with ``criterion_margin`` (case dims, ``criterion``) and ``meets_criteria`` (case dims)
    added, and the block in the ``criteria`` attribute; ``ds`` unchanged when there are no criteria."""
    import xarray as xr

    if criteria is None or not judged_criteria(criteria):
        return ds
    judged = judged_criteria(criteria)
    m = margins(ds, criteria)
    ok = ds["status"] == 0
    meets = (m >= 0).all("criterion") & ok
    out = ds.copy()
    out = out.assign_coords(
        criterion=xr.Variable(
            "criterion",
            np.array([c.name for c in judged], dtype=np.str_),
            {"units": "1", "long_name": "design criterion"},
        ),
        criterion_limit=xr.Variable(
            "criterion",
            np.array([c.limit for c in judged]),
            {"units": "1", "long_name": "the criterion's limit, in the unit criterion_unit gives (SI)"},
        ),
        criterion_unit=xr.Variable(
            "criterion",
            np.array([c.unit for c in judged], dtype=np.str_),
            {"units": "1", "long_name": "SI unit of the criterion's limit"},
        ),
    )
    out["criterion_margin"] = xr.Variable(
        m.dims,
        np.asarray(m.values, dtype=np.float64),
        {
            "units": "1",
            "long_name": "margin to the criterion as a fraction of its limit (positive: met; no_liftoff: "
            "the preload share the most unloaded mount keeps)",
        },
    )
    flags = np.where(ok.values, meets.values.astype(np.float32), np.float32(np.nan)).astype(np.float32)
    var = xr.Variable(
        ds["status"].dims,
        flags,
        {
            "units": "1",
            "long_name": "the case meets every design criterion",
            "flag_values": np.array([0, 1], dtype=np.int8),
            "flag_meanings": "false true",
        },
    )
    var.encoding = {"dtype": "int8", "_FillValue": np.int8(-1)}
    out["meets_criteria"] = var
    out.attrs["criteria"] = json.dumps(criteria.model_dump(mode="json", exclude_none=True))
    return out


def result_margins(
    result: Any, criteria: Criteria, points: Sequence[str], isolators: Sequence[str], case: int = 0
) -> dict[str, float]:
    """One case's margin to each criterion (unit 1, positive: met; NaN for a case that did not end ``ok``)
    straight from an ``engine.results.SimulationResult`` with the points and isolators named in batch
    order: what ``isolab simulate`` prints."""
    import xarray as xr

    r = result
    pa, ia = ("case", "point", "axis"), ("case", "isolator", "axis")
    pick = slice(case, case + 1)

    def arr(name: str, fill_shape: tuple[int, ...]) -> np.ndarray:
        v = getattr(r, name, None)
        return np.full(fill_shape, np.nan) if v is None else np.asarray(v, dtype=float)[pick]

    p, n = len(points), len(isolators)
    ds = xr.Dataset(
        {
            "status": (("case",), np.asarray(r.status)[pick]),
            "peak_point_displacement": (pa, arr("peak_point_displacement", (1, p, 3))),
            "point_settling_time": (("case", "point"), arr("point_settling_time", (1, p))),
            "floor_point_velocity": (pa, arr("floor_point_velocity", (1, p, 3))),
            "min_isolator_load": (("case", "isolator"), arr("min_isolator_load", (1, n))),
            "static_isolator_load": (("case", "isolator"), arr("static_isolator_load", (1, n))),
            "max_isolator_load": (("case", "isolator"), arr("max_isolator_load", (1, n))),
            "peak_isolator_deflection": (ia, arr("peak_isolator_deflection", (1, n, 3))),
        },
        coords={"point": list(points), "isolator": list(isolators)},
    )
    m = margins(ds, criteria)
    return {c.name: float(v) for c, v in zip(judged_criteria(criteria), m.values[0], strict=True)}


def criterion_margin(ds: xr.Dataset, case: Any, criterion: str) -> float:
    """One case's margin to one criterion (``case``: an index along a sampled study's ``case`` dimension,
    or a dict of grid coordinates); positive means met.

    Raises:
        KeyError: the study has no such criterion.
    """
    if "criterion_margin" not in ds:
        raise KeyError(f"{criterion!r}: the study has no criteria")
    names = [str(c) for c in ds["criterion"].values]
    if criterion not in names:
        raise KeyError(f"{criterion!r}: no such criterion (criteria: {', '.join(names)})")
    da = ds["criterion_margin"].sel(criterion=criterion)
    da = da.sel(case) if isinstance(case, dict) else da.isel(case=int(case))
    return float(da.values)
