"""A study's dataset written as its chunks land (studies.run.landing) equals the one written after the run."""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from distributed import Client

from benchmarks.endtoend import study_definition
from isolab.engine.results import OK
from isolab.studies.inputs.study import parse_study
from isolab.studies.results.store import Store
from isolab.studies.run import landing, runner
from isolab.studies.run.fanout import plan_chunks, run_chunk
from isolab.studies.run.landing import (
    LANDING_CASES,
    WriterStopped,
    lands,
    stop_writer,
    wait_for_chunk,
    write_as_chunks_land,
)
from tests.shared_cluster import shared_scheduler

N_CASES = 2400
"""A Latin hypercube of the scriber (studies/examples/lhs-10000.yaml) cut to this many cases of 0.3 s."""
CHUNK = 600
ATTRS = {"title": "isolab study landing", "study_id": "x"}


def lhs_study(n: int = N_CASES):
    return parse_study(study_definition(n, "exact", 0.3, name="landing"))


def comparable(ds: xr.Dataset) -> xr.Dataset:
    """``ds`` without the attributes that differ between two runs of one study (when and which row)."""
    return ds.drop_attrs(deep=False).assign_attrs(
        {k: v for k, v in ds.attrs.items() if k not in ("created", "study_id", "history")}
    )


@pytest.fixture(scope="module")
def saved(tmp_path_factory) -> tuple[str, list[np.ndarray], dict[int, dict[str, np.ndarray]]]:
    """The study's definition, its chunks and each chunk's arrays as a worker saves them."""
    study = lhs_study()
    run_json = json.dumps(study.model_dump(mode="json"))
    chunks = plan_chunks(study.n_cases, CHUNK)
    parts = {}
    for k, idx in enumerate(chunks):
        arrays = run_chunk(run_json, idx)
        arrays.pop("timing")
        parts[k] = arrays
    return run_json, chunks, parts


def new_store(root: Path, run_json: str, chunks: list[np.ndarray]) -> tuple[Store, str]:
    store = Store(root)
    study = parse_study(json.loads(run_json))
    sid = store.register(study)
    store.save_chunk_plan(sid, chunks)
    return store, sid


