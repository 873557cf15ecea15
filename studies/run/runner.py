"""Running a study end to end: plan the chunks, fan them out over Dask, build the dataset, store it.

Where the work runs: this process plans and follows the Dask tasks and keeps the catalog. A worker that sees
the store saves each chunk it computes; one of them writes the dataset as the chunks land, beside the chunks
still computing (:mod:`studies.run.landing`), or, for a study of few cases or chunks, assembles and writes
it at the end (:func:`finish_study`); a worker that does not see the store (another machine, no shared
volume) hands its results back and this process does both.

:func:`run_study` is what the service calls for each submitted study; :func:`run_local` runs a study
file on a private LocalCluster (the CLI and notebooks); :func:`make_client` is the default Dask client.

A run saves every chunk as it arrives (``<id>.chunks/<k>.npz``, see :class:`studies.results.store.Store`), so
calling :func:`run_study` again with the same ``study_id`` after an interruption (cancel, crash, restart)
computes only the chunks that are not saved yet. The chunk split itself is saved with the first chunk, so a
resumed run splits the cases the same way even on a cluster of another size.

Around the fan-out (see :mod:`studies.run.accuracy`): a study that asks for an accuracy instead of naming its
model gets the cheapest fidelity, integrator and step that meets it, measured on pilot cases on a worker
before the chunks run (the chunks then run the resolved definition); and every dataset carries its
measured error, from a seeded sample of cases rerun at the reference level on the same client.

An ``optimize`` design does not plan its cases: once its model is resolved, :func:`run_study` hands it to
:func:`studies.run.optimisation.run_optimisation`, which runs it a generation at a time through the same
fan-out and keeps its own journal in the study's chunk directory.
"""

from __future__ import annotations

import json
import logging
import os
import tempfile
import threading
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from isolab.studies.inputs.study import Study, study_from_json, study_labels
from isolab.studies.questions.criteria import add_criteria
from isolab.studies.questions.tolerances import add_reliability
from isolab.studies.results.dataset import add_error_estimate, from_chunks, to_dataset
from isolab.studies.results.store import Store, StoreFull, copy_atomic, failures, is_no_space, utc_now
from isolab.studies.results.streaming import streamed_dataset
from isolab.studies.results.timings import record_timing
from isolab.studies.run.accuracy import (
    Choice,
    cached_choice,
    choose,
    choose_from_json,
    remember_choice,
    resolved_definition,
)
from isolab.studies.run.costs import estimate_seconds_per_case
from isolab.studies.run.error_estimate import (
    ESTIMATED_OUTPUTS,
    OUTPUT_MEANING,
    OUTPUT_UNITS,
    REFERENCE_PAIR,
    ErrorEstimate,
    error_sample,
    estimate_errors,
    exact_estimate,
    reference_method,
    reference_pair,
    sample_arrays,
)
from isolab.studies.run.fanout import (
    TASK_RETRIES,
    checked_workers,
    choose_chunk_size,
    local_cluster,
    local_cluster_arguments,
    plan_chunks,
    run_chunks,
    worker_threads,
)
from isolab.studies.run.landing import (
    WRITER_PRIORITY,
    clear_stop,
    lands,
    stop_writer,
    write_as_chunks_land,
)
from isolab.studies.run.optimisation import run_optimisation

if TYPE_CHECKING:  # xarray loads with the first dataset built
    import xarray as xr

log = logging.getLogger(__name__)

Progress = Callable[[int, int], None]


