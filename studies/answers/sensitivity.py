"""Global sensitivity of a study's output to its varied parameters, by SALib's estimators.

Which estimator runs follows from how the study's cases were drawn (the design summary in the dataset's
attributes):

* ``saltelli``: Sobol' variance-based indices, ``SALib.analyze.sobol`` (Saltelli 2010 / Jansen
  estimators): first order S1 (the share of the output's variance a parameter explains alone) and total
  order ST (its share with all its interactions), and with ``second_order`` the pairwise S2; 95 %
  confidence intervals from the spread of the design's independent replicates (``replicates`` in the
  design summary: :func:`replicate_intervals`), or, for a design of one replicate, a bootstrap over its
  base samples (:func:`sobol_estimates`).
* ``lhs``, ``sobol``, ``random`` (any sample of independent inputs) and ``grid`` (a full factorial):
  ``SALib.analyze.delta`` from the given data (Plischke, Borgonovo and Smith 2013): Borgonovo's
  moment-independent delta (how far the output's distribution moves, on average, when a parameter is
  fixed; 0 none, 1 at most) and the first-order Sobol' index S1 from the same data, 95 % bootstrap
  confidence intervals. Each input enters as its rank (its empirical distribution): the estimator
  conditions on rank classes, so the indices do not change, and SALib's balanced resampling bins then
  hold equal counts whatever the parameter's scale (log ranges). A grid's categorical parameter (an
  isolator preset) enters by its level number: delta and S1 need classes, not an order. The rows are
  shuffled (fixed seed) first, so that a class cut inside a grid level is a random part of it.

Cases whose ``status`` is not ok, and ok cases with no value of the output, are left out and counted.
A Saltelli design is blocks of D + 2 cases (2D + 2 with second order) built from one base point each:
a block with any case left out is dropped whole (the estimator needs every case of a block), and the
answer says how many ok cases went with their block.

:func:`sensitivity` analyses a dataset; :func:`stored_sensitivity` answers for a study in a
:class:`~isolab.studies.results.store.Store`, cached as JSON beside the study's dataset, keyed by the output
and
the dataset file's modification time and size.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
import threading
import warnings
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from isolab.engine.results import OK
from isolab.studies.quantities import case_dims, output_values

if TYPE_CHECKING:  # xarray and scipy load when a sensitivity is computed: the service starts sooner
    import xarray as xr

CONF_LEVEL = 0.95
"""Confidence level of every interval."""
NUM_RESAMPLES = 1000
"""Bootstrap resamples behind each confidence interval of the Sobol' estimator (fewer for a large study:
:data:`RESAMPLE_BUDGET`)."""
MIN_RESAMPLES = 200
"""Fewest bootstrap resamples of the Sobol' estimator, whatever the study's size."""
RESAMPLE_BUDGET = 4_000_000
"""Most base samples x resamples of the Sobol' estimator (its bootstrap holds arrays of that size per
parameter): a study of more than 4,000 base samples gets fewer resamples, at least :data:`MIN_RESAMPLES`."""
SOBOL_INTERVAL = (
    "bootstrap over the base samples, three intervals joined: percentile (2.5 % to 97.5 % quantile of the "
    "resampled indices), normal (the estimate +-1.96 of their standard deviation) and bootstrap-t "
    "(studentized by each resample's linearised standard error); from the lowest lower end to the highest "
    "upper end; conf is the half-width of the smallest interval about the estimate that holds it"
)
"""How the Sobol' indices' 95 % intervals are formed (:func:`sobol_estimates`)."""
REPLICATE_INTERVAL = (
    "t interval over {r} independent replicates of the design: the estimate (from all of them) +- the "
    "t quantile with {dof} degrees of freedom times the standard error read from the replicates' spread "
    "(each index linearised per base sample and summed per replicate)"
)
"""How the Sobol' indices' 95 % intervals are formed from a design of independent replicates
(:func:`replicate_intervals`); ``{r}`` and ``{dof}`` are filled in."""
ONE_REPLICATE_NOTE = (
    "intervals from one design: a bootstrap over its base samples, which can be too narrow for indices "
    "near zero (outputs with jumps, the Sobol' sequence's own error); give design.replicates (8, say) for "
    "intervals from independent replicates"
)
"""Note of a Sobol' answer whose design has a single replicate."""
DELTA_INTERVAL = "normal approximation: the estimate +-1.96 standard deviations of the bootstrap resamples"
"""How the delta estimator's 95 % intervals are formed (SALib's own)."""
DELTA_NUM_RESAMPLES = 50
"""Bootstrap resamples behind each confidence interval of the delta estimator (each one costs a kernel
density per class: the delta estimator's time is proportional to this)."""
SEED = 20260101
"""Seed of the bootstrap resampling and the row shuffle: the same study gives the same answer."""
DELTA_RESAMPLE_CAP = 2000
"""Most cases each of the delta estimator's resamples draws (SALib's ``y_resamples``): its kernel densities
cost about the square of it; at 2,000 a 10,000-case study of 4 parameters is analysed in seconds, not
minutes, and the confidence intervals are those of 2,000-case estimates."""
MIN_SALTELLI_BLOCKS = 2
"""Fewest complete Saltelli blocks the Sobol' estimator is run on."""
CACHE_VERSION = 3
"""Part of the cache key: a change of the analysis invalidates what is cached."""

