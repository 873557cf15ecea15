"""Tolerances: how far a built machine may stray from its drawing, and the cases that spread draws.

A scene or a study may carry a ``tolerances:`` block, keyed by parameter path (the paths of
:mod:`studies.inputs.parameters`), each a distribution about the nominal value, in units::

    tolerances:
      isolators.f_vertical: {distribution: normal, sigma: 5 %}             # 5 % of the nominal, 1 sigma
      isolators.zeta: {distribution: uniform, within: 20 %}                # nominal +-20 %, evenly
      stages.y.mass: {distribution: normal, sigma: 40 kg, within: 100 kg}  # truncated at +-100 kg
      machine.block.density: {distribution: uniform, within: 100 kg/m^3}   # 2,600-2,800 about 2,700
      isolators.f_horizontal: {distribution: lognormal, sigma: 10 %}

A value written with ``%`` is a share of the nominal value, for every parameter (a dimensionless one
included: ``zeta`` 30 % with ``sigma: 10 %`` spreads it by 3 points); anything else is in the parameter's
own units (a plain number is SI). The distributions, with m the nominal, s the sigma and w the ``within``:

============  ===================================================================================
``normal``    m + s z, z standard normal; truncated to [m - w, m + w] when ``within`` is given
``uniform``   evenly over [m - w, m + w] (``within`` required, no ``sigma``)
``lognormal`` m exp(z s / m): the median is m and ``s / m`` the standard deviation of the logarithm
              (about the relative standard deviation for small spreads); truncated to [m - w, m + w]
============  ===================================================================================

The nominal value is the scene's (a study's parameter with one value sets it instead).
:func:`draw` maps points of the unit cube to these distributions by their inverse distribution
functions: a scrambled Sobol' sequence (``sampling: sobol``, the default: a smoother spread of the
cases than independent draws, so a probability estimate settles faster) or independent draws
(``sampling: random``). :func:`add_reliability` stores the share of the cases that meet the criteria
with its Clopper-Pearson interval.
"""

from __future__ import annotations

import json
import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, StrictFloat, StrictInt, StrictStr, model_validator

from isolab.studies.units import to_si

if TYPE_CHECKING:  # scipy and xarray load where they are used, not where a scene is read
    import xarray as xr

DISTRIBUTIONS = ("normal", "uniform", "lognormal")
"""The distributions a tolerance may follow."""
CONFIDENCE = 0.95
"""The confidence level of the stored probability intervals."""
INTERVAL_METHOD = "Clopper-Pearson (exact binomial)"
"""How the probability intervals are computed (:func:`clopper_pearson`)."""
MAX_TOLERANCES = 100
"""Most paths a ``tolerances:`` block may name."""

_Written = StrictFloat | StrictInt | StrictStr


class Tolerance(BaseModel):
    """One parameter's spread about its nominal value (see the module docstring)."""

    model_config = ConfigDict(extra="forbid")

    distribution: Literal["normal", "uniform", "lognormal"] = Field(
        "normal", description="normal, uniform or lognormal about the nominal value"
    )
    sigma: _Written | None = Field(
        None,
        description="normal and lognormal: the standard deviation, in the parameter's units or as a % of "
        "the nominal value",
    )
    within: _Written | None = Field(
        None,
        description="uniform: the half-width (nominal +- within); normal and lognormal: where the "
        "distribution is truncated; in the parameter's units or as a % of the nominal value",
    )

    @model_validator(mode="after")
    def _fields_of_the_distribution(self) -> Tolerance:
        if self.distribution == "uniform":
            if self.within is None:
                raise ValueError("within: a uniform tolerance needs its half-width (nominal +- within)")
            if self.sigma is not None:
                raise ValueError("sigma: a uniform tolerance is given by within alone")
        elif self.sigma is None:
            raise ValueError(f"sigma: a {self.distribution} tolerance needs its standard deviation")
        return self


Tolerances = Annotated[
    dict[Annotated[str, Field(min_length=1, max_length=200)], Tolerance], Field(max_length=MAX_TOLERANCES)
]
"""A ``tolerances:`` block: parameter path -> :class:`Tolerance`."""