def run_study(
    study: Study,
    store: Store,
    client: Any,
    study_id: str | None = None,
    progress: Progress | None = None,
    cancel: threading.Event | None = None,
    *,
    chunk_size: int | None = None,
) -> str:
    """Run every case of ``study`` on ``client`` and store the dataset; returns the study id.

    Args:
        study: a :class:`studies.inputs.study.Study`.
        store: where the catalog row, chunks and dataset go.
        client: a ``dask.distributed.Client``.
        study_id: an existing catalog row to run (or resume); None creates one.
        progress: called as ``progress(done_cases, total_cases)``.
        cancel: set it to stop: outstanding chunks are cancelled, finished ones stay saved, the study is
            marked ``cancelled`` and can be resumed by calling again with its id.
        chunk_size: cases per chunk (default: :func:`studies.run.fanout.choose_chunk_size`); ignored when
            resuming a run whose split is saved.

    The catalog row goes ``running`` (``started`` is the first start, kept on resume), then
    ``done``/``cancelled``/``failed`` (with ``finished``; ``error`` says why it failed); ``n_done`` and
    ``n_failed`` follow the chunks as they arrive.

    Raises:
        Whatever stopped the run (the row is marked ``failed`` first), e.g. FanoutError when every chunk
        failed.
    """
    from isolab.engine import __version__ as engine_version

    definition = study.model_dump(mode="json")
    # keys keep their order: the order of points in the definition is the order of the point labels
    definition_json = json.dumps(definition)
    n_cases = int(study.planned_cases)  # an optimize design: its budget
    sim = study.simulation
    if study_id is None:
        study_id = store.register(study)
    record = store.get(study_id)  # exists, and the id is valid
    store.restore_reserve()  # room to record a failure should the disk fill (see Store.release_reserve)
    store.update(study_id, status="running", started=record.started or utc_now(), finished=None, error=None)
    try:
        # an accuracy request is resolved before the fan-out: the chunks run the chosen model
        choice = _choice(client, study, definition_json, cancel, f"isolab-{study_id}")
        if choice is None:
            store.update(study_id, status="cancelled", finished=utc_now())
            return study_id
        if choice.request is None:
            run_json, run = definition_json, study
        else:
            run_json = json.dumps(resolved_definition(study, choice))
            run = study_from_json(run_json)
            store.update(study_id, fidelity=choice.fidelity, integrator=choice.integrator, dt=choice.dt)
        if study.goals is not None:  # optimize: the optimiser picks the cases, a generation at a time
            model = {"engine_version": engine_version, **choice.attrs(), "auto_step": bool(sim.auto_step)}
            return run_optimisation(
                study, run_json, store, client, study_id, model, worker_threads(client), progress, cancel
            )
        chunks = store.load_chunk_plan(study_id)
        if chunks is None or int(sum(len(c) for c in chunks)) != n_cases:
            store.clear_chunks(study_id)
            size = chunk_size or choose_chunk_size(
                n_cases, worker_threads(client), estimate_seconds_per_case(run)
            )
            chunks = plan_chunks(n_cases, size)
            store.save_chunk_plan(study_id, chunks)
        saved = store.load_chunks(study_id, fields=("indices", "status"))  # not the outputs
        skip = {
            k
            for k, arrays in saved.items()
            if k < len(chunks) and np.array_equal(arrays.get("indices", chunks[k]), chunks[k])
        }
        counts = {k: _counts(saved[k]) for k in skip}

        def on_chunk(k: int, arrays: dict[str, np.ndarray]) -> None:
            if "saved" not in arrays:  # a worker that does not see the store, or a failed chunk
                store.save_chunk(study_id, k, arrays)
            counts[k] = _counts(arrays)
            store.update(
                study_id,
                n_done=sum(c[0] for c in counts.values()),
                n_failed=sum(c[1] for c in counts.values()),
            )

        store.update(
            study_id, n_done=sum(c[0] for c in counts.values()), n_failed=sum(c[1] for c in counts.values())
        )
        if skip:
            log.info("study %s: resuming, %d of %d chunks already done", study_id, len(skip), len(chunks))
        # the error estimate's sampled cases run in the run's tail and beside the dataset's writing: sent
        # once every chunk is out, just below them
        sampled: list[Samples] = []

        def submit_samples(priority: int) -> None:
            sampled.append(_submit_samples(client, run, run_json, f"isolab-{study_id}", priority))

        attrs = {
            "title": f"isolab study {study.name}",
            "study": definition_json,
            "study_id": study_id,
            "design": _design_extra(study),
            "engine_version": engine_version,
            **choice.attrs(),
            "auto_step": bool(sim.auto_step),
        }
        # the dataset is written as the chunks land (studies.run.landing), when the study has enough of them
        writer = _start_writer(client, store, study_id, run, run_json, attrs, chunks, skip)
        report = run_chunks(
            client,
            run_json,
            chunks,
            skip=skip,
            on_chunk=on_chunk,
            progress=progress,
            cancel=cancel,
            key_prefix=f"isolab-{study_id}",
            store_target=(str(store.root), study_id),
            on_dispatched=submit_samples,
        )
        if report.cancelled:
            _stop(client, store, study_id, writer, [f for s in sampled for f in s[1]])
            store.update(study_id, status="cancelled", finished=utc_now())
            return study_id

        # the dataset is written by a worker that sees the store as the chunks land (the landing writer),
        # or else assembled and written on such a worker now (the results and the netCDF compression stay
        # out of this process, which serves requests: the load benchmark's p99 went from 70-146 ms to
        # 46-67 ms), else here; the error estimate's sampled cases run in the run's tail: when they are
        # done already before a finish starts, it writes the dataset with the estimate, else the ones left
        # run on the other workers meanwhile, and the estimate's figures are added to the written file after
        if not sampled:  # every chunk was done already (a resumed run)
            submit_samples(1)
        samples = sampled[0]
        landed = _wait(client, writer, cancel) if writer is not None else None
        ready = future = None
        if landed is None and not (cancel is not None and cancel.is_set()):
            if all(f.done() for f in samples[1]):
                ready = _error_estimate(client, run, samples, cancel)
            future = client.submit(
                finish_study,
                str(store.root),
                study_id,
                run_json,
                json.dumps(attrs),
                ready,
                pure=False,
                retries=TASK_RETRIES,
                priority=1,
                key=f"isolab-{study_id}-finish-{uuid.uuid4().hex[:8]}",
            )
        estimate = ready if ready is not None else _error_estimate(client, run, samples, cancel)
        n_failed = landed
        if landed is None and future is not None and estimate is not None:
            n_failed = _wait(client, future, cancel)
        if estimate is None or (cancel is not None and cancel.is_set()):
            _stop(client, store, study_id, writer, [f for f in (future,) if f is not None] + samples[1])
            store.update(study_id, status="cancelled", finished=utc_now())
            return study_id
        if n_failed is None:  # the worker does not see the store: finished here
            n_failed = assemble_dataset(store, study_id, run_json, attrs, estimate)
        elif ready is None:
            store.publish_dataset(study_id, estimate_dataset(estimate))
        if n_cases and int(n_failed) >= n_cases:  # not one case has a result: the study failed, saying why
            reason = f"every case failed ({failures(store.path(study_id))})"
            store.clear_chunks(study_id)
            store.update(
                study_id, status="failed", finished=utc_now(), n_done=n_cases, n_failed=n_cases, error=reason
            )
            return study_id
        store.update(study_id, status="done", finished=utc_now(), n_done=n_cases, n_failed=int(n_failed))
        try:  # after: the study is done 4 ms sooner; what is left, Store.sweep_chunks removes at a start
            store.clear_chunks(study_id)
        except OSError:
            log.warning("study %s: its chunks stay until the next start", study_id, exc_info=True)
        return study_id
    except BaseException as err:
        stop_writer(store, study_id)  # a landing writer still waiting for chunks writes nothing
        text = f"{type(err).__name__}: {err}"
        if is_no_space(err):  # "no space left on device: writing <id>.nc needs about N MB, ..."
            text = str(err) if isinstance(err, StoreFull) else f"no space left on device: {text}"
            store.release_reserve()  # room for the catalog to record it
        try:
            store.update(study_id, status="failed", finished=utc_now(), error=text)
        except Exception:  # the catalog itself failed: report the original error
            log.exception("study %s: could not mark the study failed", study_id)
        raise


