"""Experiment designs: which parameter values each case of a study takes."""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import cast

import numpy as np


@dataclass
class Design:
    """The cases of a study.

    Attributes:
        kind: "grid" (full factorial: one dataset dimension per parameter) or "sampled" (a ``case``
            dimension with each parameter as a coordinate along it).
        names: parameter names, in order (for a grid, the order of the dataset dimensions; the last
            varies fastest, as in ``numpy.ndindex``).
        values: per parameter, an array of shape (n_cases,) with the value each case takes (float, or
            str for a categorical parameter such as ``isolator_type``).
        levels: for a grid, per parameter, the array of its distinct levels in order; empty otherwise.
        paths: per parameter, the path into the scene it sets.
        units: per parameter, its SI unit ("" for categorical / dimensionless).
        display_units: per numeric parameter, the unit it was written in (``"g"``, ``"%"``, ``"kN/m"``;
            its SI unit when written as plain numbers): what figures show it in.
        scales: per numeric parameter, "linear" or "log" (the scale its range was drawn on).
    """

    kind: str
    names: list[str]
    values: dict[str, np.ndarray]
    levels: dict[str, np.ndarray]
    paths: dict[str, str]
    units: dict[str, str]
    display_units: dict[str, str] = field(default_factory=dict)
    scales: dict[str, str] = field(default_factory=dict)

    @property
    def n_cases(self) -> int:
        if not self.names:
            return 1
        return int(len(self.values[self.names[0]]))

    @property
    def shape(self) -> tuple[int, ...]:
        """Grid shape (one entry per parameter) or (n_cases,) for a sampled design."""
        if self.kind == "grid":
            return tuple(len(self.levels[n]) for n in self.names)
        return (self.n_cases,)


GRID_LIMIT = 10_000_000
"""Most cases a design may hold."""
MAX_REPLICATES = 1000
"""Most independent replicates of a saltelli design."""


@dataclass(frozen=True)
class Factor:
    """One varied parameter as a design sees it, in SI.

    Either ``levels`` (explicit values: floats, or strings for a categorical parameter) or a continuous
    range ``low`` .. ``high`` on a ``linear`` or ``log`` scale, with ``num`` levels when used in a grid.

    Attributes:
        name: the parameter's name (a dataset dimension or coordinate).
        path: the path into the scene it sets.
        unit: its SI unit ("" for categorical / dimensionless).
        levels: explicit values, or None for a range.
        low, high: range ends (SI), ``high`` may be below ``low``.
        scale: "linear" or "log" (log needs both ends of one sign and non-zero).
        num: number of grid levels spanning the range (ends included).
        display_unit: the unit the values were written in (``"g"``, ``"%"``; "" for SI), for figures.
    """

    name: str
    path: str
    unit: str = ""
    levels: np.ndarray | None = None
    low: float | None = None
    high: float | None = None
    scale: str = "linear"
    num: int | None = None
    display_unit: str = ""

    def __post_init__(self) -> None:
        if self.levels is not None:
            lv = np.asarray(self.levels)
            if lv.ndim != 1 or lv.size == 0:
                raise ValueError(f"{self.name}: levels must be a non-empty list")
            if lv.dtype.kind not in "US":
                lv = lv.astype(np.float64)
                if not np.all(np.isfinite(lv)):
                    raise ValueError(f"{self.name}: levels must be finite")
            object.__setattr__(self, "levels", lv)
            return
        if self.low is None or self.high is None:
            raise ValueError(f"{self.name}: give levels or a range (low, high)")
        if not (np.isfinite(self.low) and np.isfinite(self.high)):
            raise ValueError(f"{self.name}: range ends must be finite")
        if self.scale not in ("linear", "log"):
            raise ValueError(f"{self.name}: scale must be linear or log, got {self.scale!r}")
        if self.scale == "log" and not (self.low * self.high > 0.0):
            raise ValueError(f"{self.name}: a log range needs both ends non-zero and of one sign")
        if self.num is not None and (self.num < 1 or (self.num == 1 and self.low != self.high)):
            raise ValueError(f"{self.name}: a range needs num >= 2 levels (or low == high)")

    @property
    def categorical(self) -> bool:
        return self.levels is not None and self.levels.dtype.kind in "US"

    @property
    def bounds(self) -> tuple[float, float]:
        """(low, high) of a range, SI: set whenever ``levels`` is None (``__post_init__`` refuses a factor
        with neither)."""
        return cast(float, self.low), cast(float, self.high)

    def grid_levels(self) -> np.ndarray:
        """The levels a full-factorial grid takes (explicit levels, or ``num`` points over the range)."""
        if self.levels is not None:
            return self.levels
        if self.num is None:
            raise ValueError(f"{self.name}: a grid needs values or a range with num")
        low, high = self.bounds
        if self.num == 1:
            return np.array([float(low)])
        if self.scale == "log":
            return np.geomspace(low, high, self.num)
        return np.linspace(low, high, self.num)

    def from_unit(self, u: np.ndarray | float) -> np.ndarray:
        """Map samples ``u`` in [0, 1) to values: through the range (log space for a log scale), or to
        the level of index ``floor(u * n_levels)`` for explicit levels."""
        u = np.asarray(u, dtype=np.float64)
        if self.levels is not None:
            n = len(self.levels)
            return self.levels[np.clip(np.floor(u * n).astype(np.intp), 0, n - 1)]
        low, high = self.bounds
        if self.scale == "log":
            sign = np.sign(low)
            lo, hi = np.log(abs(low)), np.log(abs(high))
            return sign * np.exp(lo + u * (hi - lo))
        return low + u * (high - low)


