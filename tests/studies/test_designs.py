"""Experiment designs: counts, ranges, reproducibility, stratification, log scales, categorical levels."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml

from isolab.studies.inputs.study import Study
from isolab.studies.questions import designs
from isolab.studies.questions.designs import Factor

EXAMPLES = Path(__file__).resolve().parents[2] / "studies" / "examples"
G = 9.80665


def factors() -> list[Factor]:
    return [
        Factor("mass", "stages.y.mass", "kg", low=300.0, high=1500.0),
        Factor("k", "isolators.k.x", "N/m", low=1e5, high=1e7, scale="log"),
        Factor("type", "isolators.preset", "", levels=np.array(["active", "air", "elastomer"])),
    ]


def test_grid_is_full_factorial_last_fastest():
    fs = [
        Factor("a", "p.a", "m", levels=np.array([1.0, 2.0])),
        Factor("b", "p.b", "", levels=np.array(["u", "v", "w"])),
        Factor("c", "p.c", "Hz", low=1.0, high=100.0, scale="log", num=3),
    ]
    d = designs.grid(fs)
    assert d.kind == "grid" and d.n_cases == 18 and d.shape == (2, 3, 3)
    np.testing.assert_allclose(d.levels["c"], [1.0, 10.0, 100.0])
    assert d.values["a"].tolist() == [1.0] * 9 + [2.0] * 9
    assert d.values["b"][:9].tolist() == ["u"] * 3 + ["v"] * 3 + ["w"] * 3
    np.testing.assert_allclose(d.values["c"][:3], [1.0, 10.0, 100.0])
    combos = set(
        zip(d.values["a"].tolist(), d.values["b"].tolist(), d.values["c"].round(9).tolist(), strict=True)
    )
    assert len(combos) == 18
    assert d.paths == {"a": "p.a", "b": "p.b", "c": "p.c"} and d.units["c"] == "Hz"


def test_grid_without_parameters_is_one_case():
    d = designs.grid([])
    assert d.n_cases == 1 and d.shape == ()


def test_grid_rejects_repeated_levels():
    with pytest.raises(ValueError, match="repeat"):
        designs.grid([Factor("a", "p", "m", levels=np.array([1.0, 1.0]))])


@pytest.mark.parametrize("make", [designs.latin_hypercube, designs.sobol, designs.random])
@pytest.mark.parametrize("n", [1, 7, 64, 1000])
def test_sampled_count_range_and_reproducibility(make, n):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a sample size that is not a power of 2 still draws warning-free
        d = make(factors(), n, seed=5)
        again = make(factors(), n, seed=5)
        other = make(factors(), n, seed=6)
    assert d.kind == "sampled" and d.n_cases == n and d.shape == (n,) and d.levels == {}
    m, k, t = d.values["mass"], d.values["k"], d.values["type"]
    assert m.shape == k.shape == t.shape == (n,)
    assert np.all((m >= 300.0) & (m <= 1500.0))
    assert np.all((k >= 1e5) & (k <= 1e7))
    assert set(t.tolist()) <= {"active", "air", "elastomer"}
    for name in ("mass", "k", "type"):
        np.testing.assert_array_equal(d.values[name], again.values[name])
    assert not np.array_equal(d.values["mass"], other.values["mass"])


def test_lhs_hits_each_stratum_once_per_parameter():
    n = 300
    d = designs.latin_hypercube(factors(), n, seed=11)
    u_mass = (d.values["mass"] - 300.0) / 1200.0
    u_k = np.log(d.values["k"] / 1e5) / np.log(100.0)  # log range: strata are equal in log space
    for u in (u_mass, u_k):
        strata = np.floor(u * n).astype(int)
        assert sorted(strata.tolist()) == list(range(n))
    # categorical: index = floor(u * n_levels): each of 3 levels exactly n/3 times
    _, counts = np.unique(d.values["type"], return_counts=True)
    assert counts.tolist() == [100, 100, 100]


@pytest.mark.parametrize("d", [1, 2, 5])
@pytest.mark.parametrize("n", [1, 7, 2400])
@pytest.mark.parametrize("seed", [0, 11, 2**40])
def test_the_latin_hypercube_is_scipys_bit_for_bit(d: int, n: int, seed: int) -> None:
    # drawn without importing scipy.stats (0.4 s of CPU off a worker's first chunk), the points stay
    # those scipy draws: a study stored before keeps its cases when it is run or resumed again
    from scipy.stats import qmc

    theirs = qmc.LatinHypercube(d=d, rng=np.random.default_rng(seed)).random(n)
    np.testing.assert_array_equal(designs.latin_hypercube_unit(d, n, seed), theirs)


def test_a_latin_hypercube_study_is_built_without_scipy_stats() -> None:
    import subprocess
    import sys

    code = (
        "import sys\n"
        "from isolab.studies.inputs.study import load_study\n"
        f"study = load_study({str(EXAMPLES / 'lhs-10000.yaml')!r})\n"
        "assert study.n_cases > 1 and study.design().kind == 'sampled'\n"
        "print('scipy.stats' in sys.modules)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.split() == ["False"]


def test_log_scale_is_uniform_in_log_space():
    d = designs.random([Factor("k", "p", "N/m", low=1e3, high=1e7, scale="log")], 20000, seed=2)
    decades = np.floor(np.log10(d.values["k"])).astype(int)
    _, counts = np.unique(decades, return_counts=True)
    assert counts.size == 4 and np.all(np.abs(counts - 5000) < 300)  # 4 decades, 5000 each +- 4 sigma


def test_sobol_power_of_two_is_balanced():
    d = designs.sobol([Factor("x", "p", "", low=0.0, high=1.0)], 64, seed=0)
    strata = np.floor(d.values["x"] * 64).astype(int)
    assert sorted(strata.tolist()) == list(range(64))  # a scrambled Sobol' net: one point per 1/64


def test_explicit_cases():
    fs = [
        Factor("m", "stages.y.mass", "kg", low=0, high=0),
        Factor("t", "isolators.preset", "", levels=np.array(["air", "active"])),
    ]
    d = designs.explicit(fs, [{"m": 500.0, "t": "air"}, {"m": 900.0, "t": "active"}])
    assert (
        d.n_cases == 2
        and d.values["m"].tolist() == [500.0, 900.0]
        and d.values["t"].tolist() == ["air", "active"]
    )
    with pytest.raises(ValueError, match=r"design.cases\[1\]: missing m"):
        designs.explicit(fs, [{"m": 1.0, "t": "air"}, {"t": "air"}])
    with pytest.raises(ValueError, match=r"design.cases\[0\].t"):
        designs.explicit(fs, [{"m": 1.0, "t": "foam"}])


def test_bad_ranges_and_sample_counts():
    with pytest.raises(ValueError, match="log range"):
        Factor("k", "p", "", low=-1.0, high=10.0, scale="log")
    with pytest.raises(ValueError, match="samples"):
        designs.random(factors(), 0)


def scene() -> dict:
    return yaml.safe_load((EXAMPLES / "article-scriber.yaml").read_text())


@pytest.mark.parametrize("kind", ["lhs", "sobol", "random"])
def test_study_designs_with_units_and_categorical_values(kind):
    data = {
        "name": "t",
        "scene": scene(),
        "parameters": [
            {"path": "stages.y.profile.acceleration", "range": {"start": "0.5 g", "stop": "2 g"}},
            {"path": "isolators.preset", "values": ["active", "air", "elastomer"]},
            {"name": "span", "path": "isolators.layout.span_y", "values": ["3 m", "3.6 m"]},
        ],
        "design": {"type": kind, "samples": 96, "seed": 3},
    }
    d = Study.model_validate(data).design()
    assert d.names == ["stage_y_acceleration", "isolator_type", "span"]
    a = d.values["stage_y_acceleration"]
    assert d.n_cases == 96 and np.all((a >= 0.5 * G) & (a <= 2 * G))
    assert set(d.values["isolator_type"].tolist()) == {"active", "air", "elastomer"}
    assert set(d.values["span"].tolist()) == {3.0, 3.6}
    d2 = Study.model_validate(data).design()
    np.testing.assert_array_equal(d.values["stage_y_acceleration"], d2.values["stage_y_acceleration"])
    data["design"]["seed"] = 4
    d3 = Study.model_validate(data).design()
    assert not np.array_equal(d.values["stage_y_acceleration"], d3.values["stage_y_acceleration"])


def test_study_list_design_converts_units():
    data = {
        "name": "t",
        "scene": scene(),
        "parameters": [{"path": "stages.y.profile.acceleration"}, {"path": "isolators.preset"}],
        "design": {
            "type": "list",
            "cases": [
                {"stage_y_acceleration": "1 g", "isolator_type": "active"},
                {"stage_y_acceleration": 5.0, "isolator_type": "air"},
            ],
        },
    }
    d = Study.model_validate(data).design()
    assert d.kind == "sampled" and d.values["stage_y_acceleration"].tolist() == [G, 5.0]
    assert d.values["isolator_type"].tolist() == ["active", "air"]