IN_MEMORY_CASES = 200_000
"""Largest study whose dataset is assembled whole in memory (about 1.2 GB in the worker at this size);
larger ones are streamed chunk by chunk. ``ISOLAB_IN_MEMORY_CASES`` in the environment overrides it."""


def assemble_dataset(
    store: Store, study_id: str, run_json: str, attrs: dict[str, Any], estimate: ErrorEstimate | None
) -> int:
    """Build a study's dataset from its saved chunks, add the error ``estimate`` and write it atomically;
    the number of cases that did not end OK. Without an estimate the dataset is written staged
    (:meth:`studies.results.store.Store.staged_path`), for
    :meth:`~studies.results.store.Store.publish_dataset` to add the estimate's variables
    (:func:`estimate_dataset`) and move it into place.

    Up to ``IN_MEMORY_CASES`` cases the dataset is built whole in memory and written at once (fastest:
    0.3 s of CPU for 100,000 cases, compressing only the variables that shrink). Beyond, it is streamed
    (:func:`studies.results.streaming.streamed_dataset`): each chunk is read when its slice is written and
    let go after, so the memory this takes does not grow with the number of cases (only the statuses, 1 byte
    a case, and the parameter values, 8 bytes a case per parameter, are held), at about twice the CPU of
    the write in memory (0.4 s at 100,000 cases)."""

    run = study_from_json(run_json)
    iso_names, point_names = study_labels(run)
    chunks = store.load_chunk_plan(study_id)
    if chunks is None:
        raise RuntimeError(f"study {study_id}: its chunk plan is missing from the store")
    n_cases = sum(len(c) for c in chunks)
    if n_cases <= int(os.environ.get("ISOLAB_IN_MEMORY_CASES", IN_MEMORY_CASES)):
        result = from_chunks(
            store.load_chunks(study_id), chunks, n_isolators=len(iso_names), n_points=len(point_names)
        )
        n_failed = int(np.count_nonzero(result.status != 0))
        ds = to_dataset(result, run.design(), isolator_names=iso_names, point_names=point_names, attrs=attrs)
        ds = add_criteria(ds, run.criteria)
    else:
        statuses = store.load_chunks(study_id, fields=("status",))
        missing = [k for k in range(len(chunks)) if k not in statuses]
        if missing:
            raise ValueError(f"study {study_id}: chunks {missing} have no results")
        n_failed = sum(int(np.count_nonzero(statuses[k]["status"] != 0)) for k in range(len(chunks)))
        del statuses
        ds = streamed_dataset(
            lambda k: store.load_chunk(study_id, k),
            chunks,
            run.design(),
            isolator_names=iso_names,
            point_names=point_names,
            attrs=attrs,
            criteria=run.criteria,
        )
    if run.spreads:  # a monte_carlo design: the probability of meeting the criteria within tolerances
        ds = add_reliability(ds, run.spreads, run.design_spec.sampling or "sobol")
    if estimate is not None:
        ds = with_estimate(ds, estimate)
    store.write_dataset(study_id, ds, staged=estimate is None)  # a streamed one: chunk by chunk
    return n_failed


