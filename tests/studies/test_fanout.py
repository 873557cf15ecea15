"""Chunked fan-out over a real Dask LocalCluster: chunk sizing, failures, cancellation, resume."""

from __future__ import annotations

import json
import math
import operator
import os
import sys
import threading
import time
from concurrent.futures import Future
from pathlib import Path

import cloudpickle
import numpy as np
import pytest
import xarray as xr
from distributed import Client, wait

from isolab.engine import __version__ as engine_version
from isolab.engine import simulate
from isolab.engine.results import FAILED, OK, UNSTABLE
from isolab.studies.inputs.study import load_study, study_labels
from isolab.studies.results.dataset import to_dataset
from isolab.studies.results.store import Store
from isolab.studies.run import fanout, runner
from isolab.studies.run.fanout import (
    CHUNKS_PER_WORKER,
    FanoutError,
    FanoutReport,
    ReservedLane,
    choose_chunk_size,
    plan_chunks,
    reserved_lane,
    reserved_slots,
    run_chunk,
    run_chunks,
)
from isolab.studies.run.runner import finish_study, make_client, run_local, run_study
from tests.shared_cluster import shared_scheduler

pytestmark = pytest.mark.slow  # services, clusters or processes of their own: `make test-fast` skips them

# the tasks below are defined in this test module: ship them to the workers by value
cloudpickle.register_pickle_by_value(sys.modules[__name__])


@pytest.fixture(scope="module")
def client():
    with Client(shared_scheduler(2)) as c:
        yield c


def slow_chunk(*args) -> dict[str, np.ndarray]:
    """:func:`studies.run.fanout.run_chunk` after 0.2 s: a run that a cancel reliably interrupts."""
    time.sleep(0.2)
    return fanout.run_chunk(*args)


def squares_task(definition_json: str, indices: np.ndarray) -> dict[str, np.ndarray]:
    """A stand-in worker task: value = index^2, fails for the chunks starting at ``fail``."""
    spec = json.loads(definition_json)
    time.sleep(spec.get("sleep", 0.0))
    if int(indices[0]) in spec.get("fail", []):
        raise ZeroDivisionError(f"no good at case {int(indices[0])}")
    return {
        "status": np.zeros(len(indices), dtype=np.int8),
        "message": np.array([""] * len(indices)),
        "value": indices.astype(float) ** 2,
        "indices": indices,
    }


# ---------------------------------------------------------------------------------------- planning
def test_plan_chunks_is_deterministic_and_covers_every_case_once() -> None:
    chunks = plan_chunks(10, 4)
    assert [c.tolist() for c in chunks] == [[0, 1, 2, 3], [4, 5, 6, 7], [8, 9]]
    assert [c.tolist() for c in plan_chunks(10, 4)] == [c.tolist() for c in chunks]
    assert plan_chunks(0, 3) == []
    assert [c.tolist() for c in plan_chunks(3, 100)] == [[0, 1, 2]]
    with pytest.raises(ValueError, match="chunk_size"):
        plan_chunks(10, 0)


@pytest.mark.parametrize(
    ("n", "workers", "spc", "size"),
    [
        (1_000_000, 2, 1e-3, 5_000),  # huge study: capped at 5 s of work per chunk
        (1000, 2, 0.01, 125),  # 10 s of work: 8 chunks of 1.25 s (4 per worker)
        (400, 2, 0.01, 100),  # 4 s: 1 s chunks, 4 of them (2 per worker)
        (10, 2, 0.01, 5),  # 0.1 s: one chunk per worker
        (100, 2, 0.5, 10),  # 50 s: 10 chunks of 5 s (the cap)
        (5, 8, 100.0, 1),  # fewer cases than workers: one case per chunk
        (10_000, 2, 0.29e-3, 2_500),  # 2.9 s: chunks of >= 1 s would be 3, one worker idle a third: 4
        (10_000, 2, 0.352e-3, 2_500),  # 3.5 s: 4 chunks of 2,841 would end with 1,477: 4 of 2,500
        (10, 3, 0.1, 2),  # 1 s: 4 chunks of 3 on 3 workers (one works twice) -> 5 of 2
    ],
)
def test_chunk_size_rule(n: int, workers: int, spc: float, size: int) -> None:
    assert choose_chunk_size(n, workers, spc) == size


