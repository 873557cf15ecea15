"""A study's dataset written as its chunks land, beside the chunks that still compute.

Without it, a study's finish (read every saved chunk, build the dataset, write it) starts once its last
chunk is done, on one worker while the others wait: 0.8 s of a 16 s, 100,000-case study. The runner
(:func:`isolab.studies.run.runner.run_study`) instead hands Dask :func:`write_as_chunks_land` with the
study's chunks. On a worker that sees the store it leaves the worker's thread pool (``distributed.secede``:
the worker goes on computing chunks beside it) and writes the staged dataset of
:func:`isolab.studies.results.streaming.streamed_dataset`, block after block, each as soon as its chunks
are saved (the chunk files appear whole, by rename). When the last chunk lands, only its own block and the
closing of the file are left; the runner then adds the error estimate and moves the file into place
(:meth:`isolab.studies.results.store.Store.publish_dataset`).

It stops, writing nothing, when the runner leaves a stop file in the study's chunk directory
(:func:`stop_writer`: a cancelled or failed run), when the chunk directory goes, or when Dask no longer
wants the task (its client went away). It returns None when its worker does not see the store or it was
stopped: the runner then finishes the study the way it did before, from the saved chunks.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import time
from collections.abc import Callable, Mapping

import numpy as np

from isolab.engine.results import OK
from isolab.studies.inputs.study import study_from_json, study_labels
from isolab.studies.results.store import Store
from isolab.studies.results.streaming import streamed_dataset

log = logging.getLogger(__name__)

POLL_S = 0.01
"""How often the writer looks for the chunk it waits for, s (a file's presence: one ``stat``)."""
STOP_FILE = "writer.stop"
"""The file in a study's chunk directory that tells its writer to stop (:func:`stop_writer`)."""
LANDING_BLOCK_CASES = 1024
"""Fewest cases a block of the landing writer holds (consecutive chunks smaller than this are written
together): a chunk is written as soon as it lands, and the file's chunks stay large enough to read well."""
WRITER_PRIORITY = 3
"""Dask priority of a landing writer: above every chunk (see :mod:`isolab.studies.run.fanout`), so that it
starts with the run; it leaves its worker's thread pool at once, so it holds no chunk back."""
LANDING_CASES = 30_000
"""Fewest cases left to compute for which a study's dataset is written as they land (``ISOLAB_LANDING_CASES``
in the environment overrides it). Where every core runs a worker, the writer's CPU (0.09 s at 10,000 cases,
0.25 s at 100,000, against 0.07 and 0.23-0.34 s to write the dataset whole after the run) and its use of
the caches come out of the chunks beside it; measured alternately with and without (two workers, two cores):
10,000 cases 1.78-1.88 s against 1.66-1.91 s (medians 1.80 and 1.75: worse), 30,000 cases 4.81-5.07 against
4.89-5.08 s (medians 4.90 and 5.00), 100,000 cases 15.17, 15.54 s against 15.95, 16.08 s, the workers' memory
0.45 against 0.59 GB. Where the machine has a core beside the workers', the writing is free at any size."""


def lands(chunk_sizes: list[int]) -> bool:
    """Whether a study whose chunks left to compute have ``chunk_sizes`` cases has its dataset written as
    they land: when two chunks or more and at least :data:`LANDING_CASES` cases are left (else writing it
    after the run costs no more)."""
    least = int(os.environ.get("ISOLAB_LANDING_CASES", LANDING_CASES))
    return len(chunk_sizes) >= 2 and sum(chunk_sizes) >= least


class WriterStopped(Exception):
    """The runner no longer wants the dataset written (see :func:`stop_writer`)."""


def stop_writer(store: Store, study_id: str) -> None:
    """Tell the landing writer of ``study_id`` to stop, writing nothing (a cancelled or failed run)."""
    folder = store.chunk_dir(study_id)
    with contextlib.suppress(OSError):
        if folder.is_dir():
            (folder / STOP_FILE).touch()


def clear_stop(store: Store, study_id: str) -> None:
    """Remove a stop left for an earlier writer of ``study_id`` (before a new run of it starts one)."""
    with contextlib.suppress(OSError):
        (store.chunk_dir(study_id) / STOP_FILE).unlink(missing_ok=True)


def wait_for_chunk(
    store: Store, study_id: str, k: int, wanted: Callable[[], bool] = lambda: True, poll: float = POLL_S
) -> dict[str, np.ndarray]:
    """Chunk ``k``'s saved arrays (:meth:`~isolab.studies.results.store.Store.load_chunk`) as soon as they
    are saved, looked for every ``poll`` s.

    Raises:
        WriterStopped: the stop file appeared, the chunk directory went, or ``wanted()`` turned False.
    """
    folder = store.chunk_dir(study_id)
    path = folder / f"{int(k)}.npz"
    stop = folder / STOP_FILE
    while True:
        if path.is_file():
            return store.load_chunk(study_id, k)
        if stop.exists() or not folder.is_dir() or not wanted():
            raise WriterStopped(f"study {study_id}: the dataset's writer was stopped at chunk {k}")
        time.sleep(poll)


def write_as_chunks_land(store_root: str, study_id: str, run_json: str, attrs_json: str) -> int | None:
    """The Dask task that writes a study's staged dataset as its chunks are saved (see the module
    docstring); the number of cases that did not end OK, or None when this worker does not see the store
    or the writer was stopped."""
    store = Store(store_root, catalog=False)
    chunks = store.load_chunk_plan(study_id)
    if chunks is None:  # this worker does not see the store
        return None
    wanted = _leave_thread_pool()
    run = study_from_json(run_json)
    iso_names, point_names = study_labels(run)
    failed: dict[int, int] = {}

    def load(k: int) -> Mapping[str, np.ndarray]:
        arrays = wait_for_chunk(store, study_id, k, wanted)
        failed[k] = int(np.count_nonzero(np.asarray(arrays["status"]) != OK))
        return arrays

    try:
        ds = streamed_dataset(
            load,
            chunks,
            run.design(),
            isolator_names=iso_names,
            point_names=point_names,
            attrs=json.loads(attrs_json),
            criteria=run.criteria,
            block_cases=LANDING_BLOCK_CASES,
        )
        store.write_dataset(study_id, ds, staged=True)
    except WriterStopped as stopped:
        log.info("%s", stopped)
        return None
    return sum(failed.values())


def _leave_thread_pool() -> Callable[[], bool]:
    """Leave the Dask worker's thread pool when running as its task (the worker then runs another task
    beside this one); returns whether Dask still wants the task (always True outside a worker)."""
    try:
        from distributed import get_worker, secede
        from distributed.worker import thread_state

        worker = get_worker()
        key = thread_state.key
    except (ImportError, ValueError, AttributeError):  # not a task of a Dask worker
        return lambda: True
    secede()

    def wanted() -> bool:
        task = worker.state.tasks.get(key)
        return task is not None and task.state in ("executing", "long-running")

    return wanted
