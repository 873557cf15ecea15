"""Running a study's cases in chunks over a Dask cluster.

A study is split into chunks of consecutive cases (:func:`plan_chunks`). Each chunk is one Dask task,
:func:`run_chunk`, that rebuilds the study from its JSON definition on the worker, builds the chunk's
scene batch and runs the engine: tasks carry a JSON string and a few indices in, plain numpy arrays out.
:func:`run_chunks` hands each chunk's arrays to the caller as soon as it arrives, so the caller can persist
it and a study that is interrupted resumes from its finished chunks.

Chunk size rule (:func:`choose_chunk_size`):

1. at least ~1 s of work per chunk (``MIN_CHUNK_SECONDS``): Dask's per-task cost (~1 ms of scheduling,
   plus rebuilding the study and moving the result) then stays well below 5 %;
2. at least 4 chunks per worker (``CHUNKS_PER_WORKER``), so a slow chunk or a slow worker does not hold
   the study up: the largest size that leaves 4 per worker is taken when it is above the 1 s floor;
3. at most ~30 s of work per chunk (``MAX_CHUNK_SECONDS``), so progress is reported and saved often and
   an interruption loses little;
4. when the whole study is too short for rules 1 and 2 together, rule 1 wins, but never with fewer chunks
   than workers (each worker still gets a share).
"""

from __future__ import annotations

import functools
import json
import math
import threading
import time
import uuid
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from studies.dataset import failed_arrays, result_arrays

MIN_CHUNK_SECONDS = 1.0
MAX_CHUNK_SECONDS = 30.0
CHUNKS_PER_WORKER = 4
TASK_RETRIES = 2
_POLL_SECONDS = 0.05


class FanoutError(RuntimeError):
    """Every chunk of a run failed: nothing was computed."""


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
    size = min(size, max(1, n // w))  # rule 4
    return max(1, size)


@functools.lru_cache(maxsize=8)
def _study_from_json(definition_json: str):
    """The validated Study of a JSON definition, cached per worker process (chunks of one study share it).

    Validated as data (``Study.model_validate``): a worker never reads files named in a definition."""
    from studies.study import Study

    return Study.model_validate(json.loads(definition_json))


def run_chunk(definition_json: str, indices: Sequence[int] | np.ndarray) -> dict[str, np.ndarray]:
    """Run the cases ``indices`` of the study defined by ``definition_json`` (the worker task).

    Deterministic given its inputs, so Dask may rerun it elsewhere if a worker dies. Returns the
    result arrays of :func:`studies.dataset.result_arrays` plus ``indices``.
    """
    from engine import simulate

    idx = np.asarray(indices, dtype=np.int64)
    study = _study_from_json(definition_json)
    sim = study.simulation
    result = simulate(
        study.batch(idx),
        fidelity=sim.fidelity,
        integrator=sim.integrator,
        dt=sim.dt,
        auto_step=sim.auto_step,
    )
    arrays = result_arrays(result)
    arrays["indices"] = idx
    return arrays


@dataclass
class FanoutReport:
    """What :func:`run_chunks` did.

    Attributes:
        submitted: chunk indices sent to the cluster (not skipped).
        completed: chunk indices whose arrays were handed to ``on_chunk`` (including failed ones).
        failed: chunk index -> error text, for chunks whose task raised.
        cancelled: the run was cancelled before every chunk came back.
    """

    submitted: list[int] = field(default_factory=list)
    completed: list[int] = field(default_factory=list)
    failed: dict[int, str] = field(default_factory=dict)
    cancelled: bool = False


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
    task: Callable[[str, np.ndarray], dict[str, np.ndarray]] = run_chunk,
) -> FanoutReport:
    """Run every chunk not in ``skip`` on ``client`` and hand back each chunk's arrays as it arrives.

    Args:
        client: a ``dask.distributed.Client``.
        definition_json: the study definition as a JSON string.
        chunks: case indices of each chunk (see :func:`plan_chunks`).
        skip: chunk indices already done (not submitted; counted as done for progress).
        on_chunk: called as ``on_chunk(k, arrays)`` in the calling thread for each finished chunk. A chunk
            whose task raised (after ``TASK_RETRIES`` retries) arrives as all cases FAILED with the error
            text as message.
        progress: called as ``progress(done_cases, total_cases)`` at the start and after each chunk.
        cancel: when set, outstanding tasks are cancelled and the run returns with ``cancelled`` True.
        key_prefix: Dask task keys are ``<key_prefix>-chunk-<k>-<token>`` (e.g. the study id).
        task: the worker function (default :func:`run_chunk`).

    Raises:
        FanoutError: every submitted chunk failed.
    """
    from dask.distributed import as_completed

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
    futures = {}
    for k in todo:
        fut = client.submit(
            task, definition_json, np.asarray(chunks[k], dtype=np.int64),
            key=f"{key_prefix}-chunk-{k}-{token}", pure=False, retries=TASK_RETRIES,
        )
        futures[fut] = k
        report.submitted.append(k)

    pending = set(futures)
    ac = as_completed(list(futures))
    try:
        while pending:
            if cancel is not None and cancel.is_set():
                report.cancelled = True
                client.cancel(list(pending))
                break
            batch = ac.next_batch(block=False) if ac.has_ready() else []
            if not batch:
                if cancel is not None:
                    cancel.wait(_POLL_SECONDS)
                else:
                    time.sleep(_POLL_SECONDS)
                continue
            for fut in batch:
                pending.discard(fut)
                k = futures[fut]
                if fut.status == "finished":
                    arrays = fut.result()
                else:
                    exc = fut.exception() if fut.status == "error" else None
                    text = f"{type(exc).__name__}: {exc}" if exc is not None else f"task {fut.status}"
                    report.failed[k] = text
                    arrays = failed_arrays(len(chunks[k]), f"chunk {k} failed: {text}")
                    arrays["indices"] = np.asarray(chunks[k], dtype=np.int64)
                fut.release()
                if on_chunk is not None:
                    on_chunk(k, arrays)
                report.completed.append(k)
                done += len(chunks[k])
                if progress is not None:
                    progress(done, total)
    except BaseException:
        client.cancel(list(pending))
        raise
    if not report.cancelled and report.failed and len(report.failed) == len(report.submitted):
        first = min(report.failed.items())
        raise FanoutError(f"every chunk failed; chunk {first[0]}: {first[1]}")
    return report