def test_chunk_size_rule_holds_across_studies() -> None:
    for n in (1, 7, 50, 333, 4096, 10**5, 10**7):
        for w in (1, 2, 3, 16, 64):
            for spc in (1e-5, 3e-4, 2e-3, 0.05, 1.0, 40.0):
                size = choose_chunk_size(n, w, spc)
                n_chunks = math.ceil(n / size)
                work = size * spc
                if n * spc >= CHUNKS_PER_WORKER * w * 1.0 and spc <= 1.0:
                    # long enough for both: >= ~1 s per chunk and >= 4 chunks per worker
                    assert work >= 1.0 - 1e-9 and n_chunks >= CHUNKS_PER_WORKER * w, (n, w, spc, size)
                else:
                    # short study: chunks of >= 1 s where that still feeds every worker
                    assert work >= 1.0 - 1e-9 or n_chunks >= min(n, w), (n, w, spc, size)
                assert work <= 30.0 or size == 1, (n, w, spc, size)


def test_chunk_size_inputs_are_checked() -> None:
    with pytest.raises(ValueError, match="n_workers"):
        choose_chunk_size(10, 0, 1.0)
    with pytest.raises(ValueError, match="seconds_per_case_estimate"):
        choose_chunk_size(10, 2, 0.0)
    with pytest.raises(ValueError, match="n_cases"):
        choose_chunk_size(0, 2, 1.0)


def test_the_worker_count_is_asked_of_the_scheduler_not_the_client_cache(client: Client, monkeypatch) -> None:
    # the client's periodic refresh caches the scheduler's identity without its workers; a
    # `scheduler_info()` that lost the race to it read none (a study planned for one worker)
    client.sync(client._update_scheduler_info, n_workers=0)
    assert client._scheduler_identity["workers"] == {}
    monkeypatch.setattr(client, "scheduler_info", lambda *a, **k: client._scheduler_identity)
    assert fanout.worker_threads(client) == 2
    assert choose_chunk_size(2400, fanout.worker_threads(client), 1e-4) == 1200  # two chunks, not one


# -------------------------------------------------------------------------------------- fan-out
def test_every_chunk_arrives_once_with_its_cases(client: Client) -> None:
    chunks = plan_chunks(23, 5)
    got: dict[int, dict] = {}
    seen: list[tuple[int, int]] = []
    report = run_chunks(
        client,
        json.dumps({}),
        chunks,
        on_chunk=lambda k, a: got.__setitem__(k, a),
        progress=lambda d, t: seen.append((d, t)),
        task=squares_task,
        key_prefix="t1",
    )
    assert sorted(got) == [0, 1, 2, 3, 4] and sorted(report.submitted) == [0, 1, 2, 3, 4]
    assert report.failed == {} and not report.cancelled
    for k, arrays in got.items():
        np.testing.assert_array_equal(arrays["value"], chunks[k] ** 2.0)
    assert seen[0] == (0, 23) and seen[-1] == (23, 23)
    assert [d for d, _ in seen] == sorted(d for d, _ in seen)


def test_skipped_chunks_are_not_submitted(client: Client) -> None:
    chunks = plan_chunks(20, 5)
    got: dict[int, dict] = {}
    seen: list[int] = []
    report = run_chunks(
        client,
        json.dumps({}),
        chunks,
        skip={0, 2},
        on_chunk=lambda k, a: got.__setitem__(k, a),
        progress=lambda d, t: seen.append(d),
        task=squares_task,
        key_prefix="t2",
    )
    assert sorted(report.submitted) == [1, 3] and sorted(got) == [1, 3]
    assert seen[0] == 10 and seen[-1] == 20
    nothing = run_chunks(client, "{}", chunks, skip={0, 1, 2, 3}, task=squares_task)
    assert nothing.submitted == []


def test_a_failing_chunk_fails_its_cases_and_the_study_goes_on(client: Client) -> None:
    chunks = plan_chunks(12, 4)
    got: dict[int, dict] = {}
    report = run_chunks(
        client,
        json.dumps({"fail": [4]}),
        chunks,
        on_chunk=lambda k, a: got.__setitem__(k, a),
        task=squares_task,
        key_prefix="t3",
    )
    assert list(report.failed) == [1]
    assert "ZeroDivisionError: no good at case 4" in report.failed[1]
    assert got[1]["status"].tolist() == [FAILED] * 4
    assert all("no good at case 4" in m for m in got[1]["message"].tolist())
    assert "value" not in got[1]  # its outputs are missing, not made up
    assert got[0]["status"].tolist() == [OK] * 4 and got[2]["value"].tolist() == [64.0, 81.0, 100.0, 121.0]


