"""Sensitivity analysis of a study dataset against closed forms: the Ishigami function's Sobol' indices,
laid out as a study by the study's own design and dataset code."""

from __future__ import annotations

import json
import uuid
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
import yaml

from isolab.engine.results import FAILED, FLAG_FIELDS, OK, OUTPUT_FIELDS, SimulationResult, output_shape
from isolab.studies.answers import sensitivity as sensitivity_module
from isolab.studies.answers.sensitivity import SensitivityResult, sensitivity, stored_sensitivity
from isolab.studies.inputs.definitions import DefinitionError, case_count_bound, check_definition
from isolab.studies.inputs.study import Study
from isolab.studies.questions import designs
from isolab.studies.questions.designs import Factor
from isolab.studies.results.dataset import to_dataset
from isolab.studies.results.store import Store
from isolab.studies.run.runner import _design_extra

EXAMPLES = Path(__file__).resolve().parents[2] / "studies" / "examples"

A, B = 7.0, 0.1
# Analytic indices of Ishigami (a = 7, b = 0.1): V = a^2/8 + b pi^4/5 + b^2 pi^8/18 + 1/2
_V = A**2 / 8 + B * np.pi**4 / 5 + B**2 * np.pi**8 / 18 + 0.5
_V1 = 0.5 * (1 + B * np.pi**4 / 5) ** 2
_V2 = A**2 / 8
_V13 = B**2 * np.pi**8 * (1 / 18 - 1 / 50)
S1_EXACT = np.array([_V1 / _V, _V2 / _V, 0.0])
ST_EXACT = np.array([(_V1 + _V13) / _V, _V2 / _V, _V13 / _V])
ISOLATORS = ["front_left", "front_right", "rear_left", "rear_right"]


def ishigami(x1: np.ndarray, x2: np.ndarray, x3: np.ndarray) -> np.ndarray:
    return np.sin(x1) + A * np.sin(x2) ** 2 + B * x3**4 * np.sin(x1)


def result_with(settling: np.ndarray, status: np.ndarray | None = None) -> SimulationResult:
    """A result whose ``settling_time`` is ``settling`` (the other outputs: zeros)."""
    c = settling.size
    status = np.full(c, OK, dtype=np.int8) if status is None else status
    arrays = {}
    for name in OUTPUT_FIELDS:
        shape = (c, *output_shape(name, len(ISOLATORS), 1))
        arrays[name] = np.zeros(shape, dtype=bool) if name in FLAG_FIELDS else np.zeros(shape)
    arrays["settling_time"] = np.asarray(settling, dtype=float)
    message = ["" if s == OK else "failed on purpose" for s in status]
    return SimulationResult(status=status, message=message, **arrays)


def ishigami_factors() -> list[Factor]:
    return [Factor(f"x{i}", f"p.x{i}", "", low=-np.pi, high=np.pi) for i in (1, 2, 3)]


def ishigami_study(kind: str, n: int, status=None, **extra) -> xr.Dataset:
    """The Ishigami function as a study dataset of ``kind`` (saltelli, lhs, grid) with ``n`` samples."""
    factors = ishigami_factors()
    if kind == "saltelli":
        design = designs.saltelli(factors, n, seed=1, second_order=extra.get("second_order", False))
    elif kind == "lhs":
        design = designs.latin_hypercube(factors, n, seed=1)
    else:
        design = designs.grid([Factor(f.name, f.path, "", low=f.low, high=f.high, num=n) for f in factors])
    y = ishigami(*(design.values[f"x{i}"] for i in (1, 2, 3)))
    summary = {"type": kind, "samples": n, "seed": 1, **extra}
    ds = to_dataset(
        result_with(y, status),
        design,
        isolator_names=ISOLATORS,
        point_names=["tool"],
        attrs={"design": summary},
    )
    return ds


@pytest.fixture(scope="module")
def saltelli_ds() -> xr.Dataset:
    return ishigami_study("saltelli", 4096)


