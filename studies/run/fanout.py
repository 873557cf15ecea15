"""Running a study's cases in chunks over a Dask cluster.

A study is split into chunks of consecutive cases (:func:`plan_chunks`). Each chunk is one Dask task,
:func:`run_chunk`, that rebuilds the study from its JSON definition on the worker, builds the chunk's
scene batch and runs the engine: tasks carry a JSON string and a few indices in, plain numpy arrays out.
Given the study's store, a worker that sees it saves the chunk there itself and hands back only the case
statuses. :func:`run_chunks` hands each chunk's arrays (or statuses) to the caller as soon as it arrives,
so every finished chunk is persisted and a study that is interrupted resumes from them.

Chunk size rule (:func:`choose_chunk_size`):

1. at least ~1 s of work per chunk (``MIN_CHUNK_SECONDS``): Dask's per-task cost (~1 ms of scheduling,
   plus rebuilding the study and moving the result) then stays well below 5 %;
2. at least 4 chunks per worker (``CHUNKS_PER_WORKER``), so a slow chunk or a slow worker does not hold
   the study up: the largest size that leaves 4 per worker is taken when it is above the 1 s floor;
3. at most ~5 s of work per chunk (``MAX_CHUNK_SECONDS``), so progress is reported and saved often, an
   interruption loses little, and a small study submitted while a large one runs waits for at most one
   such chunk per worker (the per-task cost is still below 0.1 %);
4. when the whole study is too short for rules 1 and 2 together, rule 1 wins, but never with fewer chunks
   than workers (each worker still gets a share).
5. a study with fewer than 4 chunks per worker gets a number of chunks that is a multiple of the workers,
   of one size (3 chunks on 2 workers, or 4 of which one is half, leave a worker idle at the end).

Studies share the cluster by a fair-share rule (:func:`run_chunks`, :class:`ReservedLane`). A run does not
hand Dask all its chunks at once: it keeps at most ``LOW_LANE_PER_WORKER`` (2) chunks per worker in
flight at the *low* priority (minus its number of chunks, so among these a study of fewer chunks runs
first, equal ones first come, first served; one chunk running and one queued to follow it without a gap)
and submits the next one each time one comes back: a chunk is never submitted twice nor re-prioritised.
A run that has chunks waiting beyond those (a large study) also keeps ONE chunk in flight at
:data:`RESERVED_PRIORITY`, above every other task of the service (small studies' chunks, accuracy pilots,
error-estimate reruns and finish tasks), and sends its next chunk there each time that one comes back. At
most ``max(1, n_workers // 2)`` reserved chunks are in flight at once on one cluster (a process-wide
registry per scheduler address; when more runs ask, the slots go round first come, first served), so:

* a small study (at most two chunks per worker) sends them all at once and runs before every queued
  low-priority chunk of the large ones: it waits for at most one chunk per worker (rule 3), and reserved
  chunks hold at most half the workers, so the others serve it first;
* a large study keeps at least one worker even under a steady stream of small studies, instead of only
  the workers' idle moments: on the service's 2 workers about half its rate alone (when there are more
  large studies than reserved slots, they take the slots in turn);
* alone on the cluster a study still uses every worker (its low-priority chunks fill the rest, and a
  worker that finishes one starts the next at once).

Inside a chunk the engine runs on batches of at most ``ENGINE_BATCH_CASES`` cases. The chunk size is then a
scheduling choice only: a worker's memory does not grow with it (the exact integrator holds a few step
maps per case and breakpoint, ~0.13 MB per case on the article scene, so a 4,000-case batch would take
~0.8 GB), and batches of a few hundred cases run no slower than larger ones (they stay in cache).

Timings: each task measures itself (preparing the batch, the engine's wall and CPU time, packing the
result) and returns the figures with its arrays; :func:`run_chunks` adds when the chunk was submitted and
when its result arrived and was fetched, keeps them in :attr:`FanoutReport.timings`, and, when the
environment variable ``ISOLAB_TIMINGS`` names a file, appends one JSON line per event to it
(:mod:`isolab.studies.results.timings`; the store records its reads and writes there too).
"""

from __future__ import annotations