def test_when_every_chunk_fails_the_run_raises(client: Client) -> None:
    with pytest.raises(FanoutError, match="no good at case"):
        run_chunks(
            client, json.dumps({"fail": [0, 3]}), plan_chunks(6, 3), task=squares_task, key_prefix="t4"
        )


def test_cancel_stops_outstanding_chunks(client: Client) -> None:
    chunks = plan_chunks(12, 1)  # 12 chunks of 0.3 s on 2 workers: ~1.8 s uninterrupted
    cancel = threading.Event()
    got: dict[int, dict] = {}

    def on_chunk(k, arrays):
        got[k] = arrays
        cancel.set()

    t0 = time.perf_counter()
    report = run_chunks(
        client,
        json.dumps({"sleep": 0.3}),
        chunks,
        on_chunk=on_chunk,
        cancel=cancel,
        task=squares_task,
        key_prefix="t5",
    )
    elapsed = time.perf_counter() - t0
    assert report.cancelled
    assert 1 <= len(got) <= 3 and sorted(report.completed) == sorted(got)
    assert elapsed < 1.5
    time.sleep(0.5)
    assert sum(len(v) for v in client.processing().values()) == 0  # nothing left running


def reused_allocation_faults() -> int:
    """Page faults of allocating, filling and freeing a 4 MB array 20 times in this process (as the
    engine does a batch's arrays), after a first round that lets the allocator settle."""
    import resource

    np.ones(1 << 19).sum()
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(20):
        np.ones(1 << 19).sum()
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before


def test_a_worker_reuses_freed_memory_instead_of_fresh_pages(client: Client) -> None:
    # Dask starts workers with MALLOC_TRIM_THRESHOLD_, which pins glibc's mmap threshold: every batch's
    # arrays then came from fresh pages (1,024 faults per 4 MB array) and the engine ran 3-5 % slower in
    # a worker than alone. The cluster's workers keep glibc's own settings: the array's pages are reused.
    assert set(client.run(os.environ.get, "MALLOC_TRIM_THRESHOLD_").values()) == {None}
    faults = client.run(reused_allocation_faults)
    assert max(faults.values()) < 20 * 1024 / 10, faults


# ------------------------------------------------------------------------------------ fair share
def timed_task(definition_json: str, indices: np.ndarray) -> dict[str, np.ndarray]:
    """A stand-in chunk: sleeps ``sleep`` s, reports its start and end (``timing``) and its ``study``."""
    spec = json.loads(definition_json)
    start = time.time()
    time.sleep(spec["sleep"])
    return {
        "status": np.zeros(len(indices), dtype=np.int8),
        "indices": indices,
        "study": np.array(spec["study"]),
        "timing": np.array([start, time.time(), 0.0, 0.0, 0.0, 0.0, 0.0]),
    }


def test_the_reserved_lane_caps_its_slots_and_goes_round() -> None:
    assert [reserved_slots(n) for n in (1, 2, 3, 4, 9)] == [1, 1, 1, 2, 4]
    lane = ReservedLane()
    assert lane.take("a", 1) and not lane.take("a", 1)  # one reserved chunk per run
    assert not lane.take("b", 1) and not lane.take("c", 1)  # full: b, then c, wait their turn
    lane.give_back("a")
    assert not lane.take("c", 1) and not lane.take("a", 1)  # b asked first; a goes to the back
    assert lane.take("b", 1) and lane.in_flight == 1
    lane.give_back("b")
    lane.leave("c")  # c has nothing left to run: it no longer holds up a
    assert lane.take("a", 1)
    assert lane.take("d", 2) and lane.in_flight == 2 and not lane.take("e", 2)
    assert lane.peak == 2


def started_at(seconds: float) -> float:
    """A stand-in side task (an error-estimate rerun): sleeps ``seconds``, returns when it started."""
    start = time.time()
    time.sleep(seconds)
    return start