def _meta(factors: list[Factor]) -> tuple[list[str], dict[str, str], dict[str, str]]:
    names = [f.name for f in factors]
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise ValueError(f"parameters: names repeat: {', '.join(dup)}")
    return names, {f.name: f.path for f in factors}, {f.name: f.unit for f in factors}


def _shown(design: Design, factors: list[Factor]) -> Design:
    """``design`` with the display unit and scale of each numeric factor filled in."""
    for f in factors:
        if not f.categorical:
            design.display_units[f.name] = f.display_unit or f.unit
            design.scales[f.name] = f.scale
    return design


def grid(factors: list[Factor]) -> Design:
    """Full factorial design: every combination of levels; the last factor varies fastest."""
    names, paths, units = _meta(factors)
    levels = {f.name: f.grid_levels() for f in factors}
    for name, lv in levels.items():
        if len(np.unique(lv)) != len(lv):
            raise ValueError(f"{name}: grid levels repeat: {lv.tolist()}")
    shape = tuple(len(levels[n]) for n in names)
    n_cases = int(np.prod(shape, dtype=np.int64)) if shape else 1
    if n_cases > GRID_LIMIT:
        raise ValueError(f"design: the grid {shape} has {n_cases} cases, more than {GRID_LIMIT}")
    index = np.indices(shape).reshape(len(shape), -1) if shape else np.zeros((0, 1), dtype=np.intp)
    values = {n: levels[n][index[i]] for i, n in enumerate(names)}
    return _shown(Design("grid", names, values, levels, paths, units), factors)


def _sampled(factors: list[Factor], u: np.ndarray) -> Design:
    names, paths, units = _meta(factors)
    values = {f.name: f.from_unit(u[:, i]) for i, f in enumerate(factors)}
    return _shown(Design("sampled", names, values, {}, paths, units), factors)


def _check_n(n: int) -> int:
    if isinstance(n, bool) or int(n) != n or not 1 <= n <= GRID_LIMIT:
        raise ValueError(f"design.samples: must be an integer from 1 to {GRID_LIMIT}, got {n!r}")
    return int(n)


def latin_hypercube(factors: list[Factor], n: int, seed: int = 0) -> Design:
    """Latin hypercube sample of ``n`` cases: each factor's [0, 1) is cut into ``n`` strata and each
    stratum is hit exactly once (random position within it). Same ``seed``, same cases."""
    n = _check_n(n)
    if not factors:
        return _sampled(factors, np.zeros((n, 0)))
    return _sampled(factors, latin_hypercube_unit(len(factors), n, seed))


def latin_hypercube_unit(d: int, n: int, seed: int) -> np.ndarray:
    """``n`` points of a ``d``-dimensional Latin hypercube in [0, 1)^d, shape (n, d): the points of
    ``scipy.stats.qmc.LatinHypercube(d, rng=numpy.random.default_rng(seed)).random(n)`` (scrambled,
    strength 1, no optimisation; equal to them bit for bit, tested), drawn the same way: the seed's
    generator spawns a child, which draws each point's place in its stratum, then shuffles each
    dimension's strata. Written here because every Dask worker that runs a chunk rebuilds its study's
    design, and importing ``scipy.stats`` for it cost a worker's first chunk 0.4 s of CPU."""
    (rng,) = np.random.default_rng(seed).spawn(1)
    place = rng.uniform(size=(n, d))
    strata = np.tile(np.arange(1, n + 1), (d, 1))
    for i in range(d):
        rng.shuffle(strata[i, :])
    return (strata.T - place) / n


def sobol(factors: list[Factor], n: int, seed: int = 0) -> Design:
    """Scrambled Sobol' sequence of ``n`` cases (best balanced when ``n`` is a power of 2)."""
    n = _check_n(n)
    if not factors:
        return _sampled(factors, np.zeros((n, 0)))
    from scipy.stats import qmc

    engine = qmc.Sobol(d=len(factors), scramble=True, rng=np.random.default_rng(seed))
    if n & (n - 1) == 0:
        u = engine.random_base2(int(np.log2(n)))
    else:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=".*balance properties of Sobol.*", category=UserWarning)
            u = engine.random(n)
    return _sampled(factors, u)


def saltelli_cases(n: int, d: int, second_order: bool = False, replicates: int = 1) -> int:
    """Cases of a Saltelli design of base sample ``n`` over ``d`` parameters: ``n (d + 2)``, or
    ``n (2d + 2)`` with second-order indices, per replicate; ``replicates`` times that in all."""
    return int(replicates) * int(n) * ((2 * int(d) + 2) if second_order else (int(d) + 2))