import logging
import math
import os
import queue
import threading
import time
import uuid
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from isolab.studies.inputs.study import study_from_json
from isolab.studies.results.dataset import failed_arrays, result_arrays
from isolab.studies.results.store import is_no_space
from isolab.studies.results.timings import record_timing

MIN_CHUNK_SECONDS = 1.0
MAX_CHUNK_SECONDS = 5.0
CHUNKS_PER_WORKER = 4
TASK_RETRIES = 2
ENGINE_BATCH_CASES = 500
"""Most cases one engine call of a chunk simulates (bounds a worker's memory; see the module docstring)."""
TASK_TIMING_FIELDS = ("task_start", "task_end", "prepare_s", "engine_s", "engine_cpu_s", "pack_s", "pid")
"""Figures a chunk task returns under the key ``"timing"``: start and end (Unix time, s), time to rebuild
the study and build the batches (s), engine wall and CPU time (s), time to pack the result arrays (s), and
the worker's process id."""
RESERVED_PRIORITY = 2
"""Dask priority of a run's reserved chunk (see the module docstring): above the small studies' chunks
(minus their number), accuracy pilots (0), the finish tasks (1) and the error-estimate reruns (just below
their run's chunks, see :func:`run_chunks`); below the landing writers (3,
:data:`isolab.studies.run.landing.WRITER_PRIORITY`), which leave the thread pool as they start."""
LOW_LANE_PER_WORKER = 2
"""Chunks per worker a run keeps in flight at the low priority: one running, one queued to follow it."""
_POLL_SECONDS = 0.05


LOOPBACK = "127.0.0.1"
"""The interface every part of a LocalCluster isolab starts listens on (scheduler, workers, dashboard):
none is reachable from another machine."""
ROUTES_WITHOUT_DASHBOARD = ("distributed.http.health",)
"""What the scheduler's HTTP server of such a cluster answers without a dashboard: its health check alone
(no task keys, worker stacks or addresses; Dask has no switch to turn the server off)."""
CLUSTER_HOUSEKEEPING: dict[str, object] = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "5s",
    "distributed.worker.memory.monitor-interval": "1s",
    "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
}
"""Housekeeping of such a cluster, at the pace a machine running studies needs: Dask's defaults (a
statistical profiler sampling each worker's stack every 10 ms, event-loop health ticks every 20 ms, system
and memory monitors every 0.5 and 0.1 s) took 9.5 % of a core on an idle service with two workers, these
1.3 % (psutil over 20 s); the engine gets the rest. The profiler stays on with a dashboard, which shows it.

A worker's memory allocator keeps glibc's own settings: Dask starts workers with
``MALLOC_TRIM_THRESHOLD_=65536``, which also freezes glibc's mmap threshold at 128 kB, so every array the
engine allocates for a batch came from fresh pages (11-12 page faults a case against 3.8) and the engine
ran 3-5 % slower in a worker than in a plain process. A worker holds one chunk's arrays at a time, so the
memory glibc keeps for reuse is bounded by a chunk's."""


LOST_WORKER_TIMEOUT_S = 120
"""Seconds such a cluster waits for a killed worker's replacement to join before it closes that worker's
nanny for good (Dask's ``distributed.deploy.lost-worker-timeout``, 15 s by default). A replacement slower
than that (a spawned process's start and imports on a loaded machine) was registered and then closed with
its nanny: the service went on with one worker of two, for good (seen in the fault tests under a full test
run; with the timeout at 0.5 s a killed worker of an idle 2-worker cluster is lost the same way). Dask reads
the setting in the cluster's own process whenever a worker goes, not at the cluster's start, so
:func:`local_cluster` sets it for the process."""


def cluster_config_file() -> dict[str, Any]:
    """:data:`CLUSTER_HOUSEKEEPING` as a Dask configuration file holds it (nested; a ``null`` removes a
    setting): the image writes it to ``/etc/dask/isolab.yaml``, where the ``dask scheduler`` and ``dask
    worker`` processes of ``docker-compose.yml`` read it, and a cluster started by hand reads it from a
    folder named by ``DASK_CONFIG`` (docs/operations.md)."""
    nested: dict[str, Any] = {}
    for dotted, value in CLUSTER_HOUSEKEEPING.items():
        *parents, last = dotted.split(".")
        level = nested
        for name in parents:
            level = level.setdefault(name, {})
        level[last] = value
    return nested