def test_tasks_given_the_dispatch_priority_wait_for_every_chunk_of_the_run(client: Client) -> None:
    """The error estimate's reruns go out when ``on_dispatched`` says every chunk is out, at the priority it
    gives: below the run's chunks, so they run in its tail (and beside the dataset's writing) instead of
    holding its first chunks back."""
    side: list = []
    priorities: list[int] = []

    def dispatched(priority: int) -> None:
        priorities.append(priority)
        side.extend(
            client.submit(started_at, 0.05, pure=False, priority=priority, key=f"side-{i}") for i in range(3)
        )

    report = run_chunks(
        client,
        json.dumps({"sleep": 0.15, "study": "tail"}),
        plan_chunks(10, 1),
        task=timed_task,
        key_prefix="tail",
        on_dispatched=dispatched,
    )
    assert priorities == [-11]  # just below the run's 10 chunks, once
    starts = [f.result(timeout=30) for f in side]
    timings = report.timings.values()
    last_out = max(t.submitted for t in timings)  # the last chunk handed to Dask, once 5 had come back
    assert sum(t.task_end <= last_out + 0.01 for t in timings) >= 5
    assert min(starts) >= last_out, (starts, last_out)
    # a run with nothing left to do hands nothing out
    assert (
        run_chunks(
            client, "{}", plan_chunks(2, 1), skip={0, 1}, task=timed_task, on_dispatched=dispatched
        ).submitted
        == []
    )
    assert priorities == [-11]


def _stream_small_studies(client: Client, stop: threading.Event, turnarounds: list, n: int) -> None:
    """Submit 2-chunk studies of ``SMALL_CHUNK_S`` chunks one after the other until ``stop``, noting each
    one's turnaround (s), or what went wrong (a string)."""
    i = 0
    while not stop.is_set():
        name = f"small-{n}-{i}"
        seen: list[str] = []
        t0 = time.perf_counter()
        report = run_chunks(
            client,
            json.dumps({"sleep": SMALL_CHUNK_S, "study": name}),
            plan_chunks(2, 1),
            on_chunk=lambda k, arrays, seen=seen: seen.append(str(arrays["study"])),
            task=timed_task,
            key_prefix=name,
        )
        turnarounds.append(time.perf_counter() - t0)
        if seen != [name, name] or any(t.reserved for t in report.timings.values()):
            turnarounds.append(f"{name}: chunks of {seen}, reserved {report.timings}")
        i += 1


BIG_CHUNK_S, SMALL_CHUNK_S = 0.3, 0.05
"""Durations of a large and a small study's stand-in chunks (s): as in the service, where a large study's
chunks take up to 5 s and a 4-case study's tasks tens to hundreds of ms."""


def _big_run(client: Client, name: str, cancel: threading.Event, out: list[FanoutReport]) -> None:
    out.append(
        run_chunks(
            client,
            json.dumps({"sleep": BIG_CHUNK_S, "study": name}),
            plan_chunks(400, 1),
            cancel=cancel,
            task=timed_task,
            key_prefix=name,
        )
    )


def _chunks_per_second(report: FanoutReport, start: float, end: float) -> float:
    """Chunks of ``report`` that ended between the Unix times ``start`` and ``end``, per second."""
    ends = [t.task_end for t in report.timings.values() if math.isfinite(t.task_end)]
    return sum(start <= e <= end for e in ends) / (end - start)


def test_a_large_study_keeps_its_share_while_small_studies_stream(client: Client) -> None:
    n_workers = 2
    run_chunks(client, json.dumps({"sleep": 0.0, "study": "warm-up"}), plan_chunks(4, 1), task=timed_task)
    # alone, a study keeps every worker busy: about n_workers / BIG_CHUNK_S chunks per second
    t0 = time.time()
    alone = run_chunks(
        client, json.dumps({"sleep": BIG_CHUNK_S, "study": "alone"}), plan_chunks(12, 1), task=timed_task
    )
    alone_rate = 12 / (max(t.task_end for t in alone.timings.values()) - t0)
    assert alone_rate >= 0.75 * n_workers / BIG_CHUNK_S
    assert any(t.reserved for t in alone.timings.values())

    # a large study, then six clients that each submit a 2-chunk study as soon as their last one is done:
    # without the reserved lane their chunks (higher priority) would take every worker
    cancel, stop = threading.Event(), threading.Event()
    big: list[FanoutReport] = []
    turnarounds: list = []
    threads = [threading.Thread(target=_big_run, args=(client, "big", cancel, big))]
    threads[0].start()
    time.sleep(0.3)
    threads += [
        threading.Thread(target=_stream_small_studies, args=(client, stop, turnarounds, n)) for n in range(6)
    ]
    for t in threads[1:]:
        t.start()
    time.sleep(0.5)  # the small studies' queue builds up
    start = time.time()
    time.sleep(4.0)
    end = time.time()
    stop.set()
    for t in threads[1:]:
        t.join(timeout=30)
    cancel.set()
    threads[0].join(timeout=30)
    (report,) = big
    assert report.cancelled and len(report.completed) < 400

    loaded_rate = _chunks_per_second(report, start, end)
    assert loaded_rate >= 0.3 * alone_rate, (loaded_rate, alone_rate)
    # small studies are still served (on the low lane): each one waits for a few chunks at most, and many
    # went through
    assert all(isinstance(t, float) for t in turnarounds), [t for t in turnarounds if isinstance(t, str)]
    assert len(turnarounds) >= 20 and max(turnarounds) < 10 * BIG_CHUNK_S, turnarounds
    # never more reserved chunks at once than half the workers: by the registry and by the tasks' times
    assert reserved_lane(client).peak <= reserved_slots(n_workers) == 1
    ran = [t for t in report.timings.values() if math.isfinite(t.task_end)]  # (not the ones cancelled)
    reserved = sorted((t.task_start, t.task_end) for t in ran if t.reserved)
    assert len(reserved) >= 5
    assert all(a[1] <= b[0] + 0.01 for a, b in zip(reserved, reserved[1:], strict=False))
    assert reserved_lane(client).in_flight == 0