@dataclass(frozen=True)
class Spread:
    """A tolerance resolved in SI about its nominal value.

    Attributes:
        name: the parameter's name (a coordinate of the dataset).
        path: the canonical parameter path it sets.
        unit: the parameter's SI unit.
        distribution: one of :data:`DISTRIBUTIONS`.
        nominal: the nominal value (SI).
        sigma: the standard deviation (SI; NaN for uniform).
        low, high: the bounds (SI; -inf/inf for an untruncated normal or lognormal).
        within: the half-width as written, in SI (inf when not given).
        shares: whether ``sigma`` and ``within`` were written as a share of the nominal (``%``).
    """

    name: str
    path: str
    unit: str
    distribution: str
    nominal: float
    sigma: float
    low: float
    high: float
    within: float = math.inf
    shares: tuple[bool, bool] = (False, False)

    def about(self, nominal: float) -> Spread:
        """The same tolerance about another nominal value (SI): an amount written as a share of the
        nominal (``%``) scales with it, one written in units stays.

        Raises:
            ValueError: a lognormal spread about a nominal that is not positive, or a share of a zero
                nominal.
        """
        if nominal == self.nominal:
            return self
        if not np.isfinite(nominal):
            raise ValueError("the nominal value is not finite")
        if (self.shares[0] or self.shares[1]) and nominal == 0.0:
            raise ValueError("a share of the nominal value means nothing for a nominal of 0")
        scale = abs(nominal / self.nominal) if self.nominal != 0.0 else 1.0
        sigma = self.sigma * scale if self.shares[0] else self.sigma
        within = self.within * scale if self.shares[1] else self.within
        low, high = nominal - within, nominal + within
        if self.distribution == "lognormal":
            if nominal <= 0.0:
                raise ValueError(f"a lognormal spread needs a positive nominal, got {nominal:g}")
            if math.isfinite(within):
                low = max(low, 0.0)  # the logarithm has no lower end: truncated at zero
        return replace(self, nominal=float(nominal), sigma=sigma, low=low, high=high, within=within)

    def from_unit(self, u: np.ndarray) -> np.ndarray:
        """Map ``u`` in (0, 1) to values by the inverse distribution function (SI)."""
        u = np.clip(np.asarray(u, dtype=np.float64), 1e-12, 1.0 - 1e-12)
        m = self.nominal
        if self.distribution == "uniform":
            return self.low + u * (self.high - self.low)
        if self.distribution == "normal":
            scale, lo, hi = self.sigma, (self.low - m) / self.sigma, (self.high - m) / self.sigma
        else:  # lognormal: ln x normal about ln m with standard deviation sigma / m
            scale = self.sigma / m
            lo = math.log(self.low / m) / scale if self.low > 0 else -np.inf
            hi = math.log(self.high / m) / scale
        from scipy import special

        p_lo, p_hi = special.ndtr(lo), special.ndtr(hi)
        z = special.ndtri(p_lo + u * (p_hi - p_lo))
        z = np.clip(z, lo, hi)
        return m + self.sigma * z if self.distribution == "normal" else m * np.exp(scale * z)

    def cdf(self, x: float | np.ndarray) -> np.ndarray:
        """The probability that a draw is at most ``x`` (SI): the closed form the draws follow."""
        x = np.asarray(x, dtype=np.float64)
        m = self.nominal
        if self.distribution == "uniform":
            return np.clip((x - self.low) / (self.high - self.low), 0.0, 1.0)
        if self.distribution == "normal":
            z, lo, hi = (x - m) / self.sigma, (self.low - m) / self.sigma, (self.high - m) / self.sigma
        else:
            scale = self.sigma / m
            with np.errstate(divide="ignore", invalid="ignore"):
                z = np.where(x > 0, np.log(np.maximum(x, 1e-300) / m) / scale, -np.inf)
            lo = math.log(self.low / m) / scale if self.low > 0 else -np.inf
            hi = math.log(self.high / m) / scale
        from scipy import special

        p_lo, p_hi = special.ndtr(lo), special.ndtr(hi)
        return np.clip((special.ndtr(np.clip(z, lo, hi)) - p_lo) / (p_hi - p_lo), 0.0, 1.0)

    def described(self) -> dict[str, Any]:
        """The spread as stored in a dataset's ``tolerances`` attribute (SI)."""
        out: dict[str, Any] = {"path": self.path, "distribution": self.distribution, "nominal": self.nominal}
        if self.distribution != "uniform":
            out["sigma"] = self.sigma
        if np.isfinite(self.low):
            out["low"] = self.low
        if np.isfinite(self.high):
            out["high"] = self.high
        out["unit"] = self.unit
        return out