def test_saltelli_design_counts_and_log_scale() -> None:
    f = [Factor("k", "a", "N/m", low=1e4, high=1e6, scale="log"), Factor("z", "b", "", low=0.0, high=1.0)]
    d = designs.saltelli(f, 64, seed=3)
    assert d.n_cases == 64 * (2 + 2)
    assert designs.saltelli(f, 64, seed=3, second_order=True).n_cases == 64 * (2 * 2 + 2)
    # the log range is uniform in log space: its median is the geometric mean of the ends
    assert np.median(np.log10(d.values["k"])) == pytest.approx(5.0, abs=0.1)
    assert d.values["k"].min() >= 1e4 and d.values["k"].max() <= 1e6
    # block structure: the first two rows (A, then A with column 0 from B) share column 1
    assert d.values["z"][0] == d.values["z"][1] and d.values["k"][0] != d.values["k"][1]
    with pytest.raises(ValueError, match="lev.*saltelli design varies ranges only"):
        designs.saltelli([Factor("lev", "c", levels=np.array(["a", "b"]))], 8)


def test_ishigami_sobol_indices_through_a_study_dataset(saltelli_ds: xr.Dataset) -> None:
    r = sensitivity(saltelli_ds, "settling_time")
    assert r.method == "sobol" and r.design == "saltelli"
    assert r.n_cases == 4096 * 5 and r.n_excluded == 0
    s1, st = np.array(r.indices["S1"]), np.array(r.indices["ST"])
    s1c, stc = np.array(r.conf["S1"]), np.array(r.conf["ST"])
    np.testing.assert_allclose(S1_EXACT, [0.3139, 0.4424, 0.0], atol=1e-4)
    np.testing.assert_allclose(ST_EXACT, [0.5576, 0.4424, 0.2437], atol=1e-4)
    # within 1.5 times the 95 % interval (and a small floor) of the analytic values
    assert np.all(np.abs(s1 - S1_EXACT) <= 1.5 * s1c + 0.01), (s1, s1c)
    assert np.all(np.abs(st - ST_EXACT) <= 1.5 * stc + 0.01), (st, stc)
    assert np.all(s1c < 0.1) and np.all(stc < 0.1)
    assert r.ranking("ST") == ["x1", "x2", "x3"]
    assert r.unit == "s" and "settling time" in r.long_name
    d = r.to_dict()
    assert json.loads(json.dumps(d, allow_nan=False))["indices"]["S1"] == r.indices["S1"]
    assert SensitivityResult.from_dict(d) == r


def test_second_order_saltelli_finds_the_x1_x3_interaction() -> None:
    r = sensitivity(ishigami_study("saltelli", 2048, second_order=True), "settling_time")
    pairs = {tuple(p): v for p, v in zip(r.second_order["pairs"], r.second_order["S2"], strict=True)}
    assert pairs[("x1", "x3")] == pytest.approx(ST_EXACT[2], abs=0.06)  # S13 = ST3 (x3 acts only with x1)
    assert abs(pairs[("x1", "x2")]) < 0.06 and abs(pairs[("x2", "x3")]) < 0.06


def test_failed_cases_drop_their_whole_saltelli_block() -> None:
    n, block = 512, 5
    status = np.full(n * block, OK, dtype=np.int8)
    status[[3, 4, 700, 2000]] = FAILED  # cases of blocks 0 (two of them), 140 and 400
    ds = ishigami_study("saltelli", n, status=status)
    r = sensitivity(ds, "settling_time")
    assert r.n_excluded == 4
    assert r.n_cases == (n - 3) * block
    assert r.n_dropped == 3 * block - 4
    assert any("3 of 512 Saltelli blocks dropped" in note for note in r.notes)
    assert r.ranking("ST") == ["x1", "x2", "x3"]