_SALIB_LOCK = threading.Lock()

METHODS = {
    "sobol": "Sobol' indices from Saltelli's scheme (SALib.analyze.sobol): first order S1, total order ST",
    "delta": "Borgonovo's delta and first-order Sobol' index from the given data (SALib.analyze.delta)",
}
INDEX_MEANINGS = {
    "S1": "first-order Sobol' index: share of the output variance the parameter explains alone",
    "ST": "total-order Sobol' index: share of the output variance the parameter explains with all its "
    "interactions",
    "delta": "Borgonovo's moment-independent delta: mean shift of the output's distribution when the "
    "parameter is fixed (0 none, 1 at most)",
}


@dataclass
class SensitivityResult:
    """Sensitivity indices of one output of a study.

    Attributes:
        method: ``"sobol"`` (Saltelli design) or ``"delta"`` (any other sample or a grid).
        method_name: what the method is, in words (:data:`METHODS`).
        design: the study's design type (``saltelli``, ``lhs``, ``grid``...).
        output: the quantity analysed (:func:`isolab.studies.quantities.output_values` spec).
        long_name, unit: the output's long name and SI unit.
        parameters: parameter names, in design order.
        parameter_long_names, parameter_units: per parameter, its long name and SI unit.
        indices: index name (``S1``, ``ST``, ``delta``) -> one value per parameter (None: not estimable).
        conf: index name -> half-width of its 95 % confidence interval, per parameter (an interval about
            the index, holding ``intervals`` where those are given).
        intervals: Sobol' indices: index name -> (lower, upper) of its 95 % interval per parameter, as
            :data:`SOBOL_INTERVAL` says; None for the delta estimator.
        interval_method: how the intervals are formed, in words.
        replicates: independent replicates of a saltelli design the intervals were read from (1: one
            design, bootstrap intervals).
        second_order: ``{"pairs": [[a, b]...], "S2": [...], "S2_conf": [...]}`` for a saltelli design with
            second order, else None.
        n_cases: cases the indices were estimated from.
        n_total: cases of the study.
        n_excluded: cases left out because their status is not ok or they have no value of the output.
        n_dropped: ok cases left out with a Saltelli block that lost a case (0 for other methods).
        notes: remarks (cases left out, estimator warnings).
    """

    method: str
    method_name: str
    design: str
    output: str
    long_name: str
    unit: str
    parameters: list[str]
    parameter_long_names: list[str]
    parameter_units: list[str]
    indices: dict[str, list[float | None]]
    conf: dict[str, list[float | None]]
    n_cases: int
    n_total: int
    n_excluded: int
    n_dropped: int = 0
    second_order: dict[str, Any] | None = None
    notes: list[str] = field(default_factory=list)
    conf_level: float = CONF_LEVEL
    intervals: dict[str, list[list[float | None]]] | None = None
    interval_method: str = ""
    replicates: int = 1

    def to_dict(self) -> dict[str, Any]:
        """JSON-able dict (missing values as None, never NaN), with ``index_meanings``."""
        out = asdict(self)
        out["index_meanings"] = {k: INDEX_MEANINGS[k] for k in self.indices if k in INDEX_MEANINGS}
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> SensitivityResult:
        """The result :meth:`to_dict` wrote."""
        fields = {k: v for k, v in data.items() if k in cls.__dataclass_fields__}
        return cls(**fields)

    def ranking(self, index: str | None = None) -> list[str]:
        """Parameter names from the most to the least influential by ``index`` (default: ST for Sobol',
        delta otherwise); parameters without a value last."""
        key = index or ("ST" if "ST" in self.indices else "delta")
        values = self.indices[key]

        def strength(i: int) -> float:
            v = values[i]
            return -math.inf if v is None else v

        return [self.parameters[i] for i in sorted(range(len(values)), key=strength, reverse=True)]