def checked_workers(workers: int) -> int:
    """``workers``, the number of worker processes of a cluster to start, as an int. Raises ValueError,
    naming the field, when it is below 1."""
    if int(workers) < 1:
        raise ValueError(f"workers: {workers} must be at least 1")
    return int(workers)


def local_cluster_arguments(
    workers: int, dashboard_address: str | None = None, **settings: object
) -> tuple[dict[str, object], dict[str, Any]]:
    """The Dask settings and the ``distributed.LocalCluster`` arguments of a cluster of ``workers``
    processes with one thread each, every part of it on :data:`LOOPBACK`, with :data:`CLUSTER_HOUSEKEEPING`
    (see :func:`local_cluster`)."""
    workers = checked_workers(workers)
    config: dict[str, object] = {**CLUSTER_HOUSEKEEPING, **settings}
    if dashboard_address is not None:
        config["distributed.worker.profile.enabled"] = True
    else:
        config["distributed.scheduler.http.routes"] = list(ROUTES_WITHOUT_DASHBOARD)
    arguments: dict[str, Any] = {
        "n_workers": int(workers),
        "threads_per_worker": 1,
        "processes": True,
        "host": LOOPBACK,
        "dashboard_address": dashboard_address or f"{LOOPBACK}:0",
        "scheduler_kwargs": {"dashboard": dashboard_address is not None},
        "silence_logs": logging.WARNING,
    }
    return config, arguments


def local_cluster(workers: int, dashboard_address: str | None = None, **settings: object) -> Any:
    """A ``distributed.LocalCluster`` of ``workers`` processes with one thread each, every part of it on
    :data:`LOOPBACK`, with :data:`CLUSTER_HOUSEKEEPING`; ``dashboard_address`` (``"127.0.0.1:<port>"``)
    serves Dask's dashboard, None none. ``settings`` are more Dask settings (dotted names, as
    ``dask.config.set`` takes them) for the cluster's scheduler and workers (their nannies hand them on).
    A killed worker's replacement is waited for :data:`LOST_WORKER_TIMEOUT_S` seconds at least."""
    import dask
    from dask.utils import parse_timedelta
    from distributed import LocalCluster

    config, arguments = local_cluster_arguments(workers, dashboard_address, **settings)
    lost = "distributed.deploy.lost-worker-timeout"
    if parse_timedelta(dask.config.get(lost)) < LOST_WORKER_TIMEOUT_S:  # a longer one set is kept
        dask.config.set({lost: f"{LOST_WORKER_TIMEOUT_S}s"})  # for the process: read when a worker goes
    with dask.config.set(config):
        return LocalCluster(**arguments)


class FanoutError(RuntimeError):
    """Every chunk of a run failed: nothing was computed."""