def test_saltelli_refused_when_no_block_is_complete() -> None:
    status = np.full(8 * 5, OK, dtype=np.int8)
    status[::5] = FAILED
    status[5] = OK  # block 1 keeps its A row ... but its row 5 is the A row; fail another of its cases
    status[6] = FAILED
    with pytest.raises(ValueError, match="Saltelli blocks have every case ok"):
        sensitivity(ishigami_study("saltelli", 8, status=status), "settling_time")


def test_lhs_ranks_x1_x2_above_x3_with_delta() -> None:
    r = sensitivity(ishigami_study("lhs", 2000), "settling_time")
    assert r.method == "delta" and "delta" in r.method_name
    delta, s1, s1_conf = np.array(r.indices["delta"]), np.array(r.indices["S1"]), np.array(r.conf["S1"])
    # S1 separates x1 and x2 from x3 beyond the confidence intervals
    assert min(s1[0] - s1_conf[0], s1[1] - s1_conf[1]) > s1[2] + s1_conf[2]
    assert r.ranking("S1") == ["x2", "x1", "x3"]
    # delta too ranks x3 last, but close to x1: x3 widens the output's distribution (the b x3^4 sin x1
    # term) without moving its mean, which a moment-independent index sees and S1 does not
    assert delta[1] > delta[0] > delta[2] > 0.05
    # the given-data S1 (conditional means over ~12 rank classes at 2000 cases) is near the analytic
    # first-order indices; x2's effect, sin^2 with two periods over its range, is smoothed by the classes
    assert s1[0] == pytest.approx(S1_EXACT[0], abs=0.06)
    assert S1_EXACT[1] - 0.12 < s1[1] < S1_EXACT[1] + 0.06
    assert s1[2] < 0.05


def test_delta_leaves_out_failed_cases_and_counts_them() -> None:
    status = np.full(1000, OK, dtype=np.int8)
    status[:50] = FAILED
    r = sensitivity(ishigami_study("lhs", 1000, status=status), "settling_time")
    assert r.n_cases == 950 and r.n_excluded == 50 and r.n_total == 1000
    assert any("50 of 1000 cases left out (status not ok)" in note for note in r.notes)
    assert r.ranking("S1")[-1] == "x3"


def test_grid_gets_delta_on_the_levels() -> None:
    r = sensitivity(ishigami_study("grid", 12), "settling_time")  # 1728 cases
    assert r.method == "delta" and r.design == "grid" and r.n_cases == 12**3
    s1, delta = np.array(r.indices["S1"]), np.array(r.indices["delta"])
    # x1 near its analytic S1; x2's sin^2 is smoothed where a rank class joins two levels (10 classes
    # for 12 levels at 1728 cases): lower, but far above x3, which acts only with x1
    assert s1[0] == pytest.approx(S1_EXACT[0], abs=0.06)
    assert 0.2 < s1[1] < S1_EXACT[1] + 0.06
    assert s1[2] < 0.03 and delta[2] < min(delta[:2])
    assert r.ranking("S1")[-1] == "x3"
    assert any("full factorial" in note for note in r.notes)


def test_grid_with_a_categorical_parameter_takes_its_levels_as_classes() -> None:
    preset = Factor("preset", "isolators.preset", "", levels=np.array(["elastomer", "active", "air"]))
    x1 = Factor("x1", "p.x1", "", low=-np.pi, high=np.pi, num=20)
    x3 = Factor("x3", "p.x3", "", low=-np.pi, high=np.pi, num=20)
    design = designs.grid([x1, preset, x3])
    offset = {"elastomer": 0.0, "active": 2.0, "air": 1.0}  # Var = 2/3 against Var(sin x1) ~ 1/2
    y = np.sin(design.values["x1"]) + np.array([offset[p] for p in design.values["preset"]])
    ds = to_dataset(result_with(y), design, isolator_names=ISOLATORS, point_names=["tool"])
    r = sensitivity(ds, "settling_time")
    s1 = dict(zip(r.parameters, r.indices["S1"], strict=True))
    assert r.method == "delta" and r.n_cases == 1200
    # closed form: S1(preset) = (2/3) / (2/3 + Var sin x1) = 0.584 (Var sin x1 over 20 grid levels: 0.475);
    # 1,200 cases make 7 rank classes for 3 levels, two of which join two levels: the estimate is lower
    var_sin = np.var(np.sin(np.linspace(-np.pi, np.pi, 20)))
    exact = (2 / 3) / (2 / 3 + var_sin)
    assert exact - 0.1 < s1["preset"] < exact + 0.05
    assert s1["x3"] < 0.03 and r.ranking("S1") == ["preset", "x1", "x3"]