def test_two_large_studies_take_the_reserved_lane_in_turn(client: Client) -> None:
    # one reserved slot on 2 workers: the two studies' reserved chunks never run at once, and both get some
    reports: list[FanoutReport] = []
    threads = [
        threading.Thread(
            target=lambda name: reports.append(
                run_chunks(
                    client,
                    json.dumps({"sleep": BIG_CHUNK_S, "study": name}),
                    plan_chunks(10, 1),
                    task=timed_task,
                    key_prefix=name,
                )
            ),
            args=(name,),
        )
        for name in ("big-a", "big-b")
    ]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=60)
    assert len(reports) == 2 and all(sorted(r.completed) == list(range(10)) for r in reports)
    reserved = sorted((t.task_start, t.task_end) for r in reports for t in r.timings.values() if t.reserved)
    assert all(sum(t.reserved for t in r.timings.values()) >= 1 for r in reports)
    assert all(a[1] <= b[0] + 0.01 for a, b in zip(reserved, reserved[1:], strict=False)), reserved
    assert reserved_lane(client).peak <= 1 and reserved_lane(client).in_flight == 0


# ------------------------------------------------------------------------ studies on a real cluster
def small_study(
    integrator: str = "rk4", dt: str = "2 ms", masses=("500 kg", "1000 kg"), duration: str = "1.5 s"
) -> dict:
    """The article's scriber cut down: a 1 m Y move, three isolator types x the given stage masses."""
    return {
        "name": "small-scriber",
        "scene": {
            "machine": {
                "block": {"size": ["2.6 m", "4.2 m", "0.34 m"], "density": "2700 kg/m^3", "corner": [0, 0, 0]}
            },
            "isolators": {
                "preset": "air",
                "layout": {"span_x": "2.2 m", "span_y": "3.6 m", "height": "0.5 m"},
            },
            "stages": [
                {
                    "name": "y",
                    "mass": "1000 kg",
                    "home": ["1.3 m", "0.6 m", "0.47 m"],
                    "axis": [0, 1, 0],
                    "profile": {
                        "type": "trapezoid",
                        "travel": "1 m",
                        "velocity": "1 m/s",
                        "acceleration": "1 g",
                    },
                }
            ],
            "points": {"tool": ["1.3 m", "0.6 m", "0.6 m"], "camera": ["1.3 m", "3.6 m", "0.9 m"]},
            "simulation": {
                "fidelity": "lti",
                "integrator": integrator,
                "dt": dt,
                "auto_step": False,
                "duration": duration,
            },
        },
        "parameters": [
            {"path": "isolators.preset", "values": ["active", "air", "elastomer"]},
            {"path": "stages.y.mass", "values": list(masses)},
        ],
        "design": {"type": "grid"},
    }


def direct_dataset(study) -> xr.Dataset:
    """The same study run by the engine directly on one batch of every case, laid out the same way."""
    sim = study.simulation
    result = simulate(
        study.batch(np.arange(study.n_cases)),
        fidelity=sim.fidelity,
        integrator=sim.integrator,
        dt=sim.dt,
        auto_step=sim.auto_step,
    )
    iso, pts = study_labels(study)
    return to_dataset(result, study.design(), isolator_names=iso, point_names=pts, attrs={})