def with_estimate(ds: xr.Dataset, estimate: ErrorEstimate) -> xr.Dataset:
    """``ds`` with the variables and attributes of a study's error ``estimate``
    (:func:`studies.results.dataset.add_error_estimate`)."""
    return add_error_estimate(
        ds,
        estimate.values,
        worst_case=estimate.worst_case,
        cases=estimate.cases,
        excluded=estimate.excluded,
        method=estimate.method,
        meaning=OUTPUT_MEANING,
        units=OUTPUT_UNITS,
    )


def estimate_dataset(estimate: ErrorEstimate) -> xr.Dataset:
    """The variables and attributes a study's error ``estimate`` adds to its dataset, alone."""
    import xarray as xr

    return with_estimate(xr.Dataset(), estimate)


def finish_study(
    store_root: str, study_id: str, run_json: str, attrs_json: str, estimate: ErrorEstimate | None = None
) -> int | None:
    """The Dask task that finishes a study on a worker (:func:`assemble_dataset`; staged without an
    ``estimate``); None when this worker does not see the store, so the runner finishes."""
    record_timing("finish_start", study_id=study_id)
    store = Store(store_root, catalog=False)
    if not store.has_chunk_plan(study_id):
        return None
    return assemble_dataset(store, study_id, run_json, json.loads(attrs_json), estimate)