def test_a_study_of_enough_cases_in_two_chunks_or_more_lands(monkeypatch) -> None:
    assert lands([LANDING_CASES // 2] * 2) and not lands([LANDING_CASES // 4] * 3)
    assert not lands([10 * LANDING_CASES])  # one chunk: nothing computes beside its writing
    assert not lands([])
    monkeypatch.setenv("ISOLAB_LANDING_CASES", "2400")
    assert lands([600] * 4) and not lands([600] * 3)


def test_a_chunk_is_read_once_it_is_saved_and_a_stop_ends_the_wait(tmp_path: Path, saved) -> None:
    run_json, chunks, parts = saved
    store, sid = new_store(tmp_path, run_json, chunks)
    later = threading.Timer(0.2, store.save_chunk, (sid, 1, parts[1]))
    later.start()
    t0 = time.perf_counter()
    got = wait_for_chunk(store, sid, 1)
    assert 0.15 < time.perf_counter() - t0 < 5
    for name, values in parts[1].items():
        np.testing.assert_array_equal(got[name], values, err_msg=name)

    asked = []
    with pytest.raises(WriterStopped, match="chunk 2"):
        wait_for_chunk(store, sid, 2, wanted=lambda: asked.append(1) is not None)  # Dask let the task go
    assert asked
    stop_writer(store, sid)
    with pytest.raises(WriterStopped):
        wait_for_chunk(store, sid, 2)
    store.clear_chunks(sid)  # the run is over: nothing to wait for
    with pytest.raises(WriterStopped):
        wait_for_chunk(store, sid, 2)


def test_the_writer_writes_each_block_as_its_chunk_lands(tmp_path: Path, saved, monkeypatch) -> None:
    run_json, chunks, parts = saved
    store, sid = new_store(tmp_path, run_json, chunks)
    read: list[int] = []
    load = Store.load_chunk

    def counted(self, study_id, k, fields=None):
        read.append(int(k))
        return load(self, study_id, k, fields)

    monkeypatch.setattr(Store, "load_chunk", counted)
    for k in (0, 1):
        store.save_chunk(sid, k, parts[k])
    result: list[int | None] = []
    writer = threading.Thread(
        target=lambda: result.append(write_as_chunks_land(str(store.root), sid, run_json, json.dumps(ATTRS)))
    )
    writer.start()
    deadline = time.monotonic() + 30
    while read[-1:] != [1] and time.monotonic() < deadline:
        time.sleep(0.01)
    time.sleep(0.1)
    # the first two chunks are read (and written), the writer waits for the third; nothing is staged yet
    assert read == [0, 1] and writer.is_alive() and not store.staged_path(sid).exists()
    for k in range(2, len(chunks)):
        store.save_chunk(sid, k, parts[k])
    writer.join(60)
    assert not writer.is_alive() and read == list(range(len(chunks)))
    n_failed = sum(int(np.count_nonzero(p["status"] != OK)) for p in parts.values())
    assert result == [n_failed]
    with xr.open_dataset(store.staged_path(sid)) as f:
        landed = f.load()

    # the same dataset as the one the run's finish writes from the saved chunks afterwards
    after, after_id = new_store(tmp_path / "after", run_json, chunks)
    for k, arrays in parts.items():
        after.save_chunk(after_id, k, arrays)
    assert runner.assemble_dataset(after, after_id, run_json, ATTRS, None) == n_failed
    with xr.open_dataset(after.staged_path(after_id)) as f:
        whole = f.load()
    xr.testing.assert_identical(comparable(landed), comparable(whole))
    assert landed.sizes["case"] == N_CASES and (landed.status == OK).all()


def test_a_stopped_writer_writes_nothing(tmp_path: Path, saved) -> None:
    run_json, chunks, parts = saved
    store, sid = new_store(tmp_path, run_json, chunks)
    store.save_chunk(sid, 0, parts[0])
    result: list[int | None] = []
    writer = threading.Thread(
        target=lambda: result.append(write_as_chunks_land(str(store.root), sid, run_json, json.dumps(ATTRS)))
    )
    writer.start()
    time.sleep(0.3)
    assert writer.is_alive()
    stop_writer(store, sid)
    writer.join(5)
    assert not writer.is_alive() and result == [None]
    assert not store.staged_path(sid).exists() and not store.path(sid).exists()
    assert sorted(p.name for p in store.chunk_dir(sid).iterdir()) == ["0.npz", "plan.npz", "writer.stop"]
    # a writer of a worker that does not see the store writes nothing either
    assert write_as_chunks_land(str(tmp_path / "elsewhere"), sid, run_json, "{}") is None


# ----------------------------------------------------------------------------------- on a cluster
@pytest.fixture(scope="module")
def client():
    # a study of N_CASES is written as it lands (the runner decides; the workers only write)
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("ISOLAB_LANDING_CASES", str(N_CASES))
        with Client(shared_scheduler(2)) as c:
            yield c


@pytest.mark.slow  # a cluster
def test_a_run_writes_its_dataset_as_chunks_land_and_resumes_after_a_cancel(
    client: Client, tmp_path: Path, monkeypatch
) -> None:
    study = lhs_study()
    writers: list = []
    start = runner._start_writer

    def spied(*args, **kwargs):
        writers.append(start(*args, **kwargs))
        return writers[-1]

    monkeypatch.setattr(runner, "_start_writer", spied)
    store = Store(tmp_path / "landing")
    sid = runner.run_study(study, store, client, chunk_size=CHUNK)
    assert store.get(sid)["status"] == "done" and not store.chunk_dir(sid).exists()
    (writer,) = writers
    assert writer is not None and writer.result() == 0  # the writer wrote it: no case failed
    landed = store.open_dataset(sid)
    assert json.loads(landed.attrs["error_estimate_cases"])  # the estimate added to the landed file

    # written after the run (as a study of too few cases is): the same dataset
    monkeypatch.setattr(runner, "lands", lambda sizes: False)
    after = Store(tmp_path / "after")
    whole = after.open_dataset(runner.run_study(study, after, client, chunk_size=CHUNK))
    xr.testing.assert_identical(comparable(landed), comparable(whole))

    # cancelled after its first chunk: the writer stops and stages nothing; resumed (its chunks left still
    # land), the same dataset as a run that was never cancelled
    monkeypatch.setattr(runner, "lands", landing.lands)
    study = lhs_study(2 * N_CASES)
    whole = after.open_dataset(runner.run_study(study, after, client, chunk_size=CHUNK))
    cancel = threading.Event()
    again = Store(tmp_path / "cancelled")
    sid = runner.run_study(
        study,
        again,
        client,
        chunk_size=CHUNK // 2,
        cancel=cancel,
        progress=lambda done, total: cancel.set() if done > 0 else None,
    )
    assert again.get(sid)["status"] == "cancelled"
    deadline = time.monotonic() + 10
    while not writers[-1].done() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert writers[-1].done() and not again.staged_path(sid).exists() and not again.path(sid).exists()
    assert runner.run_study(study, again, client, study_id=sid) == sid
    assert again.get(sid)["status"] == "done" and writers[-1].result() == 0
    xr.testing.assert_identical(comparable(again.open_dataset(sid)), comparable(whole))