def _plain(values: Any) -> list[float | None]:
    """Floats with NaN/inf as None (JSON has no NaN)."""
    return [float(v) if np.isfinite(v) else None for v in np.asarray(values, dtype=np.float64).reshape(-1)]


def design_info(ds: xr.Dataset) -> dict[str, Any]:
    """The design summary of a study dataset (its ``design`` attribute, JSON in a netCDF file)."""
    raw = ds.attrs.get("design")
    if isinstance(raw, str):
        try:
            raw = json.loads(raw)
        except json.JSONDecodeError:
            raw = None
    if not isinstance(raw, dict):
        raise ValueError("the dataset has no design summary (attribute 'design'); it is not a study dataset")
    return raw


@contextlib.contextmanager
def _quiet_salib(seed: int) -> Iterator[None]:
    """Run SALib code with its warnings caught and numpy's global random state restored afterwards
    (SALib's delta seeds and draws from it and changes the warnings' format). One analysis at a time
    per process: the global state is shared by threads."""
    with _SALIB_LOCK:
        state = np.random.get_state()  # noqa: NPY002 (SALib's delta draws from the legacy global state)
        fmt = warnings.formatwarning
        try:
            with warnings.catch_warnings(record=True):
                warnings.simplefilter("ignore")
                np.random.seed(seed)  # noqa: NPY002
                yield
        finally:
            warnings.formatwarning = fmt
            np.random.set_state(state)  # noqa: NPY002


def _parameter_meta(ds: xr.Dataset, names: list[str]) -> tuple[list[str], list[str]]:
    long_names, units = [], []
    for n in names:
        attrs = ds[n].attrs if n in ds.variables else {}
        long_names.append(str(attrs.get("long_name", n)))
        unit = str(attrs.get("units", ""))
        units.append("" if unit == "1" else unit)
    return long_names, units


def sensitivity(ds: xr.Dataset, output: str) -> SensitivityResult:
    """Sensitivity indices of ``output`` over a study dataset's varied parameters (see the module
    docstring for which method each design gets).

    Args:
        ds: a study dataset (:func:`isolab.studies.results.dataset.to_dataset`), loaded.
        output: a quantity of :func:`isolab.studies.quantities.output_values`, e.g.
            ``peak_point_displacement.tool.z`` or ``settling_time``.

    Raises:
        ValueError: an unknown output (naming it and the choices), a study without varied parameters or a
            list design, too few usable cases, or an output that does not vary.
    """
    info = design_info(ds)
    names = [str(n) for n in info.get("names", [])]
    kind = str(info.get("kind", ""))
    design = str(info.get("type", kind))
    y_da = output_values(ds, output)
    if not names:
        raise ValueError("the study varies no parameter: there is nothing to rank")
    if design == "list":
        raise ValueError(
            "a list design's cases are chosen by hand: no sensitivity estimator applies to them; "
            "run an lhs, sobol, saltelli or grid design"
        )
    dims = case_dims(ds)
    y = np.asarray(y_da.transpose(*dims).values, dtype=np.float64).reshape(-1)
    status = np.asarray(ds["status"].transpose(*dims).values).reshape(-1)
    bad = (status != OK) | ~np.isfinite(y)
    notes = _excluded_note(bad, int(((status == OK) & ~np.isfinite(y)).sum()))
    long_name = str(y_da.attrs.get("long_name", output))
    unit = str(y_da.attrs.get("units", ""))
    unit = "" if unit == "1" else unit
    p_long, p_units = _parameter_meta(ds, names)
    common = dict(
        design=design,
        output=str(output),
        long_name=long_name,
        unit=unit,
        parameters=names,
        parameter_long_names=p_long,
        parameter_units=p_units,
        n_total=int(y.size),
    )
    if design == "saltelli":
        replicates = int(info.get("replicates") or 1)  # a study stored before replicates existed: one
        return _sobol(y, bad, names, bool(info.get("second_order", False)), replicates, output, notes, common)
    return _delta(ds, dims, y, bad, names, kind, output, notes, common)