def test_study_on_the_cluster_gives_the_engine_numbers(client: Client, tmp_path: Path) -> None:
    # explicit Euler at 25 ms is past the stability limit of the stiff (elastomer, ~17 Hz) mounts only
    study = load_study(small_study(integrator="euler", dt="25 ms"))
    store = Store(tmp_path)
    seen: list[tuple[int, int]] = []
    sid = run_study(study, store, client, chunk_size=2, progress=lambda d, t: seen.append((d, t)))
    assert seen[0] == (0, 6) and seen[-1] == (6, 6) and len(seen) == 4
    with xr.open_dataset(store.path(sid)) as f:
        ds = f.load()
    direct = direct_dataset(study)
    for name in direct.data_vars:
        np.testing.assert_array_equal(ds[name].values, direct[name].values, err_msg=name)
    assert ds.status.sel(isolator_type="elastomer").values.tolist() == [UNSTABLE, UNSTABLE]
    assert np.isnan(ds.peak_displacement.sel(isolator_type="elastomer")).all()
    assert (ds.status.sel(isolator_type=["active", "air"]) == OK).all()
    # active mounts feed the stage's force forward and move least; a heavier stage moves the base more
    y = ds.peak_displacement.sel(axis="y")
    assert float(y.sel(isolator_type="active", stage_y_mass=1000)) < float(
        y.sel(isolator_type="air", stage_y_mass=1000)
    )
    assert float(y.sel(isolator_type="air", stage_y_mass=1000)) > float(
        y.sel(isolator_type="air", stage_y_mass=500)
    )
    row = store.get(sid)
    assert (row["status"], row["n_cases"], row["n_done"], row["n_failed"]) == ("done", 6, 6, 2)
    assert row["parameters"] == ["isolator_type", "stage_y_mass"]
    assert row["isolator_types"] == ["active", "air", "elastomer"]
    assert row["fidelity"] == "lti" and row["integrator"] == "euler"
    assert row["started"] <= row["finished"] and row["error"] is None
    assert not store.chunk_dir(sid).exists()
    assert ds.attrs["engine_version"] == engine_version and ds.attrs["dt"] == 0.025
    assert json.loads(ds.attrs["study"]) == study.model_dump(mode="json")
    assert json.loads(ds.attrs["design"])["type"] == "grid"


def test_an_interrupted_study_resumes_without_recomputing(
    client: Client, tmp_path: Path, monkeypatch
) -> None:
    definition = small_study(masses=[f"{m} kg" for m in range(300, 1500, 150)])  # 3 x 8 = 24 cases
    study = load_study(definition)
    calls: list[dict] = []

    def counting_run_chunks(client, definition_json, chunks, skip=(), **kw):
        report = fanout.run_chunks(client, definition_json, chunks, skip=skip, task=slow_chunk, **kw)
        calls.append(
            {"skip": set(skip), "submitted": set(report.submitted), "completed": set(report.completed)}
        )
        return report

    monkeypatch.setattr(runner, "run_chunks", counting_run_chunks)
    store = Store(tmp_path / "interrupted")
    cancel = threading.Event()
    sid = run_study(
        study,
        store,
        client,
        chunk_size=2,
        cancel=cancel,
        progress=lambda done, total: cancel.set() if done > 0 else None,
    )
    row = store.get(sid)
    saved = store.done_chunks(sid)
    assert row["status"] == "cancelled" and row["finished"] is not None
    # chunks already running when the cancel came are still saved by their workers (and reused below);
    # the catalog counts the ones the runner saw arrive
    assert 0 < len(saved) < 12 and 0 < row["n_done"] <= 2 * len(saved)
    assert not store.path(sid).exists()

    resumed = run_study(study, store, client, study_id=sid)
    assert resumed == sid and store.get(sid)["status"] == "done"
    assert store.get(sid)["started"] == row["started"] and store.get(sid)["n_done"] == 24
    first, second = calls
    assert saved <= second["skip"]  # (a chunk still running at the cancel may have been saved since)
    assert second["submitted"] == set(range(12)) - second["skip"]  # finished chunks are not recomputed
    assert second["submitted"] and not (second["submitted"] & first["completed"])

    whole = Store(tmp_path / "whole")
    other = run_study(study, whole, client, chunk_size=2)
    a, b = store.open_dataset(sid), whole.open_dataset(other)
    for name in b.data_vars:
        np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=name)
    np.testing.assert_array_equal(a.stage_y_mass.values, np.arange(300.0, 1500.0, 150.0))
    assert (a.status == OK).all()
    direct = direct_dataset(study)
    for name in direct.data_vars:  # and both equal the engine run directly (estimates are the study's own)
        np.testing.assert_array_equal(a[name].values, direct[name].values, err_msg=name)


