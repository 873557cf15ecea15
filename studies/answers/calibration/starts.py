"""Where a calibration's fit starts: the scene's values, and more starts within the bounds on request.

A least-squares fit finds the minimum nearest its start. With ``starts: N`` the fit is run from the
scene's values and from ``N - 1`` points of a scrambled Sobol' sequence (fixed seed: the same request
gives the same answer) within the parameters' bounds; the best fit is kept and :func:`start_spread`
reports where each start ended.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from isolab.studies.inputs.definitions import DefinitionError, Loc, detail

MAX_STARTS = 16
"""Most starts of one calibration (each costs about one fit)."""
SOBOL_SEED = 20_240_611
"""Seed of the scrambled Sobol' sequence of the starts."""


def start_count(value: Any, loc: Loc) -> int:
    """The number of starts a request asks for: a whole number from 1 to :data:`MAX_STARTS`.

    Raises:
        DefinitionError: anything else, at ``loc``.
    """
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= MAX_STARTS:
        raise DefinitionError(
            [detail(loc, f"must be a whole number of starts from 1 to {MAX_STARTS}, got {value!r}")]
        )
    return int(value)


def start_points(start: np.ndarray, lower: np.ndarray, upper: np.ndarray, n: int) -> np.ndarray:
    """(n, P) starting values: ``start`` (the scene's) first, then ``n - 1`` scrambled Sobol' points
    within ``lower`` .. ``upper``."""
    if n <= 1 or start.size == 0:
        return start[None, :].copy()
    from scipy.stats import qmc

    m = max(0, int(np.ceil(np.log2(n - 1))))
    unit = qmc.Sobol(start.size, scramble=True, seed=SOBOL_SEED).random_base2(m)[: n - 1]
    return np.vstack([start[None, :], lower + unit * (upper - lower)])


def start_spread(
    names: list[str], starts: np.ndarray, ends: np.ndarray, costs: list[float], best: int, sigma: np.ndarray
) -> dict[str, Any]:
    """Where each start went: its start and end values (SI, per parameter in ``names``), its chi-square
    (``costs``, against the noise), which one was kept (``best``), how many ended within 3 sigma of it
    on every parameter (``agreeing``), and the range of the end values per parameter."""
    agree = 0
    for e in ends:
        d = np.abs(e - ends[best])
        ok = np.where(np.isfinite(sigma) & (sigma > 0), d <= 3 * np.nan_to_num(sigma, nan=np.inf), True)
        agree += bool(np.all(ok))
    return {
        "count": int(len(costs)),
        "best": int(best),
        "agreeing": int(agree),
        "chi_square": [float(c) for c in costs],
        "start": {n: [float(v) for v in starts[:, i]] for i, n in enumerate(names)},
        "end": {n: [float(v) for v in ends[:, i]] for i, n in enumerate(names)},
        "range": {n: [float(ends[:, i].min()), float(ends[:, i].max())] for i, n in enumerate(names)},
    }
