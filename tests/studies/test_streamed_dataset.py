"""A study's dataset written chunk by chunk from its saved chunks equals the one built whole in memory."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import netCDF4
import numpy as np
import pytest
import xarray as xr

from isolab.engine.results import FAILED, OK, TIPPING, UNSTABLE
from isolab.studies.questions.criteria import Criteria, add_criteria
from isolab.studies.questions.designs import Design
from isolab.studies.results.dataset import (
    add_error_estimate,
    failed_arrays,
    from_chunks,
    result_arrays,
    to_dataset,
)
from isolab.studies.results.store import Store, failures, write_netcdf
from isolab.studies.results.streaming import streamed_dataset

sys.path.insert(0, str(Path(__file__).parent))
from test_dataset import ISOLATORS, POINTS, fake_result, grid_design  # noqa: E402

CRITERIA = Criteria.model_validate(
    {"tool": {"displacement": "10 um"}, "isolators": {"no_liftoff": True, "max_force": "20 kN"}}
)
ATTRS = {"title": "isolab study streamed", "study": "{}", "created": "2026-01-02T03:04:05Z", "dt": 0.002}
ESTIMATE = {
    "values": {"peak_displacement": 1.5e-3, "natural_frequency": float("nan")},
    "worst_case": {"peak_displacement": 3, "natural_frequency": None},
    "cases": [1, 3, 7],
    "excluded": {7: "reference rerun failed"},
    "method": "sampled",
    "meaning": {"peak_displacement": "largest relative error of peak_displacement"},
    "units": {"peak_displacement": "1", "natural_frequency": "1"},
}
LONG = "worker died: " + "the chunk's task raised after three retries " * 3


def sampled_design(n: int, seed: int = 0) -> Design:
    rng = np.random.default_rng(seed)
    return Design(
        kind="sampled",
        names=["isolator_type", "stage_y_mass"],
        values={
            "isolator_type": rng.choice(["active", "air", "passive"], n).astype(np.str_),
            "stage_y_mass": rng.uniform(100.0, 1200.0, n),
        },
        levels={},
        paths={"isolator_type": "isolators.preset", "stage_y_mass": "stages.y.mass"},
        units={"isolator_type": "", "stage_y_mass": "kg"},
    )


def chunk_parts(design: Design, chunks: list[np.ndarray], failed_chunk: int | None, seed: int = 1) -> dict:
    """Each chunk's arrays as a worker saves them: some unstable and tipping cases, and one chunk whose
    task failed (status and a long message only)."""
    n = design.n_cases
    types = design.values["isolator_type"]
    masses = np.asarray(design.values["stage_y_mass"], dtype=float)
    rng = np.random.default_rng(seed)
    status = np.full(n, OK, dtype=np.int8)
    status[rng.random(n) < 0.1] = UNSTABLE
    status[rng.random(n) < 0.05] = TIPPING
    parts = {}
    for k, idx in enumerate(chunks):
        if k == failed_chunk:
            parts[k] = failed_arrays(len(idx), LONG)
            continue
        arrays = result_arrays(fake_result([str(types[i]) for i in idx], masses[idx], status[idx]))
        arrays["indices"] = np.asarray(idx, dtype=np.int64)
        parts[k] = arrays
    return parts


def in_memory(parts: dict, chunks: list[np.ndarray], design: Design, estimate: bool = True) -> xr.Dataset:
    """The dataset as the runner built it whole before it streamed (from_chunks, to_dataset, criteria,
    and the error estimate unless ``estimate`` is False)."""
    result = from_chunks(parts, chunks, n_isolators=len(ISOLATORS), n_points=len(POINTS))
    ds = add_criteria(
        to_dataset(result, design, isolator_names=ISOLATORS, point_names=POINTS, attrs=ATTRS), CRITERIA
    )
    return add_error_estimate(ds, **ESTIMATE) if estimate else ds


def streamed(parts: dict, chunks: list[np.ndarray], design: Design, estimate: bool = True) -> xr.Dataset:
    ds = streamed_dataset(
        parts.__getitem__,
        chunks,
        design,
        isolator_names=ISOLATORS,
        point_names=POINTS,
        attrs=ATTRS,
        criteria=CRITERIA,
    )
    return add_error_estimate(ds, **ESTIMATE) if estimate else ds


def written(ds: xr.Dataset, path: Path) -> xr.Dataset:
    write_netcdf(ds, path)
    with xr.open_dataset(path) as f:
        return f.load()


COMPRESSION = ("zlib", "complevel", "shuffle", "contiguous")
"""Encoding keys that say whether a variable is compressed: a dataset built in memory compresses only the
variables that shrink (studies.results.compression), a streamed one every numeric variable."""


def assert_same_file(
    old: xr.Dataset, new: xr.Dataset, block: int | None, same_compression: bool = False
) -> None:
    xr.testing.assert_identical(new, old)
    assert list(new.attrs) == list(old.attrs)
    for name in old.variables:
        a, b = dict(old[name].encoding), dict(new[name].encoding)
        for e in (a, b):
            e.pop("source", None)
        if same_compression:
            assert [a.get(k) for k in COMPRESSION] == [b.get(k) for k in COMPRESSION], name
        for e in (a, b):  # either none or zlib at level 1 with the shuffle filter
            assert not e.get("zlib") or (e.get("complevel"), e.get("shuffle")) == (1, True), name
        if b.get("zlib") and block is not None and name in new.data_vars and new[name].dims[0] == "case":
            # the file's chunks are the streamed blocks along the cases
            assert b["chunksizes"][0] == block and tuple(b["chunksizes"][1:]) == new[name].shape[1:], name
        for e in (a, b):
            e.pop("chunksizes", None)
            e.pop("preferred_chunks", None)
            for key in COMPRESSION:
                e.pop(key, None)
        assert a.keys() == b.keys(), name
        for key in a:
            assert str(a[key]) == str(b[key]), (name, key)


@pytest.mark.parametrize(
    "plan",
    ["consecutive", "uneven", "interleaved"],
)
def test_a_streamed_sampled_study_equals_the_one_built_in_memory(tmp_path: Path, plan: str) -> None:
    n = 10_000
    design = sampled_design(n)
    if plan == "consecutive":  # as the runner plans them: 2,000-case chunks, read three at a time
        chunks = [np.arange(s, min(s + 2000, n)) for s in range(0, n, 2000)]
        block = 6000
    elif plan == "uneven":  # a resumed plan of another size: blocks of 4,096+ cases
        edges = [0, 1500, 5000, 5200, 9000, n]
        chunks = [np.arange(a, b) for a, b in zip(edges, edges[1:], strict=False)]
        block = 5000
    else:  # any partition of the cases
        chunks = [np.arange(0, n, 2), np.arange(1, n, 2)]
        block = 5000
    parts = chunk_parts(design, chunks, failed_chunk=len(chunks) - 1 if plan != "interleaved" else None)
    old = written(in_memory(parts, chunks, design), tmp_path / "old.nc")
    lazy = streamed(parts, chunks, design)
    assert all(
        lazy[v].chunks is not None for v in ("peak_displacement", "status", "message", "meets_criteria")
    )
    new = written(lazy, tmp_path / "new.nc")
    assert_same_file(old, new, block)

    # what the file holds, case by case: a case that did not end ok has no numbers, only its status and why
    bad = new.status.values != OK
    assert bad.any() and (~bad).any()
    for name in ("peak_displacement", "peak_isolator_force", "settling_time", "criterion_margin"):
        values = new[name].values
        assert np.isnan(values[bad]).all() and np.isfinite(values[~bad]).all(), name
    assert np.isnan(new.meets_criteria.values[bad]).all()
    if plan != "interleaved":
        last = chunks[-1]
        assert (new.status.values[last] == FAILED).all() and (new.message.values[last] == LONG).all()
        assert failures(tmp_path / "new.nc").endswith(
            f"case {int(np.flatnonzero(bad)[0])}: {new.message.values[bad][0]}"
        )
    with netCDF4.Dataset(tmp_path / "new.nc") as raw:  # yes/no outputs stored as int8, -1 when missing
        raw.set_auto_maskandscale(False)
        liftoff = raw["liftoff"][:]
        assert (
            liftoff.dtype == np.int8
            and (liftoff[bad] == -1).all()
            and set(np.unique(liftoff[~bad])) <= {0, 1}
        )
        assert (
            raw["peak_displacement"].filters()["zlib"]
            and raw["peak_displacement"].filters()["complevel"] == 1
        )
        assert raw["peak_displacement"].filters()["shuffle"]
    # closed form (see fake_result): the peak y displacement is twice x, m / fn^2 * 1e-6
    ok = np.flatnonzero(~bad)
    fn = np.array(
        [{"active": 1.0, "air": 3.0, "passive": 10.0}[t] for t in design.values["isolator_type"][ok]]
    )
    np.testing.assert_allclose(
        new.peak_displacement.sel(axis="y").values[ok], 2e-6 * design.values["stage_y_mass"][ok] / fn**2
    )
    assert new["error_estimate_peak_displacement"].attrs["case"] == 3
    assert json.loads(new.attrs["error_estimate_cases"]) == [1, 3, 7]


def test_a_streamed_grid_study_equals_the_one_built_in_memory(tmp_path: Path) -> None:
    design, _, _ = grid_design()
    chunks = [np.arange(0, 2), np.arange(2, 4), np.arange(4, 6)]
    parts = chunk_parts(design, chunks, failed_chunk=1)
    old = written(in_memory(parts, chunks, design), tmp_path / "old.nc")
    new = written(streamed(parts, chunks, design), tmp_path / "new.nc")
    assert_same_file(old, new, None)
    assert new.status.sel(isolator_type="air").values.tolist() == [FAILED, FAILED]
    assert np.isnan(new.peak_displacement.sel(isolator_type="air")).all()


@pytest.mark.parametrize("how", ["in memory", "streamed"])
def test_a_dataset_staged_then_given_its_error_estimate_equals_the_one_written_whole(
    tmp_path: Path, how: str, monkeypatch
) -> None:
    """The runner writes the dataset while the error estimate's cases run, then adds the estimate to the
    file and moves it into place: the same values, attributes, units and encodings as the file written
    with the estimate inside, and nothing under the study's name until it is complete. The file is
    flushed to the disk once, when published (a staged file lost is written again by the next run)."""
    synced: list[str] = []
    fsync = os.fsync

    def recorded(fd: int) -> None:
        synced.append(os.readlink(f"/proc/self/fd/{fd}"))
        fsync(fd)

    monkeypatch.setattr(os, "fsync", recorded)
    n = 5_000
    design = sampled_design(n)
    chunks = [np.arange(s, min(s + 2000, n)) for s in range(0, n, 2000)]
    parts = chunk_parts(design, chunks, failed_chunk=1)
    whole = written(in_memory(parts, chunks, design), tmp_path / "whole.nc")
    bulk = (in_memory if how == "in memory" else streamed)(parts, chunks, design, estimate=False)
    store = Store(tmp_path / "store")
    sid = "ab" * 16
    synced.clear()
    store.write_dataset(sid, bulk, staged=True)
    assert store.staged_path(sid).is_file() and not store.path(sid).exists()
    assert not [p for p in synced if ".nc" in Path(p).name]
    store.publish_dataset(sid, add_error_estimate(xr.Dataset(), **ESTIMATE))
    assert store.path(sid).is_file() and not store.staged_path(sid).exists()
    assert [p for p in synced if ".nc" in Path(p).name] == [str(store.staged_path(sid))]
    with xr.open_dataset(store.path(sid)) as f:
        published = f.load()
    # one block of three chunks when streamed; built in memory, the same variables compressed
    assert_same_file(whole, published, n if how == "streamed" else None, same_compression=how == "in memory")
    assert published["error_estimate_peak_displacement"].attrs == {
        "units": "1",
        "long_name": "largest relative error of peak_displacement, over the sampled cases against the "
        "reference level",
        "case": 3,
    }
    assert published["error_estimate_peak_displacement"].item() == 1.5e-3
    assert np.isnan(published["error_estimate_natural_frequency"].item())


def test_a_chunk_that_does_not_fit_fails_the_write_and_leaves_no_file(tmp_path: Path) -> None:
    design = sampled_design(6)
    chunks = [np.arange(0, 3), np.arange(3, 6)]
    parts = chunk_parts(design, chunks, failed_chunk=None)
    parts[1]["peak_displacement"] = parts[1]["peak_displacement"][:, :2]
    with pytest.raises(ValueError, match=r"parts\[1\]: peak_displacement has shape"):
        write_netcdf(streamed(parts, chunks, design), tmp_path / "study.nc")
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(ValueError, match="cover the cases"):
        streamed(parts, [np.arange(0, 3), np.arange(2, 5)], design)


_ASSEMBLE = textwrap.dedent(
    """
    import os, sys, threading
    import numpy as np
    sys.path.insert(0, {tests!r})
    from test_streamed_dataset import CRITERIA, ATTRS, ESTIMATE, ISOLATORS, POINTS, sampled_design
    from isolab.studies.results.dataset import add_error_estimate
    from isolab.studies.results.streaming import streamed_dataset
    from isolab.studies.results.store import Store, write_netcdf

    def rss():
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")

    store, sid = Store({root!r}, catalog=False), {sid!r}
    chunks = store.load_chunk_plan(sid)
    design = sampled_design(int(sum(len(c) for c in chunks)))
    before = rss()
    peak, stop = [before], threading.Event()

    def sample():
        while not stop.wait(0.002):
            peak[0] = max(peak[0], rss())

    sampler = threading.Thread(target=sample)
    sampler.start()
    if {whole!r}:  # the dataset built whole in memory, as before it streamed
        from test_streamed_dataset import in_memory
        ds = in_memory({{k: store.load_chunk(sid, k) for k in range(len(chunks))}}, chunks, design)
    else:
        ds = add_error_estimate(streamed_dataset(lambda k: store.load_chunk(sid, k), chunks, design,
            isolator_names=ISOLATORS, point_names=POINTS, attrs=ATTRS, criteria=CRITERIA), **ESTIMATE)
    write_netcdf(ds, {out!r})
    stop.set()
    sampler.join()
    print(max(peak[0], rss()) - before)
    """
)


def assembly_growth(tmp_path: Path, n_chunks: int, whole: bool) -> int:
    """Resident memory (bytes) a fresh process gains assembling and writing a study of ``n_chunks`` saved
    chunks of 4,096 cases (sampled every 2 ms)."""
    n = 4096 * n_chunks
    root = tmp_path / f"s{n_chunks}"
    store, sid = Store(root, catalog=False), "a" * 32
    if not store.has_chunk_plan(sid):
        design = sampled_design(n)
        chunks = [np.arange(s, s + 4096) for s in range(0, n, 4096)]
        for k, arrays in chunk_parts(design, chunks, failed_chunk=3).items():
            store.save_chunk(sid, k, arrays)
        store.save_chunk_plan(sid, chunks)
    out = tmp_path / f"s{n_chunks}-{whole}.nc"
    code = _ASSEMBLE.format(
        tests=str(Path(__file__).parent), root=str(root), sid=sid, out=str(out), whole=whole
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    with xr.open_dataset(out) as f:
        assert f.sizes["case"] == n and int((f.status == FAILED).sum()) == 4096
    return int(done.stdout.split()[-1])


@pytest.mark.slow  # four processes of their own write 20,000- and 82,000-case studies (~14 s)
def test_the_memory_a_streamed_write_takes_does_not_grow_with_the_chunks(tmp_path: Path) -> None:
    # 5 and 20 chunks of 4,096 cases (~0.8 kB a case in memory): built whole, the larger study takes
    # ~47 MB more than the smaller one (several times that while it is written: ~240 MB measured);
    # streamed, ~15 MB: only what is held per case at once, the case coordinates and the parameter values
    # (~150 bytes a case with the text one), and the file library's caches (10 and 40 chunks: ~18 MB)
    extra = 15 * 4096 * 770
    streamed_growth = assembly_growth(tmp_path, 20, False) - assembly_growth(tmp_path, 5, False)
    whole_growth = assembly_growth(tmp_path, 20, True) - assembly_growth(tmp_path, 5, True)
    assert whole_growth > extra  # the measure sees the whole result
    assert streamed_growth < 0.5 * extra, (streamed_growth, whole_growth)
