"""How far a calibration's answer can be trusted: sensor noise, goodness of fit and honest uncertainties.

- **sensor noise** (:func:`record_noise`): each channel's noise is stated by the user, or estimated from
  the record alone, without the model: the robust scatter of its second differences (median absolute
  deviation; a smooth signal sampled finely has second differences far below its noise, and the few
  samples at a stage's jerk do not move a median);
- **goodness of fit** (:func:`goodness_of_fit`): the chi-square of the residuals against that noise, per
  channel and in all, with the 95 % range a chi-square of its degrees of freedom falls in and a verdict in
  words. A misfit the noise does not explain (a model error) shows as a chi-square above the range;
- **inflation** (:func:`channel_inflation`): a channel whose misfit exceeds its noise, or whose residuals
  are correlated over more samples than its noise (and its filter) make them, carries less information
  than its samples say. Its variance is multiplied by ``max(1, chi2/dof)`` times the ratio of the
  residuals' correlation length to the noise's (``1 + 2 sum(rho_l)`` over the lags up to the first zero
  crossing of the autocorrelation ``rho``: Bretherton's effective number of samples ``N / (1 + 2 sum
  rho)``, which for an AR(1) series is ``N (1 - r1) / (1 + r1)``);
- **the engine's timing** (:func:`step_timing_error`): a stated model error of the time offset where
  acceleration channels are fitted: the engine resolves a stage's acceleration jump to within its step,
  so the offset carries an error of a step's uniform spread, ``dt / sqrt(12)``, in quadrature;
- **identifiability** (:func:`parameter_verdict`): 1-sigma uncertainties from the inflated Jacobian, and
  the parameters the measurement does not determine, with the reason.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

UNDETERMINED_WIDTH_FRACTION = 0.25
"""A parameter whose 1-sigma uncertainty exceeds this fraction of its bounds' width is not determined."""
UNDETERMINED_RELATIVE = 0.5
"""... or exceeds this fraction of its fitted value's magnitude."""
ZERO_COLUMN = 1e-9
"""A Jacobian column (per bounds' width, weighted by the noise) shorter than this fraction of the longest
is zero: the channels do not respond to the parameter."""
COLLINEAR = 1e-8
"""Singular values of the column-normalised Jacobian below this fraction of the largest: collinear."""
CHI_SQUARE_LEVEL = 0.95
"""Probability of the expected range of a chi-square of the fit's degrees of freedom."""
MAX_CORRELATION_LAGS = 2_000
"""Longest lag of the residuals' autocorrelation looked at, samples."""
MAD_TO_SIGMA = 1.4826
"""Standard deviation per median absolute deviation of a normal distribution."""
MAD_EFFICIENCY = 0.37
"""Efficiency of the median absolute deviation against the standard deviation, normal samples."""


def record_noise(values: np.ndarray) -> float:
    """The white noise of a finely sampled record, estimated without any model: the robust standard
    deviation of its second differences over sqrt(6) (a white sample's second difference has variance
    6 sigma^2), in the record's units. 0 for a record without scatter."""
    d2 = np.diff(np.asarray(values, dtype=np.float64), 2)
    if d2.size == 0:
        return 0.0
    return float(MAD_TO_SIGMA * np.median(np.abs(d2 - np.median(d2))) / np.sqrt(6.0))


def step_timing_error(dt: float) -> float:
    """The model error of a fitted time offset, s, where acceleration channels are fitted at step ``dt``
    (s): an acceleration jump falls anywhere within a step, ``dt / sqrt(12)``."""
    return float(dt) / float(np.sqrt(12.0))


def correlation_length(series: np.ndarray) -> float:
    """``1 + 2 sum(rho_l)`` of ``series`` (its autocorrelation summed over the lags up to its first zero
    crossing): how many consecutive samples count as one independent sample (Bretherton's effective
    number of samples is ``N`` over it). 1 for white noise."""
    x = np.asarray(series, dtype=np.float64) - float(np.mean(series))
    n = x.size
    if n < 4 or not np.any(x):
        return 1.0
    size = 1 << int(np.ceil(np.log2(2 * n)))
    f = np.fft.rfft(x, size)
    acf = np.fft.irfft(f * np.conj(f), size)[: min(n, MAX_CORRELATION_LAGS + 1)]
    rho = acf / acf[0]
    below = np.flatnonzero(rho[1:] <= 0.0)
    last = int(below[0]) if below.size else rho.size - 1
    return float(max(1.0, 1.0 + 2.0 * np.sum(rho[1 : last + 1])))