def test_bad_output_names_the_choices(saltelli_ds: xr.Dataset) -> None:
    with pytest.raises(ValueError, match="no_such_output.*settling_time"):
        sensitivity(saltelli_ds, "no_such_output")


def test_constant_output_is_refused(saltelli_ds: xr.Dataset) -> None:
    with pytest.raises(ValueError, match="depends on none of the varied parameters"):
        sensitivity(saltelli_ds, "dt")


# ------------------------------------------------------------------------------------ saltelli studies
def scriber_study(parameters: list[dict], **design) -> dict:
    scene = yaml.safe_load((EXAMPLES / "article-scriber.yaml").read_text())
    return {"name": "s", "scene": scene, "parameters": parameters, "design": {"type": "saltelli", **design}}


RANGES = [
    {"path": "isolators.f_vertical", "range": {"start": "2 Hz", "stop": "6 Hz", "scale": "log"}},
    {"path": "isolators.zeta", "range": {"start": "5 %", "stop": "30 %"}},
    {"path": "stages.y.mass", "range": {"start": "500 kg", "stop": "1500 kg"}},
]


def test_saltelli_study_runs_n_times_d_plus_2_cases_counted_before_building() -> None:
    body = scriber_study(RANGES, samples=16, seed=2)
    assert case_count_bound(body) == (16 * 5, ["body", "design", "samples"])
    assert case_count_bound(scriber_study(RANGES, samples=16, second_order=True))[0] == 16 * 8
    study = Study.model_validate(body)
    d = study.design()
    assert study.n_cases == 16 * 5 and d.kind == "sampled"
    assert d.names == ["isolator_f_vertical", "isolator_zeta", "stage_y_mass"]
    f = d.values["isolator_f_vertical"]
    assert f.min() >= 2.0 and f.max() <= 6.0
    assert _design_extra(study) == {"type": "saltelli", "samples": 16, "seed": 2, "second_order": False}
    # the limit sees the true count: 16 base samples are 80 cases, above a limit of 50
    with pytest.raises(DefinitionError, match="80 cases, more than this service's limit of 50"):
        check_definition(body, max_cases=50)


def test_saltelli_study_refuses_list_and_categorical_parameters() -> None:
    listed = [*RANGES[:2], {"path": "stages.y.mass", "values": ["500 kg", "1500 kg"]}]
    with pytest.raises(DefinitionError) as err:
        check_definition(scriber_study(listed, samples=8))
    assert err.value.details[0]["loc"][:4] == ["body", "parameters", 2, "values"]
    assert "saltelli design varies ranges only" in err.value.details[0]["msg"]
    categorical = [*RANGES[:2], {"path": "isolators.preset", "values": ["air", "elastomer"]}]
    with pytest.raises(DefinitionError) as err:
        check_definition(scriber_study(categorical, samples=8))
    assert err.value.details[0]["loc"][:3] == ["body", "parameters", 2]
    assert "isolators.preset" in err.value.details[0]["msg"] and "categorical" in err.value.details[0]["msg"]


