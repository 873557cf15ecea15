"""An optimum answered as a plateau: the designs within a stated share of the best objective and the range
of each variable over them (against the closed form of a bowl), variables at an end of their range flagged,
and the stopping rule on stalled improvement."""

from __future__ import annotations

import json

import numpy as np
import pytest
import xarray as xr

from isolab.studies.questions.designs import Factor
from isolab.studies.questions.goals import Constraint, Goals, Objective
from isolab.studies.run.optimisation import describe_optimum, mark_optimum, non_dominated, optimise, stalled


def goals(x_low: float = -2.0, plateau: float = 0.1, stall: int | None = None, budget: int = 1200) -> Goals:
    factors = (Factor("x", "x", low=x_low, high=3.0), Factor("y", "y", low=0.01, high=100.0, scale="log"))
    return Goals(
        (Objective("f0", "minimize"),),
        (Constraint("x", ">=", 1.5),),
        "ga",
        budget,
        24,
        7,
        ("case_ok", "x >= 1.5"),
        factors,
        plateau,
        stall,
    )


def bowl(v: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(x - 1)^2 + (log10 y)^2 subject to x >= 1.5: optimum 0.25 at x = 1.5, y = 1."""
    x, y = v["x"], v["y"]
    f = (x - 1.0) ** 2 + np.log10(y) ** 2
    return f[:, None], np.stack([np.zeros_like(x), 1.5 - x], axis=1)


def marked(g: Goals, n: int = 401) -> xr.Dataset:
    x, y = np.meshgrid(np.linspace(g.factors[0].low, 3.0, n), np.geomspace(0.01, 100.0, n), indexing="ij")
    v = {"x": x.ravel(), "y": y.ravel()}
    F, G = bowl(v)
    ds = xr.Dataset({k: ("case", a) for k, a in v.items()})
    return mark_optimum(ds, F, G, np.zeros(len(F), dtype=int), g)


def test_the_plateau_is_every_feasible_design_within_the_share_of_the_best() -> None:
    ds = marked(goals(plateau=0.1))
    s = json.loads(ds.attrs["optimisation"])
    # f <= 1.1 * 0.25 with x >= 1.5: x in [1.5, 1 + sqrt(0.275)], |log10 y| <= sqrt(0.025)
    (x_lo, x_hi), (y_lo, y_hi) = s["plateau_ranges"]["x"], s["plateau_ranges"]["y"]
    assert x_lo == pytest.approx(1.5, abs=1e-9)
    assert x_hi == pytest.approx(1 + np.sqrt(0.275), abs=0.0125)  # the grid's step in x
    assert np.log10(y_hi) == pytest.approx(np.sqrt(0.025), abs=0.01)  # its step in log10 y
    assert np.log10(y_lo) == pytest.approx(-np.sqrt(0.025), abs=0.01)
    plateau = ds["plateau"].values
    f = (ds["x"].values - 1) ** 2 + np.log10(ds["y"].values) ** 2
    np.testing.assert_array_equal(plateau, (ds["feasible"].values) & (f <= 0.275 + 1e-12))
    assert s["n_plateau"] == int(plateau.sum()) > 1
    assert ds["plateau"].attrs["units"] == "1" and "within 0.1" in ds["plateau"].attrs["long_name"]
    assert (
        s["at_limit"] == {} and (ds["at_range_limit"].values == 0).all()
    )  # the constraint binds, not a range


def test_a_best_value_at_an_end_of_its_range_is_flagged() -> None:
    ds = marked(goals(x_low=1.5, plateau=0.0))
    s = json.loads(ds.attrs["optimisation"])
    assert s["at_limit"] == {"x": "low"}
    assert ds["at_range_limit"].sel(parameter="x") == -1 and ds["at_range_limit"].sel(parameter="y") == 0
    assert ds["at_range_limit"].attrs["units"] == "1"
    ds.attrs["optimisation"] = json.dumps({**s, "best_objectives": {}})  # no outputs to read units from
    lines = describe_optimum(ds)
    assert any("x is at the low end of its range" in line for line in lines)
    assert any(line.startswith("plateau: ") for line in lines)


def test_one_objective_keeps_exactly_the_rows_no_other_row_beats() -> None:
    def by_pairs(F: np.ndarray) -> np.ndarray:  # the definition: no row no worse everywhere, better once
        return np.array([not ((F <= row).all(axis=1) & (F < row).any(axis=1)).any() for row in F])

    rng = np.random.default_rng(3)
    f = rng.integers(0, 6, 300).astype(float)  # many ties, the lowest among them
    f[[4, 50]] = np.nan  # a case without a value dominates none and none dominates it
    f[9] = np.inf
    for F in (f[:, None], np.full((5, 1), np.nan), np.array([[2.0]]), np.zeros((0, 1))):
        np.testing.assert_array_equal(non_dominated(F), by_pairs(F))
    assert non_dominated(f[:, None]).sum() == np.count_nonzero(f == 0) + 2


def test_stalled_counts_generations_that_do_not_improve_the_best() -> None:
    ok = np.zeros((2, 1))
    bad = np.ones((2, 1))
    F = [
        np.array([[2.0], [3.0]]),
        np.array([[1.0], [5.0]]),
        np.array([[0.9995], [2.0]]),
        np.array([[1.0], [1.0]]),
    ]
    assert not stalled(F, [ok] * 4, 3)  # the second generation improved by half; then two quiet ones
    assert stalled(F, [ok] * 4, 2)
    assert stalled(F[:1], [bad], 1)  # no feasible case yet: nothing improved
    assert not stalled(F[:2], [bad, ok], 1)  # the first feasible case is an improvement


def test_the_run_stops_once_improvement_stalls() -> None:
    def evaluate(_g: int, v: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        F, G = bowl(v)
        return {"F": F, "G": G}

    full = optimise(goals(), evaluate)
    early = optimise(goals(stall=5), evaluate)
    assert not full.stalled and full.n_cases == 1200
    assert early.stalled and early.n_cases < full.n_cases
    Fs = [a["F"] for a in early.generations]
    Gs = [a["G"] for a in early.generations]
    assert stalled(Fs, Gs, 5) and not stalled(Fs[:-1], Gs[:-1], 5)  # it stopped at the first stall
    best = min(float(f[(g <= 0).all(axis=1), 0].min()) for f, g in zip(Fs, Gs, strict=True) if (g <= 0).any())
    assert best == pytest.approx(0.25, abs=0.02)