def filter_correlation_length(sos: np.ndarray | None, n: int) -> float:
    """:func:`correlation_length` of white noise after the zero-phase filter ``sos`` (1 without one):
    what a channel's residuals show when they are its filtered noise and nothing else."""
    if sos is None:
        return 1.0
    from scipy.signal import sosfiltfilt  # on first use: importing scipy costs a command 0.4 s

    m = min(n, 4_096)
    x = np.zeros(m)
    x[m // 2] = 1.0
    h = sosfiltfilt(sos, x)  # its autocorrelation is that of the filtered noise
    return correlation_length(np.concatenate([h, -h]))  # centred: the impulse response has zero mean


@dataclass
class ChannelMisfit:
    """One channel's misfit against its noise: ``chi_square`` over ``dof`` degrees of freedom, the
    correlation length of its residuals over its noise's, and the variance inflation of its samples."""

    chi_square: float
    dof: float
    correlation: float
    inflation: float

    @property
    def reduced(self) -> float:
        return self.chi_square / self.dof if self.dof > 0 else float("nan")


def channel_inflation(
    residuals: np.ndarray, noise: np.ndarray, samples: np.ndarray, reference: np.ndarray, fitted: int
) -> list[ChannelMisfit]:
    """Per channel (columns of ``residuals``, (N, ch), filtered like the fit saw them): its chi-square
    against ``noise`` (the standard deviation of a filtered sample's noise, per channel) over its share of
    the degrees of freedom (``samples``: independent samples per channel, less the ``fitted`` parameters
    shared in proportion), the correlation of its residuals over ``reference`` (its noise's correlation
    length) and the variance inflation ``max(1, chi2/dof) * max(1, correlation)``."""
    total = float(np.sum(samples))
    out = []
    for k in range(residuals.shape[1]):
        dof = max(float(samples[k]) * (1.0 - fitted / max(total, 1.0)), 1.0)
        chi = float(np.sum((residuals[:, k] / noise[k]) ** 2) * samples[k] / residuals.shape[0])
        corr = correlation_length(residuals[:, k]) / reference[k]
        out.append(ChannelMisfit(chi, dof, corr, max(1.0, chi / dof) * max(1.0, corr)))
    return out


def expected_range(
    dof: float, noise_dof: float = math.inf, level: float = CHI_SQUARE_LEVEL
) -> tuple[float, float]:
    """The range ``chi2 / dof`` lies in with probability ``level`` when the residuals are the noise: a
    chi-square's against a stated noise, an F distribution's against a noise estimated with ``noise_dof``
    degrees of freedom of its own."""
    from scipy.stats import chi2
    from scipy.stats import f as f_distribution

    q = [(1 - level) / 2, (1 + level) / 2]
    d = max(dof, 1.0)
    if math.isinf(noise_dof):
        lo, hi = chi2.ppf(q, d) / d
    else:
        lo, hi = f_distribution.ppf(q, d, max(noise_dof, 1.0))
    return float(lo), float(hi)


def noise_dof(samples: int) -> float:
    """Degrees of freedom of :func:`record_noise` from ``samples`` samples: second differences count as
    one in about 1.94 (their correlation), a median as 0.37 of a mean."""
    return MAD_EFFICIENCY * samples / 1.94


def goodness_of_fit(
    names: list[str], misfits: list[ChannelMisfit], noise_source: list[str], fitted: int, samples: int
) -> dict[str, Any]:
    """The chi-square test of a fit: per channel and in all, ``chi_square``, ``dof``, ``reduced_chi_square``
    (chi2/dof), its ``expected_range`` and ``consistent``; the residuals' ``correlation`` (their
    correlation length over the noise's) and the ``inflation`` of each channel's variance; a ``verdict``
    in words. ``noise_source`` says per channel whether its noise was ``stated`` or ``estimated`` from the
    record (from ``samples`` samples: the range then allows for the estimate's own scatter)."""
    chans = []
    own = [math.inf if src == "stated" else noise_dof(samples) for src in noise_source]
    for name, m, src, nd in zip(names, misfits, noise_source, own, strict=True):
        lo, hi = expected_range(m.dof, nd)
        chans.append(
            {
                "name": name,
                "noise": src,
                "chi_square": m.chi_square,
                "dof": m.dof,
                "reduced_chi_square": m.reduced,
                "expected_range": [lo, hi],
                "consistent": bool(lo <= m.reduced <= hi),
                "correlation": m.correlation,
                "inflation": m.inflation,
            }
        )
    chi = float(sum(m.chi_square for m in misfits))
    dof = float(max(sum(m.dof for m in misfits), 1.0))
    estimated = [nd for nd in own if not math.isinf(nd)]
    lo, hi = expected_range(dof, sum(estimated) if estimated else math.inf)
    reduced = chi / dof
    stated = "the stated sensor noise" if all(s == "stated" for s in noise_source) else "the sensor noise"
    if reduced > hi:
        k = int(np.argmax([m.reduced for m in misfits]))
        verdict = (
            f"the misfit is larger than {stated} explains (chi2/dof {reduced:.3g}, expected "
            f"{lo:.3g} to {hi:.3g}; worst {names[k]} at {misfits[k].reduced:.3g}): the model does not "
            "match the measurement to within its noise, and the uncertainties are inflated by the misfit "
            "and the residuals' correlation"
        )
    elif reduced < lo and stated.startswith("the stated"):
        verdict = (
            f"the misfit is smaller than {stated} (chi2/dof {reduced:.3g}, expected {lo:.3g} to {hi:.3g}): "
            "the noise is overstated, and the uncertainties are pessimistic"
        )
    elif reduced < lo:
        verdict = (
            f"the misfit is smaller than the noise estimated from the record (chi2/dof {reduced:.3g}, "
            f"expected {lo:.3g} to {hi:.3g}): the signal changes too fast between samples for that "
            "estimate, and the uncertainties follow the residuals instead"
        )
    else:
        verdict = f"the misfit is {stated} (chi2/dof {reduced:.3g}, expected {lo:.3g} to {hi:.3g})"
    correlated = [k for k, m in enumerate(misfits) if m.correlation > 1.5]
    if correlated:
        verdict += "; the residuals of " + ", ".join(
            f"{names[k]} ({misfits[k].correlation:.3g} times the noise's correlation)" for k in correlated
        )
        verdict += " are correlated, which widens the uncertainties"
    return {
        "chi_square": chi,
        "dof": dof,
        "reduced_chi_square": reduced,
        "expected_range": [lo, hi],
        "consistent": bool(lo <= reduced <= hi),
        "fitted": fitted,
        "channels": chans,
        "verdict": verdict,
    }


def parameter_verdict(
    J: np.ndarray, width: np.ndarray, x: np.ndarray, names: list[str]
) -> tuple[np.ndarray, list[str], dict[str, Any]]:
    """1-sigma uncertainties (NaN where not determined), reasons ("" where determined) and the
    identifiability figures of the Jacobian ``J`` (rows weighted by each sample's inflated noise, columns
    per unit of ``x``; ``width`` the bounds' width of each). The covariance is ``(J^T J)^-1``; a column is
    zero when, per bounds' width, it is below :data:`ZERO_COLUMN` of the longest (a verdict that does not
    depend on the parameters' units)."""
    P = J.shape[1]
    sigma = np.full(P, np.nan)
    reasons = [""] * P
    norms = np.linalg.norm(J, axis=0)
    scaled = norms * width
    zero = scaled <= ZERO_COLUMN * max(float(scaled.max()) if P else 0.0, 1e-300)
    for z in np.flatnonzero(zero):
        reasons[int(z)] = "not determined by this measurement: the measured channels do not respond to it"
    live = np.flatnonzero(~zero)
    corr = np.full((P, P), np.nan)
    sv: list[float] = []
    if live.size:
        Jn = J[:, live] / norms[live]
        _, s, vt = np.linalg.svd(Jn, full_matrices=False)
        sv = (s / s[0]).tolist()
        small = s < COLLINEAR * s[0]
        keep = ~small
        cov_n = (vt[keep].T / s[keep] ** 2) @ vt[keep]  # pseudo-inverse of Jn^T Jn
        d = np.sqrt(np.clip(np.diag(cov_n), 0.0, None))
        sigma[live] = d / norms[live]
        with np.errstate(invalid="ignore", divide="ignore"):
            corr[np.ix_(live, live)] = cov_n / np.outer(d, d)
        for row in np.flatnonzero(small):
            group = [int(live[q]) for q in np.flatnonzero(np.abs(vt[row]) > 0.1)]
            for g in group:
                others = ", ".join(names[j] for j in group if j != g)
                reasons[g] = (
                    "not determined by this measurement: collinear with "
                    + (others or "the others")
                    + " (only a combination of them is seen)"
                )
    for i in range(P):
        if reasons[i]:
            sigma[i] = np.nan
            continue
        big = sigma[i] > UNDETERMINED_WIDTH_FRACTION * width[i]
        if names[i] != "time_offset":  # an offset near zero is a value like any other
            big = big or sigma[i] > UNDETERMINED_RELATIVE * abs(x[i])
        if big:
            partner = ""
            row_c = np.abs(np.nan_to_num(corr[i]))
            row_c[i] = 0.0
            if row_c.max() > 0.9:
                j = int(row_c.argmax())
                partner = f"; correlated with {names[j]} at {corr[i, j]:+.4f}"
            reasons[i] = (
                f"not determined by this measurement: 1-sigma uncertainty {sigma[i]:.3g} is more than "
                f"{UNDETERMINED_WIDTH_FRACTION:g} of the bounds' width or "
                f"{UNDETERMINED_RELATIVE:g} of the value" + partner
            )
            sigma[i] = np.nan
    info = {
        "names": names,
        "fitted": list(names),
        "singular_values": sv,
        "condition_number": (1.0 / sv[-1]) if sv and sv[-1] > 0 else None,
        "correlation": [[None if not np.isfinite(v) else float(v) for v in row] for row in corr],
    }
    return sigma, reasons, info