def reserved_slots(n_workers: int) -> int:
    """Reserved chunks a cluster of ``n_workers`` worker threads may run at once: ``max(1, n_workers // 2)``
    (the other half serves everything else first)."""
    return max(1, int(n_workers) // 2)


def worker_threads(client) -> int:
    """Worker threads of ``client``'s cluster (1 when the scheduler cannot be asked).

    Asked of the scheduler itself (``Client.nthreads``): ``Client.scheduler_info`` answers from the
    client's cached identity, which its periodic refresh (every 2 s) rewrites *without* the workers, so
    a call that lost that race read no workers, planned a study for one and, on two workers, halved its
    chunks (a 2,400-case study ran as one chunk and was not written as its chunks landed)."""
    try:
        return max(1, sum(int(n) for n in client.nthreads().values()))
    except Exception:  # no live scheduler: size for one worker
        return 1


class ReservedLane:
    """The reserved chunks in flight on one cluster (see the module docstring); thread-safe.

    A run asks with :meth:`take` each time it has no reserved chunk in flight and chunks waiting; it gets
    a slot when fewer than ``slots`` are held and no run that asked before it is still waiting, so the
    slots go round first come, first served. It gives the slot back with :meth:`give_back` when the
    chunk comes back (or the run ends), and :meth:`leave` when it stops asking (no chunk waiting any more,
    or the run ended), so that it does not hold up the runs behind it.

    Attributes:
        peak: most reserved chunks ever in flight at once.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._holders: set[str] = set()
        self._waiting: list[str] = []
        self.peak = 0

    @property
    def in_flight(self) -> int:
        """Reserved chunks in flight now."""
        with self._lock:
            return len(self._holders)

    def take(self, run: str, slots: int) -> bool:
        """Whether ``run`` may submit a reserved chunk now (then it holds a slot until :meth:`give_back`);
        otherwise it waits its turn (ask again later)."""
        with self._lock:
            if run in self._holders:
                return False
            if run not in self._waiting:
                self._waiting.append(run)
            if self._waiting.index(run) >= int(slots) - len(self._holders):
                return False
            self._waiting.remove(run)
            self._holders.add(run)
            self.peak = max(self.peak, len(self._holders))
            return True

    def give_back(self, run: str) -> None:
        """``run``'s reserved chunk came back: free its slot."""
        with self._lock:
            self._holders.discard(run)

    def leave(self, run: str) -> None:
        """``run`` stops waiting for a slot (it has no chunk waiting any more, or it ended)."""
        with self._lock:
            if run in self._waiting:
                self._waiting.remove(run)


_LANES: dict[str, ReservedLane] = {}
_LANES_LOCK = threading.Lock()


def reserved_lane(client) -> ReservedLane:
    """The process-wide :class:`ReservedLane` of ``client``'s cluster (keyed by the scheduler address)."""
    address = getattr(getattr(client, "scheduler", None), "address", None) or f"client-{id(client)}"
    with _LANES_LOCK:
        return _LANES.setdefault(str(address), ReservedLane())


def plan_chunks(n_cases: int, chunk_size: int) -> list[np.ndarray]:
    """Split cases ``0..n_cases-1`` into consecutive chunks of ``chunk_size`` (the last may be shorter)."""
    if int(n_cases) < 0:
        raise ValueError(f"n_cases: {n_cases} is negative")
    if int(chunk_size) < 1:
        raise ValueError(f"chunk_size: {chunk_size} must be at least 1")
    n, size = int(n_cases), int(chunk_size)
    return [np.arange(start, min(start + size, n), dtype=np.int64) for start in range(0, n, size)]


def choose_chunk_size(n_cases: int, n_workers: int, seconds_per_case_estimate: float) -> int:
    """Cases per chunk by the rule in the module docstring.

    Args:
        n_cases: cases in the study, >= 1.
        n_workers: Dask workers (threads that run chunks), >= 1.
        seconds_per_case_estimate: expected engine time per case, s (> 0).
    """
    if int(n_cases) < 1:
        raise ValueError(f"n_cases: {n_cases} must be at least 1")
    if int(n_workers) < 1:
        raise ValueError(f"n_workers: {n_workers} must be at least 1")
    spc = float(seconds_per_case_estimate)
    if not math.isfinite(spc) or spc <= 0.0:
        raise ValueError(f"seconds_per_case_estimate: {seconds_per_case_estimate} must be a positive number")
    n, w = int(n_cases), int(n_workers)
    floor_size = math.ceil(MIN_CHUNK_SECONDS / spc)  # rule 1
    ceiling_size = max(floor_size, math.floor(MAX_CHUNK_SECONDS / spc))  # rule 3
    balanced = n // (CHUNKS_PER_WORKER * w)  # rule 2
    size = min(max(balanced, floor_size), ceiling_size)
    size = max(1, min(size, max(1, n // w)))  # rule 4
    n_chunks = -(-n // size)
    if w < n_chunks < CHUNKS_PER_WORKER * w:  # rule 5: a multiple of the workers, of one size
        size = -(-n // (n_chunks + (-n_chunks) % w))
    return size


def run_chunk(
    definition_json: str,
    indices: Sequence[int] | np.ndarray,
    store_root: str | None = None,
    study_id: str | None = None,
    chunk_index: int | None = None,
) -> dict[str, np.ndarray]:
    """Run the cases ``indices`` of the study defined by ``definition_json`` (the worker task).

    The engine runs on consecutive batches of at most ``ENGINE_BATCH_CASES`` cases. Deterministic given
    its inputs, so Dask may rerun it elsewhere if a worker dies. Returns the result arrays of
    :func:`studies.results.dataset.result_arrays` plus ``indices``, and the task's own timings under
    ``"timing"``
    (float64, in the order of ``TASK_TIMING_FIELDS``).

    With ``store_root``, ``study_id`` and ``chunk_index``, and when this worker sees that store (the study's
    chunk split is saved there), the task saves the chunk itself (atomically) and returns only
    ``indices``, ``status`` and ``saved``: the results never travel through the process that runs the
    study. A worker that does not see the store returns the whole arrays, as without those arguments.
    """
    from isolab.engine import simulate

    task_start = time.time()
    t0 = time.perf_counter()
    idx = np.asarray(indices, dtype=np.int64)
    study = study_from_json(definition_json)
    sim = study.simulation
    prepare = time.perf_counter() - t0
    engine_wall = engine_cpu = pack = 0.0
    parts: list[dict[str, np.ndarray]] = []
    for start in range(0, len(idx), ENGINE_BATCH_CASES):
        t0 = time.perf_counter()
        batch = study.batch(idx[start : start + ENGINE_BATCH_CASES])
        t1 = time.perf_counter()
        c1 = time.thread_time()
        fidelity, integrator, dt = sim.engine_choice()
        result = simulate(batch, fidelity=fidelity, integrator=integrator, dt=dt, auto_step=sim.auto_step)
        c2 = time.thread_time()
        t2 = time.perf_counter()
        parts.append(result_arrays(result))
        del batch, result
        prepare += t1 - t0
        engine_wall += t2 - t1
        engine_cpu += c2 - c1
        pack += time.perf_counter() - t2
    t0 = time.perf_counter()
    arrays = (
        parts[0] if len(parts) == 1 else {name: np.concatenate([p[name] for p in parts]) for name in parts[0]}
    )
    arrays["indices"] = idx
    if store_root is not None and study_id is not None and chunk_index is not None:
        from isolab.studies.results.store import Store

        store = Store(store_root, catalog=False)
        if store.has_chunk_plan(study_id):
            store.save_chunk(study_id, int(chunk_index), arrays)
            arrays = {"indices": idx, "status": arrays["status"], "saved": np.array(True)}
    pack += time.perf_counter() - t0
    arrays["timing"] = np.array(
        [task_start, time.time(), prepare, engine_wall, engine_cpu, pack, float(os.getpid())]
    )
    return arrays


@dataclass
class ChunkTiming:
    """Where one chunk's time went (durations in s, times as Unix times in s).

    Attributes:
        n_cases: cases in the chunk.
        submitted: when the chunk was handed to Dask.
        task_start, task_end: when the task started and ended on its worker (NaN for a task that gave no
            timings, e.g. one that raised).
        worker_pid: the worker's process id (0 if unknown).
        prepare_s: time in the task to rebuild the study and build the engine batches.
        engine_s, engine_cpu_s: engine wall and CPU time in the task.
        pack_s: time in the task to turn results into arrays.
        arrived: when the client learnt the task was finished (up to the 50 ms poll later).
        fetch_s: time to fetch the result from the worker (transfer and deserialisation).
        result_bytes: size of the result arrays.
        handled_s: time in ``on_chunk`` (the runner saves the chunk and updates the catalog there).
        reserved: the chunk ran at the reserved priority (see the module docstring).
    """

    n_cases: int
    submitted: float
    task_start: float = float("nan")
    task_end: float = float("nan")
    worker_pid: int = 0
    prepare_s: float = float("nan")
    engine_s: float = float("nan")
    engine_cpu_s: float = float("nan")
    pack_s: float = float("nan")
    arrived: float = float("nan")
    fetch_s: float = 0.0
    result_bytes: int = 0
    handled_s: float = 0.0
    reserved: bool = False


@dataclass
class FanoutReport:
    """What :func:`run_chunks` did.

    Attributes:
        submitted: chunk indices sent to the cluster, in order (a cancelled run does not send the rest).
        completed: chunk indices whose arrays were handed to ``on_chunk`` (including failed ones).
        failed: chunk index -> error text, for chunks whose task raised.
        cancelled: the run was cancelled before every chunk came back.
        timings: chunk index -> :class:`ChunkTiming`, for every chunk that came back.
    """

    submitted: list[int] = field(default_factory=list)
    completed: list[int] = field(default_factory=list)
    failed: dict[int, str] = field(default_factory=dict)
    cancelled: bool = False
    timings: dict[int, ChunkTiming] = field(default_factory=dict)


def run_chunks(
    client,
    definition_json: str,
    chunks: Sequence[np.ndarray],
    skip: Iterable[int] = (),
    on_chunk: Callable[[int, dict[str, np.ndarray]], None] | None = None,
    progress: Callable[[int, int], None] | None = None,
    cancel: threading.Event | None = None,
    *,
    key_prefix: str = "isolab",
    task: Callable[..., dict[str, np.ndarray]] = run_chunk,
    store_target: tuple[str, str] | None = None,
    on_dispatched: Callable[[int], None] | None = None,
) -> FanoutReport:
    """Run every chunk not in ``skip`` on ``client`` and hand back each chunk's arrays as it arrives.

    The chunks go out a few at a time, by the fair-share rule of the module docstring (one per worker at the
    low priority, plus one at the reserved priority when the cluster's :func:`reserved_lane` has room).

    Args:
        client: a ``dask.distributed.Client``.
        definition_json: the study definition as a JSON string.
        chunks: case indices of each chunk (see :func:`plan_chunks`).
        skip: chunk indices already done (not submitted; counted as done for progress).
        on_chunk: called as ``on_chunk(k, arrays)`` in the calling thread for each finished chunk
            (``arrays`` holds ``saved`` when a worker saved the chunk itself). A chunk whose task raised
            (after ``TASK_RETRIES`` retries) arrives as all cases FAILED with the error text as message.
        progress: called as ``progress(done_cases, total_cases)`` at the start and after each chunk.
        cancel: when set, outstanding tasks are cancelled and the run returns with ``cancelled`` True.
        key_prefix: Dask task keys are ``<key_prefix>-chunk-<k>-<token>`` (e.g. the study id).
        task: the worker function (default :func:`run_chunk`).
        store_target: ``(store root, study id)``: workers that see that store save their chunks there
            themselves, and hand back only the case statuses with ``saved`` set (see :func:`run_chunk`).
        on_dispatched: called once every chunk is with Dask, with the Dask priority just below this run's
            chunks: tasks submitted at it run once the run's chunks have all gone to the workers (its
            tail), as a chunk of a run one chunk larger would.

    Raises:
        FanoutError: every submitted chunk failed.
        OSError: a chunk's task failed for want of space in the store (ENOSPC, e.g.
            :class:`studies.results.store.StoreFull`): the outstanding chunks are cancelled.
    """
    skip = {int(k) for k in skip}
    total = int(sum(len(c) for c in chunks))
    done = int(sum(len(chunks[k]) for k in skip if 0 <= k < len(chunks)))
    report = FanoutReport()
    if progress is not None:
        progress(done, total)
    todo = [k for k in range(len(chunks)) if k not in skip]
    if not todo:
        return report
    if cancel is not None and cancel.is_set():
        report.cancelled = True
        return report

    token = uuid.uuid4().hex[:8]
    n_workers = worker_threads(client)
    slots = reserved_slots(n_workers)
    lane = reserved_lane(client)
    run = f"{key_prefix}-{token}"
    record_timing(
        "fanout_start",
        key_prefix=key_prefix,
        n_chunks=len(chunks),
        n_todo=len(todo),
        n_cases=total,
        chunk_cases=[len(chunks[k]) for k in todo],
        n_workers=n_workers,
        reserved_slots=slots,
    )
    # the fair-share rule of the module docstring: LOW_LANE_PER_WORKER chunks per worker in flight at the
    # low priority and, while chunks wait beyond those, one more at the reserved priority when the lane
    # has room; each chunk that comes back wakes the loop at once (the done callback) to send the next
    futures: dict = {}  # future -> chunk index
    pending: set = set()
    waiting = list(reversed(todo))  # popped from the end: chunks go out in order
    low_in_flight = 0
    reserved_future = None
    arrived: queue.SimpleQueue = queue.SimpleQueue()  # futures as they finish (Dask's callback thread)

    def submit(reserved: bool):
        k = waiting.pop()
        args: list[Any] = [definition_json, np.asarray(chunks[k], dtype=np.int64)]
        if store_target is not None:
            args += [str(store_target[0]), str(store_target[1]), k]
        fut = client.submit(
            task,
            *args,
            key=f"{key_prefix}-chunk-{k}-{token}",
            pure=False,
            retries=TASK_RETRIES,
            priority=RESERVED_PRIORITY if reserved else -len(todo),
        )
        futures[fut] = k
        pending.add(fut)
        report.submitted.append(k)
        report.timings[k] = ChunkTiming(n_cases=len(chunks[k]), submitted=time.time(), reserved=reserved)
        fut.add_done_callback(arrived.put)
        return fut

    dispatched = False  # on_dispatched called

    def top_up() -> None:
        nonlocal low_in_flight, reserved_future, dispatched
        while waiting and low_in_flight < LOW_LANE_PER_WORKER * n_workers:
            submit(reserved=False)
            low_in_flight += 1
        if waiting and reserved_future is None and lane.take(run, slots):
            reserved_future = submit(reserved=True)
        if not waiting:
            lane.leave(run)
            if on_dispatched is not None and not dispatched:  # once
                dispatched = True
                on_dispatched(-len(todo) - 1)

    try:
        top_up()
        while pending:
            if cancel is not None and cancel.is_set():
                report.cancelled = True
                client.cancel(list(pending))
                break
            try:  # wake up as soon as a chunk comes back, or every _POLL_SECONDS to look at cancel
                batch = [arrived.get(timeout=_POLL_SECONDS)]
            except queue.Empty:
                if waiting and reserved_future is None:
                    top_up()  # ask the reserved lane again
                continue
            while not arrived.empty():
                batch.append(arrived.get())
            batch = [f for f in batch if f in pending]
            for fut in batch:
                pending.discard(fut)
                k = futures[fut]
                if fut is reserved_future:
                    reserved_future = None
                    lane.give_back(run)
                else:
                    low_in_flight -= 1
                timing = report.timings[k]
                timing.arrived = time.time()
                if fut.status == "finished":
                    t0 = time.perf_counter()
                    arrays = fut.result()
                    timing.fetch_s = time.perf_counter() - t0
                    _take_task_timing(arrays, timing)
                else:
                    exc = fut.exception() if fut.status == "error" else None
                    if is_no_space(exc):  # not the cases' fault: the study fails (and can run again)
                        assert exc is not None
                        raise exc
                    text = f"{type(exc).__name__}: {exc}" if exc is not None else f"task {fut.status}"
                    report.failed[k] = text
                    arrays = failed_arrays(len(chunks[k]), f"chunk {k} failed: {text}")
                    arrays["indices"] = np.asarray(chunks[k], dtype=np.int64)
                fut.release()
                if on_chunk is not None:
                    t0 = time.perf_counter()
                    on_chunk(k, arrays)
                    timing.handled_s = time.perf_counter() - t0
                report.completed.append(k)
                record_timing(
                    "chunk", key_prefix=key_prefix, chunk=k, failed=k in report.failed, **asdict(timing)
                )
                done += len(chunks[k])
                if progress is not None:
                    progress(done, total)
            if not (cancel is not None and cancel.is_set()):
                top_up()  # the next chunks go out as these came back
    except BaseException:
        client.cancel(list(pending))
        raise
    finally:
        lane.leave(run)
        if reserved_future is not None:
            lane.give_back(run)
    record_timing(
        "fanout_end", key_prefix=key_prefix, cancelled=report.cancelled, n_failed_chunks=len(report.failed)
    )
    if not report.cancelled and report.failed and len(report.failed) == len(report.submitted):
        first = min(report.failed.items())
        raise FanoutError(f"every chunk failed; chunk {first[0]}: {first[1]}")
    return report


def _take_task_timing(arrays: dict[str, np.ndarray], timing: ChunkTiming) -> None:
    """Move a task's own timings (``arrays["timing"]``) into ``timing``; note the result's size."""
    figures = arrays.pop("timing", None)
    timing.result_bytes = int(sum(np.asarray(a).nbytes for a in arrays.values()))
    if figures is None or np.shape(figures) != (len(TASK_TIMING_FIELDS),):
        return
    got = dict(zip(TASK_TIMING_FIELDS, np.asarray(figures, dtype=np.float64).tolist(), strict=True))
    for name in ("task_start", "task_end", "prepare_s", "engine_s", "engine_cpu_s", "pack_s"):
        setattr(timing, name, got[name])
    timing.worker_pid = int(got["pid"])