def _excluded_note(bad: np.ndarray, n_nan_ok: int) -> list[str]:
    n_bad = int(bad.sum())
    if not n_bad:
        return []
    note = f"{n_bad} of {bad.size} cases left out"
    if n_nan_ok:
        note += f" ({n_bad - n_nan_ok} not ok, {n_nan_ok} ok without a value of the output)"
    else:
        note += " (status not ok)"
    return [note]


def _check_varies(y: np.ndarray, output: str) -> None:
    if y.size and float(np.ptp(y)) == 0.0:
        raise ValueError(
            f"{output!r}: the output is {y[0]:.6g} in every usable case; it depends on none of the "
            "varied parameters, so there is nothing to rank"
        )


def sobol_resamples(n_base: int) -> int:
    """Bootstrap resamples of the Sobol' estimator for ``n_base`` base samples: :data:`NUM_RESAMPLES`,
    fewer when ``n_base`` x resamples exceeds :data:`RESAMPLE_BUDGET`, never under :data:`MIN_RESAMPLES`."""
    return int(max(MIN_RESAMPLES, min(NUM_RESAMPLES, RESAMPLE_BUDGET // max(int(n_base), 1))))


def studentized_intervals(
    y: np.ndarray, d: int, resamples: int, second_order: bool = False
) -> dict[str, np.ndarray]:
    """Bootstrap-t 95 % intervals ((d, 2): lower, upper) of S1 (Saltelli 2010) and ST (Jansen) from the
    outputs ``y`` of a Saltelli design over ``d`` parameters (blocks of ``d + 2``, ``2d + 2`` with
    ``second_order``: A, A with column j from B..., B)).

    Each index is a ratio of block means, linearised per block into its influence z_i (the standard error
    is sd(z) / sqrt(N)); each of ``resamples`` draws of N blocks with replacement (seed :data:`SEED`) gives
    t = (index* - index) / se*, and the interval is index - t_(97.5 %) se .. index - t_(2.5 %) se. Where a
    few blocks carry most of an index (a total index near zero whose differences are rare jumps), the
    resamples that miss them have a small se*, so the upper end reaches further than a percentile
    interval's.
    """
    y = np.asarray(y, dtype=np.float64).reshape(-1)
    block = (2 * d + 2) if second_order else (d + 2)
    n = y.size // block
    rows = (y - y.mean()) / (y.std() or 1.0)
    table = rows.reshape(n, block)
    a, ab, b = table[:, 0], table[:, 1 : d + 1], table[:, -1]
    pick = np.random.default_rng(SEED).integers(n, size=(int(resamples), n))
    tail = 100.0 * (1.0 - CONF_LEVEL) / 2
    out: dict[str, np.ndarray] = {"S1": np.full((d, 2), np.nan), "ST": np.full((d, 2), np.nan)}

    def spread(aa: np.ndarray, bb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The variance of A and B together (keepdims) and each block's share of it: the same for every
        index, so made once for the sample and once for its resamples."""
        both = np.concatenate([aa, bb], axis=-1)
        mu, var = both.mean(axis=-1, keepdims=True), both.var(axis=-1, keepdims=True)
        return var, 0.5 * ((aa - mu) ** 2 + (bb - mu) ** 2)

    def ratio(num: np.ndarray, var: np.ndarray, share: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        with np.errstate(divide="ignore", invalid="ignore"):
            index = num.mean(axis=-1, keepdims=True) / var
            influence = (num - index * share) / var
        return index[..., 0], influence.std(axis=-1, ddof=1) / math.sqrt(n)

    var, share = spread(a, b)
    var_star, share_star = spread(a[pick], b[pick])
    for j in range(d):
        for k, num in (("S1", b * (ab[:, j] - a)), ("ST", 0.5 * (a - ab[:, j]) ** 2)):
            index, se = ratio(num, var, share)
            star, se_star = ratio(num[pick], var_star, share_star)
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (star - index) / se_star
            t = t[np.isfinite(t)]
            if t.size < 2 or not (np.isfinite(se) and se > 0):
                continue
            t_lo, t_hi = np.percentile(t, [tail, 100.0 - tail])
            out[k][j] = (index - t_hi * se, index - t_lo * se)
    return out


def replicate_intervals(
    y: np.ndarray, d: int, replicate: np.ndarray, second_order: bool = False
) -> dict[str, np.ndarray]:
    """S1 (Saltelli 2010) and ST (Jansen) of the outputs ``y`` of a Saltelli design over ``d`` parameters
    made of independent replicates (blocks of ``d + 2`` cases, ``2d + 2`` with ``second_order``;
    ``replicate`` gives each block's replicate), with their 95 % t intervals.

    Each index is estimated from every block together, as ``SALib.analyze.sobol`` would from the joined
    outputs: a ratio of block means, mean(num) / var. Linearised, its error is the mean over blocks of
    the influence z = (num - index * share) / var (share: the block's part of the variance). The R
    replicates are independent draws of the design (independently scrambled Sobol' sequences), so the sums
    T_r of z over each replicate are independent whatever the sequence's own error and however rare the
    output's jumps; the standard error is sqrt(R / (R - 1) sum T_r^2) / N_blocks (the random-group
    estimator; sum T_r = 0) and the interval the index +- t_(R-1, 97.5 %) se.

    Returns:
        ``S1``, ``ST`` (d,), ``S1_conf``, ``ST_conf`` (d,): the half-widths, and ``S1_interval``,
        ``ST_interval`` ((d, 2): lower, upper), all of the standardised output (indices are ratios: no
        unit); ``replicates``: the number of replicates with a block.

    Raises:
        ValueError: fewer than 2 replicates, or ``replicate`` not one label per block.
    """
    from scipy.stats import t as student

    y = np.asarray(y, dtype=np.float64).reshape(-1)
    block = (2 * d + 2) if second_order else (d + 2)
    n = y.size // block
    replicate = np.asarray(replicate).reshape(-1)
    if replicate.size != n:
        raise ValueError(f"replicate: one label per block expected ({n}), got {replicate.size}")
    labels, group = np.unique(replicate, return_inverse=True)
    r = labels.size
    if r < 2:
        raise ValueError(f"replicate intervals need at least 2 replicates, got {r}")
    table = ((y - y.mean()) / (y.std() or 1.0)).reshape(n, block)
    a, ab, b = table[:, 0], table[:, 1 : d + 1], table[:, -1]
    mu = 0.5 * (a.mean() + b.mean())
    share = 0.5 * ((a - mu) ** 2 + (b - mu) ** 2)
    var = share.mean()
    q = float(student.ppf(0.5 + CONF_LEVEL / 2, r - 1))
    out: dict[str, np.ndarray] = {"replicates": np.asarray(r)}
    for k, num in (("S1", b[:, None] * (ab - a[:, None])), ("ST", 0.5 * (a[:, None] - ab) ** 2)):
        with np.errstate(divide="ignore", invalid="ignore"):
            index = num.mean(axis=0) / var
            z = (num - index * share[:, None]) / var
        sums = np.zeros((r, d))
        np.add.at(sums, group, z)
        conf = q * np.sqrt(r / (r - 1) * np.sum(sums**2, axis=0)) / n
        out[k], out[f"{k}_conf"] = index, conf
        out[f"{k}_interval"] = np.column_stack([index - conf, index + conf])
    return out


def sobol_estimates(
    y: np.ndarray,
    d: int,
    second_order: bool = False,
    resamples: int | None = None,
    replicate: np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """Sobol' indices of ``y``, the outputs of a Saltelli design over ``d`` parameters in its order
    (blocks of ``d + 2`` cases, ``2d + 2`` with ``second_order``), by ``SALib.analyze.sobol``: S1
    (Saltelli 2010) and ST (Jansen), with ``S1_conf`` and ``ST_conf`` the half-widths of their 95 %
    intervals formed as :data:`SOBOL_INTERVAL` says, and ``S1_interval`` and ``ST_interval`` ((d, 2):
    lower, upper) the intervals themselves; with ``second_order``, S2 and S2_conf as SALib gives them
    (normal approximation). The bootstrap (``resamples``, default :func:`sobol_resamples`) is seeded by
    :data:`SEED`; the indices do not depend on it.

    With ``replicate`` (each block's replicate, at least 2 of them) the S1 and ST intervals are
    :func:`replicate_intervals`' t intervals instead, and ``replicates`` their count; the bootstrap then
    serves S2 alone (``resamples`` default :data:`MIN_RESAMPLES`).
    """
    from SALib.analyze import sobol as salib_sobol
    from scipy.stats import norm

    y = np.asarray(y, dtype=np.float64).reshape(-1)
    n_base = y.size // ((2 * d + 2) if second_order else (d + 2))
    problem = {"num_vars": d, "names": [f"x{i}" for i in range(d)], "bounds": [[0.0, 1.0]] * d}
    by_replicate = replicate is not None and np.unique(replicate).size >= 2
    if resamples is not None:
        count = int(resamples)
    else:
        count = MIN_RESAMPLES if by_replicate else sobol_resamples(n_base)
    with _quiet_salib(SEED):
        si = salib_sobol.analyze(
            problem,
            y,
            calc_second_order=second_order,
            num_resamples=count,
            conf_level=CONF_LEVEL,
            seed=SEED,
            keep_resamples=True,
        )
    out: dict[str, np.ndarray] = {}
    if second_order:
        out["S2"] = np.asarray(si["S2"], dtype=np.float64)
        out["S2_conf"] = np.asarray(si["S2_conf"], dtype=np.float64)
    if by_replicate and replicate is not None:
        spread = replicate_intervals(y, d, replicate, second_order)
        for k in ("S1", "ST"):  # SALib's estimates: the same ratios (to rounding) as the intervals'
            est = np.asarray(si[k], dtype=np.float64)
            out[k], out[f"{k}_conf"] = est, spread[f"{k}_conf"]
            out[f"{k}_interval"] = est[:, None] + np.column_stack([-spread[f"{k}_conf"], spread[f"{k}_conf"]])
        out["replicates"] = spread["replicates"]
        return out
    z = float(norm.ppf(0.5 + CONF_LEVEL / 2))
    tail = 100.0 * (1.0 - CONF_LEVEL) / 2
    studentized = studentized_intervals(y, d, count, second_order)
    for k in ("S1", "ST"):
        est = np.asarray(si[k], dtype=np.float64)
        boot = np.asarray(si[f"{k}_conf_all"], dtype=np.float64).reshape(-1, d)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # an index SALib could not resample: NaN
            sd = np.nanstd(boot, axis=0, ddof=1)
            q_lo, q_hi = np.nanpercentile(boot, [tail, 100.0 - tail], axis=0)
        t_lo, t_hi = studentized[k].T
        lower = np.fmin(np.minimum(est - z * sd, q_lo), t_lo)
        upper = np.fmax(np.maximum(est + z * sd, q_hi), t_hi)
        out[k] = est
        out[f"{k}_conf"] = np.maximum(est - lower, upper - est)
        out[f"{k}_interval"] = np.column_stack([lower, upper])
    return out


def _sobol(
    y: np.ndarray,
    bad: np.ndarray,
    names: list[str],
    second_order: bool,
    replicates: int,
    output: str,
    notes: list[str],
    common: dict,
) -> SensitivityResult:
    d = len(names)
    block = (2 * d + 2) if second_order else (d + 2)
    if y.size % (block * replicates):
        raise ValueError(
            f"the dataset has {y.size} cases, not a whole number of Saltelli blocks of {block} "
            f"({d} parameters{', second order' if second_order else ''}) in {replicates} equal replicates: "
            "it is not a complete saltelli design"
        )
    n_blocks = y.size // block
    keep = ~bad.reshape(n_blocks, block).any(axis=1)
    n_keep = int(keep.sum())
    n_excluded = int(bad.sum())
    n_dropped = (n_blocks - n_keep) * block - n_excluded
    if n_excluded:
        notes.append(
            f"{n_blocks - n_keep} of {n_blocks} Saltelli blocks dropped whole with them "
            f"({n_dropped} ok cases); indices from the {n_keep} complete blocks"
        )
    if n_keep < MIN_SALTELLI_BLOCKS:
        raise ValueError(
            f"{output!r}: only {n_keep} of {n_blocks} Saltelli blocks have every case ok with a value of the "
            f"output ({n_excluded} cases left out); Sobol' indices need at least {MIN_SALTELLI_BLOCKS}"
        )
    yk = y.reshape(n_blocks, block)[keep].reshape(-1)
    _check_varies(yk, output)
    replicate = np.repeat(np.arange(replicates), n_blocks // replicates)[keep]
    used = int(np.unique(replicate).size)
    if replicates > 1 and used < 2:
        notes.append(
            f"only {used} of {replicates} replicates have a complete block: intervals by the bootstrap over "
            "its base samples"
        )
    si = sobol_estimates(yk, d, second_order, replicate=replicate if used >= 2 else None)
    s2 = None
    if second_order:
        pairs = [(j, k) for j in range(d) for k in range(j + 1, d)]
        s2 = {
            "pairs": [[names[j], names[k]] for j, k in pairs],
            "S2": _plain([si["S2"][j, k] for j, k in pairs]),
            "S2_conf": _plain([si["S2_conf"][j, k] for j, k in pairs]),
        }
    if n_keep < 64:
        notes.append(f"only {n_keep} base samples: the confidence intervals are wide; raise design.samples")
    if "replicates" in si:
        n_rep = int(si["replicates"])
        method = REPLICATE_INTERVAL.format(r=n_rep, dof=n_rep - 1)
    else:
        n_rep, method = 1, SOBOL_INTERVAL
        if replicates == 1:
            notes.append(ONE_REPLICATE_NOTE)
    return SensitivityResult(
        method="sobol",
        method_name=METHODS["sobol"],
        indices={"S1": _plain(si["S1"]), "ST": _plain(si["ST"])},
        conf={"S1": _plain(si["S1_conf"]), "ST": _plain(si["ST_conf"])},
        intervals={k: [_plain(row) for row in si[f"{k}_interval"]] for k in ("S1", "ST")},
        interval_method=method,
        replicates=n_rep,
        n_cases=int(yk.size),
        n_excluded=n_excluded,
        n_dropped=int(n_dropped),
        second_order=s2,
        notes=notes,
        **common,
    )


def _encoded(values: np.ndarray) -> np.ndarray:
    """A parameter's values as numbers: numeric as they are, categorical as level numbers."""
    values = np.asarray(values).reshape(-1)
    if values.dtype.kind in "USO":
        _, codes = np.unique(values.astype(str), return_inverse=True)
        return codes.astype(np.float64)
    return values.astype(np.float64)


def _delta(
    ds: xr.Dataset,
    dims: tuple[str, ...],
    y: np.ndarray,
    bad: np.ndarray,
    names: list[str],
    kind: str,
    output: str,
    notes: list[str],
    common: dict,
) -> SensitivityResult:
    from SALib.analyze import delta as salib_delta
    from scipy.stats import rankdata

    columns = []
    for n in names:
        coord = ds[n]
        if kind == "grid":  # a grid dimension: broadcast its levels over the case dims
            coord = coord.broadcast_like(ds["status"]).transpose(*dims)
        columns.append(_encoded(coord.values))
    x = np.column_stack(columns)
    keep = ~bad
    n_keep = int(keep.sum())
    if n_keep < 20:
        raise ValueError(
            f"{output!r}: {n_keep} usable cases ({int(bad.sum())} left out); the delta estimator needs at "
            "least 20 (a few hundred for tight confidence intervals)"
        )
    xk, yk = x[keep], y[keep]
    _check_varies(yk, output)
    order = np.random.default_rng(SEED).permutation(n_keep)
    xk, yk = xk[order], yk[order]
    ranks = np.column_stack([rankdata(xk[:, i], method="average") / n_keep for i in range(len(names))])
    problem = {"num_vars": len(names), "names": [f"p{i}" for i in range(len(names))]}
    with _quiet_salib(SEED):
        si = salib_delta.analyze(
            problem,
            ranks,
            yk,
            num_resamples=DELTA_NUM_RESAMPLES,
            conf_level=CONF_LEVEL,
            seed=SEED,
            y_resamples=min(n_keep, DELTA_RESAMPLE_CAP),
        )
    for n, note in zip(names, si.get("notes", []) or [], strict=False):
        text = str(note).strip()
        if text and not text.startswith("Step:"):  # the 'step' mode is for inputs around 0: not ours
            notes.append(f"{n}: {text}")
    if kind == "grid":
        notes.append(
            "full factorial: delta and S1 from the grid points as given data (each level one sample of "
            "the parameter, levels equally likely)"
        )
    return SensitivityResult(
        method="delta",
        method_name=METHODS["delta"],
        indices={"delta": _plain(si["delta_raw"]), "S1": _plain(si["S1"])},
        conf={"delta": _plain(si["delta_raw_conf"]), "S1": _plain(si["S1_conf"])},
        interval_method=DELTA_INTERVAL,
        n_cases=n_keep,
        n_excluded=int(bad.sum()),
        notes=notes,
        **common,
    )


# ----------------------------------------------------------------------------------------------- cache
def cache_path(results_dir: Path, dataset_path: Path, output: str) -> Path:
    """Where the analysis of ``output`` of the dataset file ``dataset_path`` is cached under
    ``results_dir``: keyed by the output, the file's modification time and size, and
    :data:`CACHE_VERSION`, so a rewritten dataset is analysed anew."""
    st = dataset_path.stat()
    key = json.dumps([CACHE_VERSION, str(output), st.st_mtime_ns, st.st_size])
    digest = hashlib.sha256(key.encode()).hexdigest()[:24]
    return results_dir / f"sensitivity-{digest}.json"


def stored_sensitivity(store: Any, study_id: str, output: str) -> SensitivityResult:
    """The sensitivity of ``output`` of a stored study: read from the cache beside its dataset, else
    computed (:func:`sensitivity`) and cached.

    Raises:
        FileNotFoundError: the study has no dataset file.
        ValueError: as :func:`sensitivity`.
    """
    from isolab.studies.results.netcdf_locks import NETCDF_LOCK
    from isolab.studies.results.store import atomic_path

    path = Path(store.path(study_id))
    if not path.is_file():
        raise FileNotFoundError(f"study {study_id} has no dataset file")
    cached = cache_path(Path(store.results_dir(study_id)), path, output)
    if cached.is_file():
        with contextlib.suppress(OSError, ValueError, TypeError):
            return SensitivityResult.from_dict(json.loads(cached.read_text(encoding="utf-8")))
    import xarray as xr

    with NETCDF_LOCK, xr.open_dataset(path) as opened:
        ds = opened.load()
    result = sensitivity(ds, output)
    with atomic_path(cached) as tmp:
        tmp.write_text(json.dumps(result.to_dict(), allow_nan=False), encoding="utf-8")
    return result