def saltelli(
    factors: list[Factor], n: int, seed: int = 0, second_order: bool = False, replicates: int = 1
) -> Design:
    """Saltelli's scheme on a scrambled Sobol' sequence (``SALib.sample.sobol``), for Sobol' indices.

    ``n`` is the base sample N (best a power of 2); the design has :func:`saltelli_cases` cases, laid out
    as N consecutive blocks of ``d + 2`` (``2d + 2`` with ``second_order``): the row of matrix A, the d
    rows of A with column i taken from B, (second order: the d rows of B with column i from A), then the
    row of B. :func:`SALib.analyze.sobol.analyze` reads the outputs in that order. Every factor must be a
    range (``low`` .. ``high``; a log scale is sampled uniformly in log space, as :meth:`Factor.from_unit`
    does). Same ``seed``, same cases.

    With ``replicates`` R > 1 the design is R such designs of N base samples one after the other (R N
    blocks in all), each on its own independently scrambled Sobol' sequence (seeds spawned from ``seed``):
    independent estimates whose spread gives the indices' intervals
    (:func:`isolab.studies.answers.sensitivity.replicate_intervals`). R = 1 is the single design above,
    case for case.
    """
    from SALib.sample import sobol as salib_sobol

    n = _check_n(n)
    if not factors:
        raise ValueError("parameters: a saltelli design needs at least one parameter with a range")
    for f in factors:
        if f.levels is not None:
            kind = "categorical" if f.categorical else "a list of values"
            raise ValueError(
                f"{f.name}: a saltelli design varies ranges only and this parameter is {kind}; "
                "give it a range (start, stop)"
            )
    if isinstance(replicates, bool) or int(replicates) != replicates or not 1 <= replicates <= MAX_REPLICATES:
        raise ValueError(
            f"design.replicates: must be an integer from 1 to {MAX_REPLICATES}, got {replicates!r}"
        )
    replicates = int(replicates)
    total = saltelli_cases(n, len(factors), second_order, replicates)
    if total > GRID_LIMIT:
        times = f" in {replicates} replicates" if replicates > 1 else ""
        raise ValueError(
            f"design.samples: {n} base samples over {len(factors)} parameters{times} make {total} cases, "
            f"more than {GRID_LIMIT}"
        )
    problem = {
        "num_vars": len(factors),
        "names": [f.name for f in factors],
        "bounds": [[0.0, 1.0]] * len(factors),
    }
    if replicates == 1:
        rngs = [np.random.default_rng(seed)]
    else:
        rngs = [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(replicates)]
    parts = []
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*balance properties of Sobol.*", category=UserWarning)
        warnings.filterwarnings("ignore", category=DeprecationWarning)
        for rng in rngs:
            parts.append(
                salib_sobol.sample(problem, n, calc_second_order=bool(second_order), scramble=True, seed=rng)
            )
    u = parts[0] if replicates == 1 else np.concatenate(parts)
    return _sampled(factors, np.clip(u, 0.0, np.nextafter(1.0, 0.0)))


def random(factors: list[Factor], n: int, seed: int = 0) -> Design:
    """Independent uniform samples of ``n`` cases."""
    n = _check_n(n)
    return _sampled(factors, np.random.default_rng(seed).random((n, len(factors))))


def explicit(factors: list[Factor], cases: Sequence[Mapping[str, object]]) -> Design:
    """The cases listed one by one: each a mapping of every factor's name to its value (SI, or a level
    name for a categorical factor)."""
    names, paths, units = _meta(factors)
    if not cases:
        raise ValueError("design.cases: give at least one case")
    for i, case in enumerate(cases):
        missing = [n for n in names if n not in case]
        extra = [k for k in case if k not in paths]
        if missing or extra:
            problems = [f"missing {', '.join(missing)}"] if missing else []
            if extra:
                problems.append(f"unknown {', '.join(map(str, extra))} (parameters: {', '.join(names)})")
            raise ValueError(f"design.cases[{i}]: " + "; ".join(problems))
    values = {}
    for f in factors:
        col = [case[f.name] for case in cases]
        levels = f.levels
        if levels is not None and f.categorical:  # a categorical factor has levels
            bad = [i for i, v in enumerate(col) if v not in set(levels.tolist())]
            if bad:
                raise ValueError(
                    f"design.cases[{bad[0]}].{f.name}: {col[bad[0]]!r} is not one of {levels.tolist()}"
                )
            values[f.name] = np.asarray(col)
        else:
            try:
                arr = np.asarray(col, dtype=np.float64)
            except (TypeError, ValueError):
                raise ValueError(f"design.cases: {f.name} must be numbers, got {col!r}") from None
            if not np.all(np.isfinite(arr)):
                raise ValueError(f"design.cases: {f.name} must be finite")
            values[f.name] = arr
    return _shown(Design("sampled", names, values, {}, paths, units), factors)