def test_a_study_whose_every_chunk_fails_is_marked_failed(
    client: Client, tmp_path: Path, monkeypatch
) -> None:
    def every_chunk_fails(client, definition_json, chunks, store_target=None, **kw):
        return fanout.run_chunks(
            client, json.dumps({"fail": [int(c[0]) for c in chunks]}), chunks, task=squares_task, **kw
        )

    monkeypatch.setattr(runner, "run_chunks", every_chunk_fails)
    store = Store(tmp_path)
    with pytest.raises(FanoutError, match="no good at case 0"):
        run_study(load_study(small_study()), store, client, chunk_size=3)
    (row,) = store.list()
    assert row["status"] == "failed" and "FanoutError" in row["error"] and row["finished"] is not None
    assert row["n_done"] == 6 and row["n_failed"] == 6
    assert not store.path(row["id"]).exists()


def test_make_client_joins_the_configured_scheduler(client: Client, monkeypatch) -> None:
    monkeypatch.setenv("DASK_SCHEDULER_ADDRESS", client.scheduler.address)
    with make_client(workers=1) as joined:
        assert joined.scheduler.address == client.scheduler.address
        assert len(joined.scheduler_info()["workers"]) == 2
        assert joined.submit(operator.add, 2, 3).result() == 5


def test_run_local_writes_the_dataset_file(tmp_path: Path) -> None:
    out = tmp_path / "out" / "small.nc"
    out.parent.mkdir()
    ds = run_local(small_study(integrator="exact", duration="1 s"), out, workers=1)
    assert sorted(p.name for p in out.parent.iterdir()) == ["small.nc"]
    with xr.open_dataset(out) as f:
        back = f.load()
    xr.testing.assert_identical(back, ds)
    study = load_study(small_study(integrator="exact", duration="1 s"))
    direct = direct_dataset(study)
    np.testing.assert_array_equal(back.natural_frequency.values, direct.natural_frequency.values)
    # 1 Hz active mounts have the lowest first mode, ~17 Hz elastomer the highest last mode
    f1 = back.natural_frequency.sel(mode=1, stage_y_mass=500)
    assert (
        float(f1.sel(isolator_type="active"))
        < float(f1.sel(isolator_type="air"))
        < float(f1.sel(isolator_type="elastomer"))
    )


def test_a_worker_saves_its_chunk_only_where_it_sees_the_store(tmp_path: Path) -> None:
    # a worker on another machine (no such store there) hands the whole result back, as without a store
    study = load_study(small_study(integrator="exact", duration="1 s"))
    definition_json = json.dumps(study.model_dump(mode="json"))
    store = Store(tmp_path)
    sid = store.create(study.model_dump(mode="json"), name="s", n_cases=study.n_cases)
    idx = np.array([0, 1], dtype=np.int64)
    unseen = run_chunk(definition_json, idx, str(tmp_path / "elsewhere"), sid, 0)
    assert "saved" not in unseen and "peak_displacement" in unseen
    assert run_chunk(definition_json, idx, str(tmp_path), sid, 0).keys() == unseen.keys()  # no plan yet
    assert not store.done_chunks(sid)
    # with the split saved, the worker writes the chunk and returns the statuses only
    store.save_chunk_plan(sid, [idx, np.arange(2, study.n_cases)])
    seen = run_chunk(definition_json, idx, str(tmp_path), sid, 0)
    assert set(seen) == {"indices", "status", "saved", "timing"} and bool(seen["saved"])
    on_disk = store.load_chunks(sid)[0]
    for name in unseen:
        if name != "timing":
            np.testing.assert_array_equal(on_disk[name], unseen[name], err_msg=name)
    assert finish_study(str(tmp_path / "elsewhere"), sid, definition_json, "{}", None) is None