def _start_writer(
    client: Any,
    store: Store,
    study_id: str,
    run: Study,
    run_json: str,
    attrs: dict[str, Any],
    chunks: list[np.ndarray],
    skip: set[int],
) -> Any:
    """The Dask future of the study's landing writer (:func:`studies.run.landing.write_as_chunks_land`),
    or None when the dataset is better written after the run: a study of too few cases or chunks left to
    compute to write any while others compute, or one whose dataset needs every case at once (the
    tolerance analysis of a ``monte_carlo`` design)."""
    if run.spreads or not lands([len(c) for k, c in enumerate(chunks) if k not in skip]):
        return None
    clear_stop(store, study_id)  # a stop left by a cancelled run of this study
    return client.submit(
        write_as_chunks_land,
        str(store.root),
        study_id,
        run_json,
        json.dumps(attrs),
        pure=False,
        retries=TASK_RETRIES,
        priority=WRITER_PRIORITY,
        key=f"isolab-{study_id}-writer-{uuid.uuid4().hex[:8]}",
    )


def _stop(client: Any, store: Store, study_id: str, writer: Any, futures: list[Any]) -> None:
    """Cancel a run's outstanding ``futures`` and its landing ``writer`` (which writes nothing)."""
    stop_writer(store, study_id)
    client.cancel([*futures, *([writer] if writer is not None else [])])


def _wait(client: Any, future: Any, cancel: threading.Event | None) -> Any:
    """The result of a Dask future, as soon as it is done; None (and the future cancelled) when ``cancel``
    is set first (looked at every 50 ms)."""
    ended = threading.Event()
    future.add_done_callback(lambda _: ended.set())
    while not future.done():
        if cancel is not None and cancel.is_set():
            client.cancel([future])
            return None
        ended.wait(0.05)
    return future.result()


def _choice(
    client: Any, study: Study, definition_json: str, cancel: threading.Event | None, key_prefix: str
) -> Choice | None:
    """The fidelity, integrator and step to run with: the study's own, or measured for its accuracy
    request on a worker (:func:`studies.run.accuracy.choose`); None when cancelled meanwhile."""
    if study.simulation.request is None or study.simulation.accuracy == "reference":
        return choose(study)
    known = cached_choice(study)
    if known is not None:
        return known
    future = client.submit(
        choose_from_json, definition_json, pure=False, key=f"{key_prefix}-accuracy-{uuid.uuid4().hex[:8]}"
    )
    choice = _wait(client, future, cancel)
    if choice is not None:
        remember_choice(study, choice)
    return choice


Samples = tuple[list[int], list[Any], tuple[str, str]]
"""An error estimate's sampled cases, the Dask futures of their reruns (none when the study runs at its
reference level) and the reference level they rerun at (fidelity, integrator)."""


def _submit_samples(client: Any, study: Study, run_json: str, key_prefix: str, priority: int) -> Samples:
    """The error estimate's seeded sample of cases, their reruns
    (:func:`studies.run.error_estimate.sample_arrays` as Dask tasks at ``priority``: the cases split in
    order over the workers but one, one task each, so that the worker that ends the last chunk is free
    for the task that finishes the study; none for a study that runs at its reference level itself) and
    the reference they rerun at (:func:`studies.run.error_estimate.reference_pair` of the sampled cases:
    the nonlinear level does not model a scene's extra linear states).

    On the service's two workers the four cases of a study rerun as one task beside the task that
    finishes the study (one engine call per level instead of four: 0.105 against 0.124 s of CPU, and one
    worker's share of the tail against the finish's other: a 10,000-case study 47 ms sooner, median of 16
    alternated pairs); on a larger cluster they spread over the idle workers."""
    cases = error_sample(study)
    try:
        pair = reference_pair(study.batch(np.array(cases)))
    except ValueError:  # a scene the engine refuses: its chunks and reruns report why
        pair = REFERENCE_PAIR
    if (study.simulation.fidelity, study.simulation.integrator) == pair:
        return cases, [], pair
    token = uuid.uuid4().hex[:8]

    def submit(group: list[int]) -> Any:
        return client.submit(
            sample_arrays,
            run_json,
            group,
            pair,
            pure=False,
            priority=priority,
            key=f"{key_prefix}-sample-{group[0]}-{token}",
        )

    free = max(1, worker_threads(client) - 1)  # the workers besides the one that finishes the study
    groups = [g.tolist() for g in np.array_split(np.asarray(cases), min(len(cases), free))]
    return cases, [submit(g) for g in groups], pair