def _amount(value: _Written, nominal: float, dimension: str, where: str) -> float:
    """A sigma or half-width in SI: a share of ``nominal`` when written with ``%``, else a quantity."""
    if isinstance(value, str) and value.strip().endswith("%"):
        number = value.strip()[:-1].strip()
        try:
            share = float(number) / 100.0
        except ValueError:
            raise ValueError(f"{where}: {value!r} is not a number followed by %") from None
        if nominal == 0.0:
            raise ValueError(
                f"{where}: a share of the nominal value means nothing for a nominal of 0; give it in units"
            )
        amount = share * abs(nominal)
    else:
        amount = to_si(value, dimension, where)
    if not (np.isfinite(amount) and amount > 0.0):
        raise ValueError(f"{where}: must be positive, got {value!r}")
    return float(amount)


def resolve_spread(
    tolerance: Tolerance, *, name: str, path: str, unit: str, dimension: str, nominal: float, where: str
) -> Spread:
    """The :class:`Spread` of ``tolerance`` about ``nominal`` (SI), for a parameter of ``dimension``.

    Raises:
        ValueError: ``<where>.<field>: reason`` (a sigma that is not positive, a lognormal about a
            nominal that is not positive, a truncation below zero for it).
    """
    if not np.isfinite(nominal):
        raise ValueError(f"{where}: the nominal value is not finite")
    sigma = float("nan")
    if tolerance.sigma is not None:
        sigma = _amount(tolerance.sigma, nominal, dimension, f"{where}.sigma")
    low, high, w = -np.inf, np.inf, math.inf
    if tolerance.within is not None:
        w = _amount(tolerance.within, nominal, dimension, f"{where}.within")
        low, high = nominal - w, nominal + w
    if tolerance.distribution == "lognormal":
        if nominal <= 0.0:
            raise ValueError(
                f"{where}.distribution: a lognormal spread needs a positive nominal, got {nominal:g}"
            )
        if tolerance.within is not None and low <= 0.0:
            low = 0.0  # the logarithm has no lower end: truncate at zero
    shares = (_is_share(tolerance.sigma), _is_share(tolerance.within))
    return Spread(
        name, path, unit, tolerance.distribution, float(nominal), sigma, float(low), float(high), w, shares
    )


def _is_share(value: _Written | None) -> bool:
    return isinstance(value, str) and value.strip().endswith("%")


def unit_draws(n: int, d: int, seed: int = 0, sampling: str = "sobol") -> np.ndarray:
    """(n, d) points of the unit cube: a scrambled Sobol' sequence (``sobol``) or independent uniform
    draws (``random``); the same ``seed`` gives the same points."""
    rng = np.random.default_rng(seed)
    if d == 0:
        return np.zeros((n, 0))
    if sampling == "random":
        return rng.random((n, d))
    if sampling != "sobol":
        raise ValueError(f"design.sampling: {sampling!r}; choose sobol or random")
    from scipy.stats import qmc

    engine = qmc.Sobol(d=d, scramble=True, rng=rng)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*balance properties of Sobol.*", category=UserWarning)
        return engine.random(n)


def draw(spreads: list[Spread], n: int, seed: int = 0, sampling: str = "sobol") -> np.ndarray:
    """(n, len(spreads)) values (SI) drawn from each spread (see :func:`unit_draws`)."""
    u = unit_draws(n, len(spreads), seed, sampling)
    return np.stack([s.from_unit(u[:, j]) for j, s in enumerate(spreads)], axis=1).reshape(n, len(spreads))


def cloud(spreads: list[Spread], unit: np.ndarray, nominals: Mapping[str, float]) -> np.ndarray:
    """(N, len(spreads)) values (SI) of one candidate's tolerance cloud: each spread about the candidate's
    value of it (``nominals``, by spread name; a spread not named there about its own nominal), mapped from
    the unit-cube points ``unit`` (N, len(spreads)). Every candidate given the same ``unit`` sees the same
    draws (common random numbers): two candidates differ by their values, not by the luck of the draw."""
    u = np.asarray(unit, dtype=np.float64).reshape(-1, len(spreads))
    columns = [
        (s.about(float(nominals[s.name])) if s.name in nominals else s).from_unit(u[:, j])
        for j, s in enumerate(spreads)
    ]
    return np.stack(columns, axis=1).reshape(len(u), len(spreads))