def test_a_study_is_finished_by_a_worker(client: Client, tmp_path: Path, monkeypatch) -> None:
    # finishing here would fail, so the dataset comes from a worker (another process, which the patch
    # does not reach), and it equals the engine's direct run
    monkeypatch.setattr(runner, "assemble_dataset", lambda *a, **k: pytest.fail("finished in the runner"))
    study = load_study(small_study(integrator="exact", duration="1 s"))
    store = Store(tmp_path)
    sid = run_study(study, store, client, chunk_size=2)
    row = store.get(sid)
    assert (row["status"], row["n_done"]) == ("done", study.n_cases)
    assert not store.chunk_dir(sid).exists()
    ds, direct = store.open_dataset(sid), direct_dataset(study)
    for name in direct.data_vars:
        np.testing.assert_array_equal(ds[name].values, direct[name].values, err_msg=name)
    # the error estimate's reference reruns ran from the worker's task too
    assert json.loads(ds.attrs["error_estimate_cases"]) and "DOP853" in ds.attrs["error_estimate_method"]


def test_reruns_go_in_order_over_every_worker_but_the_one_that_finishes(monkeypatch) -> None:
    # the error estimate's sampled cases rerun as one task per worker but one, in order: on two workers all
    # in one task, beside the task that finishes the study; on more, spread over the idle workers
    study = load_study(small_study(integrator="exact", duration="1 s"))
    cases = runner.error_sample(study)
    assert len(cases) >= 2

    class Sent:
        def __init__(self, workers: int):
            self.workers, self.groups = workers, []

        def submit(self, function, definition, group, pair, **kwargs):
            assert function is runner.sample_arrays and kwargs["priority"] == -3
            self.groups.append(group)
            return Future()

    monkeypatch.setattr(runner, "worker_threads", lambda c: c.workers)
    for workers, tasks in ((1, 1), (2, 1), (3, 2), (len(cases) + 1, len(cases)), (64, len(cases))):
        client = Sent(workers)
        got, futures, pair = runner._submit_samples(client, study, "{}", "isolab-x", -3)
        assert got == cases and sum(client.groups, []) == cases
        assert len(futures) == len(client.groups) == tasks
        assert max(map(len, client.groups)) - min(map(len, client.groups)) <= 1  # an even split
        assert pair == runner.REFERENCE_PAIR


def test_reruns_done_before_the_finish_are_written_by_the_worker_at_once(
    client: Client, tmp_path: Path, monkeypatch
) -> None:
    # the error estimate's reruns are done when the last chunk is (here: waited for as they are sent): the
    # worker writes the dataset with the estimate, and nothing is added to the file afterwards
    sent = runner._submit_samples

    def sent_and_done(*args, **kwargs):
        cases, reruns, pair = sent(*args, **kwargs)
        wait(reruns)
        return cases, reruns, pair

    monkeypatch.setattr(runner, "_submit_samples", sent_and_done)
    monkeypatch.setattr(Store, "publish_dataset", lambda *a, **k: pytest.fail("the estimate added after"))
    study = load_study(small_study(integrator="exact", duration="1 s"))
    store = Store(tmp_path)
    sid = run_study(study, store, client, chunk_size=2)
    assert store.get(sid)["status"] == "done" and not store.chunk_dir(sid).exists()
    ds = store.open_dataset(sid)
    assert json.loads(ds.attrs["error_estimate_cases"]) and "DOP853" in ds.attrs["error_estimate_method"]
    estimates = [ds[v].values for v in ds.data_vars if str(v).startswith("error_estimate_")]
    assert estimates and all(np.isfinite(e) for e in estimates)


def test_a_streamed_study_equals_one_assembled_in_memory(tmp_path: Path, monkeypatch) -> None:
    """The runner streams the dataset of a study above ``ISOLAB_IN_MEMORY_CASES`` chunk by chunk: the file
    it writes holds the same values, attributes and units as the one built whole in memory."""
    whole = run_local(small_study(integrator="exact", duration="1 s"), tmp_path / "whole.nc", workers=1)
    monkeypatch.setenv("ISOLAB_IN_MEMORY_CASES", "0")  # the worker processes inherit it
    streamed = run_local(small_study(integrator="exact", duration="1 s"), tmp_path / "streamed.nc", workers=1)
    for ds in (whole, streamed):
        ds.attrs.pop("created", None)
        ds.attrs.pop("timing", None)
    xr.testing.assert_identical(streamed.drop_attrs(deep=False), whole.drop_attrs(deep=False))
    assert set(streamed.attrs) == set(whole.attrs)


def test_a_local_run_refuses_no_workers_before_reading_the_study(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="workers: 0 must be at least 1"):
        run_local(tmp_path / "no-such-study.yaml", tmp_path / "out.nc", workers=0)
    with pytest.raises(ValueError, match="workers: -2 must be at least 1"):
        fanout.local_cluster_arguments(-2)