def _error_estimate(
    client: Any,
    study: Study,
    samples: Samples,
    cancel: threading.Event | None,
) -> ErrorEstimate | None:
    """The largest error per output over the sampled cases (see :func:`_submit_samples`); None when
    ``cancel`` is set while waiting for them."""
    cases, futures, pair = samples
    _, points = study_labels(study)
    outputs = [o for o in ESTIMATED_OUTPUTS if o != "peak_point_displacement" or len(points) > 0]
    if not futures:
        return exact_estimate(cases, outputs, pair)
    try:
        parts = [_wait(client, f, cancel) for f in futures]
    except Exception as err:  # the study's own results stand; the estimate says why it is missing
        log.exception("error estimate: the sampled cases failed")
        nan = {o: float("nan") for o in outputs}
        return ErrorEstimate(
            nan,
            {o: None for o in outputs},
            tuple(cases),
            {c: f"reference rerun failed: {type(err).__name__}: {err}" for c in cases},
            "reference reruns failed",
        )
    if any(p is None for p in parts):
        return None
    ours = {k: np.concatenate([np.asarray(p["ours"][k]) for p in parts]) for k in parts[0]["ours"]}
    reference = {
        k: np.concatenate([np.asarray(p["reference"][k]) for p in parts]) for k in parts[0]["reference"]
    }
    return estimate_errors(
        ours, reference, cases, outputs, method=reference_method(pair), integrator=study.simulation.integrator
    )


def _counts(arrays: dict[str, np.ndarray]) -> tuple[int, int]:
    status = np.asarray(arrays["status"])
    return int(status.size), int(np.count_nonzero(status != 0))


def _design_extra(study: Study) -> dict[str, Any]:
    """What the design summary adds from the study's ``design:`` block (type, samples, seed; saltelli:
    second_order and, when given, replicates, which the sensitivity analysis reads)."""
    dump = study.design_spec.model_dump(mode="json")
    if dump.get("type") == "saltelli":
        dump["second_order"] = bool(dump.get("second_order"))
    keys = ("type", "seed", "samples", "second_order", "replicates")
    return {k: v for k, v in dump.items() if k in keys and v is not None}


def make_client(
    scheduler_address: str | None = None, workers: int = 2, *, dashboard_address: str | None = None
):
    """A Dask client: to ``scheduler_address``, else ``DASK_SCHEDULER_ADDRESS`` / dask's
    ``scheduler-address`` config, else a new LocalCluster of ``workers`` processes with one thread each
    (:func:`studies.run.fanout.local_cluster_arguments`: on loopback; closed with the client; Dask's
    dashboard on ``dashboard_address``, ``"127.0.0.1:<port>"``, none by default)."""
    import dask
    from dask.distributed import Client

    address = (
        scheduler_address
        or os.environ.get("DASK_SCHEDULER_ADDRESS")
        or dask.config.get("scheduler-address", None)
        or dask.config.get("distributed.scheduler-address", None)
    )
    if address:
        return Client(address)
    config, arguments = local_cluster_arguments(workers, dashboard_address)
    with dask.config.set(config):
        return Client(**arguments)  # the client's own cluster: closed with it


def run_local(
    source: str | Path | dict[str, Any] | Study,
    out_path: str | Path,
    workers: int = 2,
    progress: Progress | None = None,
    store: Store | None = None,
) -> xr.Dataset:
    """Run a study (YAML/JSON file, text or dict, as :func:`studies.inputs.study.load_study` takes, or a
    validated
    :class:`studies.inputs.study.Study`) on a private LocalCluster of ``workers`` processes (one thread each)
    and
    write its dataset to ``out_path`` atomically, with the mode a new file gets under the umask. Uses
    ``store`` if given (the study stays in its catalog), else a temporary one. Returns the dataset (loaded
    in memory)."""
    from dask.distributed import Client

    from isolab.studies.inputs.study import load_study

    workers = checked_workers(workers)  # before the study is read
    study = source if isinstance(source, Study) else load_study(source)
    with tempfile.TemporaryDirectory(prefix="isolab-") as tmp:
        own = store if store is not None else Store(Path(tmp))
        with local_cluster(workers) as cluster, Client(cluster) as client:
            study_id = run_study(study, own, client, progress=progress)
        copy_atomic(own.path(study_id), out_path)
        return own.open_dataset(study_id)