# --------------------------------------------------------------------------------------------- probability
def clopper_pearson(k: int, n: int, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """The two-sided Clopper-Pearson interval of a probability seen ``k`` times in ``n`` independent
    trials: it holds the true probability with at least ``confidence`` (exact binomial tails)."""
    if n <= 0:
        return 0.0, 1.0
    a = 1.0 - confidence
    from scipy import stats

    low = 0.0 if k <= 0 else float(stats.beta.ppf(a / 2, k, n - k + 1))
    high = 1.0 if k >= n else float(stats.beta.ppf(1 - a / 2, k + 1, n - k))
    return low, high


def meets_counts(ds: xr.Dataset) -> tuple[int, int, np.ndarray, list[str]]:
    """(cases meeting every criterion, cases, failures per criterion, criterion names) of a dataset with
    criteria; a case that did not end ok meets nothing."""
    ok = np.asarray(ds["status"].values).reshape(-1) == 0
    n = int(ok.size)
    margin = np.asarray(ds["criterion_margin"].values, dtype=np.float64).reshape(n, -1)
    met = np.nan_to_num(margin, nan=-1.0) >= 0.0
    met &= ok[:, None]
    names = [str(c) for c in ds["criterion"].values]
    return int(met.all(axis=1).sum()), n, (~met).sum(axis=0), names


def add_reliability(
    ds: xr.Dataset, spreads: list[Spread], sampling: str, confidence: float = CONFIDENCE
) -> xr.Dataset:
    """``ds`` (a study drawn from ``spreads``, with criteria) with ``probability_meets_criteria`` and
    ``criterion_failure_probability`` and their ``*_interval`` (``bound``: lower, upper), and the spreads
    in the ``tolerances`` attribute. ``ds`` unchanged, but for the attribute, when it has no criteria."""
    out = ds.copy()
    out.attrs["tolerances"] = json.dumps({s.name: s.described() for s in spreads})
    out.attrs["tolerance_sampling"] = sampling
    if "criterion_margin" not in ds:
        return out
    k, n, fails, names = meets_counts(ds)
    how = f"{INTERVAL_METHOD} {confidence:.0%} interval over {n} cases, as if drawn independently " + (
        "(a scrambled Sobol' sequence usually spreads them more evenly: the interval is then wide)"
        if sampling == "sobol"
        else "(they were)"
    )
    import xarray as xr

    bound = xr.Variable("bound", np.array(["lower", "upper"]), {"units": "1", "long_name": "interval bound"})
    out = out.assign_coords(bound=bound)
    common = {"units": "1", "confidence": confidence, "interval_method": INTERVAL_METHOD}
    out["probability_meets_criteria"] = xr.Variable(
        (),
        k / n if n else np.nan,
        {
            **common,
            "long_name": "probability that the machine, within its tolerances, meets every criterion "
            "(share of the cases; a case that did not end ok does not)",
        },
    )
    out["probability_meets_criteria_interval"] = xr.Variable(
        "bound",
        np.array(clopper_pearson(k, n, confidence)),
        {**common, "long_name": f"interval of probability_meets_criteria: {how}"},
    )
    out["criterion_failure_probability"] = xr.Variable(
        "criterion",
        fails / n if n else np.full(len(names), np.nan),
        {**common, "long_name": "probability that the machine, within its tolerances, fails the criterion"},
    )
    out["criterion_failure_probability_interval"] = xr.Variable(
        ("criterion", "bound"),
        np.array([clopper_pearson(int(f), n, confidence) for f in fails]).reshape(len(names), 2),
        {**common, "long_name": f"interval of criterion_failure_probability: {how}"},
    )
    return out


def described_reliability(ds: xr.Dataset) -> list[str]:
    """Lines that report a tolerance study's probabilities (empty when the dataset has none, or one per
    candidate: a robust optimisation's, reported with its optimum)."""
    if "probability_meets_criteria" not in ds or ds["probability_meets_criteria"].ndim:
        return []
    p = float(ds["probability_meets_criteria"].values)
    lo, hi = (float(v) for v in ds["probability_meets_criteria_interval"].values)
    conf = float(ds["probability_meets_criteria"].attrs.get("confidence", CONFIDENCE))
    lines = [f"meets every criterion: {p:.1%} of the cases ({conf:.0%} interval {lo:.1%} to {hi:.1%})"]
    fails = ds["criterion_failure_probability"]
    for name, f in zip(fails["criterion"].values, fails.values, strict=True):
        lines.append(f"  fails {name}: {float(f):.1%}")
    return lines


def tolerance_names(tolerances: Mapping[str, Tolerance] | None) -> list[str]:
    """The paths a tolerance block names, in order."""
    return list(tolerances or {})