def test_stored_analysis_is_cached_beside_the_dataset(tmp_path: Path, monkeypatch) -> None:
    store = Store(tmp_path)
    sid = uuid.uuid4().hex
    store.write_dataset(sid, ishigami_study("saltelli", 64))
    first = stored_sensitivity(store, sid, "settling_time")
    cached = list(store.results_dir(sid).glob("sensitivity-*.json"))
    assert len(cached) == 1 and json.loads(cached[0].read_text())["indices"] == first.indices

    def no_recompute(*args, **kwargs):
        raise AssertionError("recomputed")

    monkeypatch.setattr(sensitivity_module, "sensitivity", no_recompute)
    assert stored_sensitivity(store, sid, "settling_time") == first
    with pytest.raises(AssertionError, match="recomputed"):  # another output is another key
        stored_sensitivity(store, sid, "natural_frequency.1")
    monkeypatch.undo()
    store.write_dataset(sid, ishigami_study("saltelli", 128))  # a new dataset file: analysed anew
    assert stored_sensitivity(store, sid, "settling_time").n_cases == 128 * 5
    store.delete(sid)
    assert not store.results_dir(sid).exists()
    with pytest.raises(FileNotFoundError):
        stored_sensitivity(store, sid, "settling_time")


LINEAR = np.array([1.0, 0.5, 0.15, 0.1])
"""y = sum a_i x_i with x_i uniform on [0, 1]: S1_i = ST_i = a_i^2 / sum a^2 (0.78, 0.19, 0.018, 0.008)."""


def closed_form_run(
    model: str, n: int, seed: int, resamples: int | None = None
) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]:
    """Sobol' estimates of ``model`` on a Saltelli design of ``n`` base samples (the studies' own design and
    interval code, no engine), with the exact S1 and ST."""
    if model == "ishigami":
        factors, exact_s1, exact_st = ishigami_factors(), S1_EXACT, ST_EXACT
    else:
        factors = [Factor(f"x{i}", f"p.x{i}", "", low=0.0, high=1.0) for i in range(LINEAR.size)]
        exact_s1 = exact_st = LINEAR**2 / np.sum(LINEAR**2)
    design = designs.saltelli(factors, n, seed=seed)
    x = [design.values[f.name] for f in factors]
    y = ishigami(*x) if model == "ishigami" else np.column_stack(x) @ LINEAR
    return sensitivity_module.sobol_estimates(y, len(factors), resamples=resamples), exact_s1, exact_st


@pytest.mark.parametrize("model", ["ishigami", "linear"])
def test_sobol_intervals_cover_the_closed_form_indices_and_a_4x_run(model: str) -> None:
    """40 seeds of 128 base samples: each index's 95 % interval holds the exact value, and the estimate of
    a run 4 times larger, in at least 90 % of them; indices near zero (Ishigami S1 of x3 = 0; the linear
    model's 0.018 and 0.008) included."""
    exact_hits, big_hits, widths = [], [], []
    for seed in range(40):
        small, exact_s1, exact_st = closed_form_run(model, 128, seed)
        big, _, _ = closed_form_run(model, 512, 1000 + seed, resamples=10)  # its indices alone
        for k, exact in (("S1", exact_s1), ("ST", exact_st)):
            lo, hi = small[f"{k}_interval"].T
            assert np.all(lo <= small[k]) and np.all(small[k] <= hi)
            # conf is the half-width of an interval about the estimate that holds [lo, hi]
            assert np.all(small[k] - small[f"{k}_conf"] <= lo + 1e-12)
            assert np.all(hi <= small[k] + small[f"{k}_conf"] + 1e-12)
            exact_hits.append((lo <= exact) & (exact <= hi))
            big_hits.append((lo <= big[k]) & (big[k] <= hi))
            widths.append(hi - lo)
    exact_cover, big_cover = np.mean(exact_hits, axis=0), np.mean(big_hits, axis=0)
    assert np.all(exact_cover >= 0.9), exact_cover
    assert np.all(big_cover >= 0.9), big_cover
    # and they say something: far narrower than the indices' range
    assert np.mean(widths) < (0.4 if model == "ishigami" else 0.2), np.mean(widths)
