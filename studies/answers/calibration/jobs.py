"""Calibrations as jobs: checked and priced at once, fitted on the Dask workers, stopped on request.

A request is checked and its engine time estimated without running the engine (:func:`price_request`);
one over :data:`MAX_CALIBRATION_SECONDS` is refused. :class:`CalibrationJobs` stores an accepted one
(:class:`isolab.studies.results.calibrations.CalibrationStore`) and runs it as one Dask task
(:func:`calibration_task`) on a worker, never in the service's process. The task reports progress (engine
batches and cases) through a Dask ``Variable`` before each engine batch and looks at a Dask ``Event``
there too: set, the fit stops at its next engine batch (within one batch's time, seconds). A fit that
runs past :data:`TIME_LIMIT_SECONDS` stops the same way and the job fails saying so. At start the jobs a
stopped service left queued or running are submitted again (a fit starts over: it is short and
deterministic, so the answer is the same).

The answer is :meth:`isolab.studies.answers.calibration.Calibration.to_json`'s, the same numbers as a
calibration run directly; ``draw`` (given by the service: the figure lives above this layer) adds the
base64 PNG ``plot_png`` on the worker when the request asks for it.
"""

from __future__ import annotations

import base64
import logging
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from pydantic import BaseModel, Field

from isolab.studies.answers.calibration.fit import PreparedFit
from isolab.studies.answers.calibration.requests import prepare_request
from isolab.studies.inputs.definitions import DefinitionError, detail
from isolab.studies.results.calibrations import UNFINISHED_JOBS, CalibrationNotFound, CalibrationStore
from isolab.studies.results.catalog import utc_now
from isolab.studies.run.costs import step_cost

log = logging.getLogger(__name__)

MAX_CALIBRATION_SECONDS = 300.0
"""Largest estimated engine time of one calibration, s of one core: a request above it is refused (422)."""
TIME_LIMIT_SECONDS = 2 * MAX_CALIBRATION_SECONDS
"""A calibration still fitting after this long stops and fails, s (the estimate is rough)."""
CALL_OVERHEAD = 0.08
"""Fixed time of one engine batch of a calibration (building the batch, interpolating, filtering), s."""
PROGRESS_INTERVAL = 1.0
"""How often the service reads the running jobs' progress, s."""
MAX_TRACE_POINTS = 2000
"""Most samples per trace a stored answer keeps (:func:`decimated_traces`)."""

Draw = Callable[[dict[str, Any], dict[str, Any]], bytes]
"""``draw(traces, answer)``: a PNG of measured against simulated traces."""


class CalibrationStopped(Exception):
    """A calibration's fit stopped before its end: cancelled, or past its time limit (the message)."""


@dataclass(frozen=True)
class CalibrationCost:
    """The estimated engine work of a calibration.

    Attributes:
        seconds: engine time on one core, s.
        engine_calls: engine batches the fit is expected to run.
        cases: cases over all batches.
        steps_per_case: engine steps of one case (the simulated duration over ``dt``).
        limit_seconds: the largest estimate accepted, s.
    """

    seconds: float
    engine_calls: int
    cases: int
    steps_per_case: int
    limit_seconds: float = MAX_CALIBRATION_SECONDS

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


class ChannelTrace(BaseModel):
    """One measured channel against the simulation, as the fit saw it (SI)."""

    name: str = Field(description="the channel, e.g. cg.y")
    unit: str = Field(description="the unit the measurement was written in")
    factor: float = Field(description="SI per that unit: divide a value by it to read it in that unit")
    measured: list[float | None] = Field(description="the measurement, SI")
    before: list[float | None] = Field(description="the scene as given (aligned by the offset scan), SI")
    after: list[float | None] = Field(description="the calibrated scene, SI")


class CalibrationTraces(BaseModel):
    """Measured against simulated traces of a calibration, every ``every``-th sample."""

    time: list[float] = Field(description="measurement time, s")
    every: int = Field(description="one sample kept in every this many of the fit's")
    channels: list[ChannelTrace]


def _values(a: Any, every: int) -> list[float | None]:
    x = np.asarray(a, dtype=np.float64).reshape(-1)[::every]
    return [float(v) if np.isfinite(v) else None for v in x]


def decimated_traces(traces: Mapping[str, Any], max_points: int = MAX_TRACE_POINTS) -> dict[str, Any]:
    """The traces of a fit (:attr:`isolab.studies.answers.calibration.Calibration.traces`) as JSON-able
    data (:class:`CalibrationTraces`), every ``every``-th sample kept so that at most ``max_points``
    remain (the traces are the filtered ones the fit compared, so thinning them draws the same lines)."""
    t = np.asarray(traces["time"], dtype=np.float64).reshape(-1)
    every = max(1, -(-t.size // max(int(max_points), 1)))
    return {
        "time": [float(v) for v in t[::every]],
        "every": every,
        "channels": [
            {
                "name": str(ch["name"]),
                "unit": str(ch.get("unit") or ""),
                "factor": float(ch.get("factor") or 1.0),
                "measured": _values(ch["measured"], every),
                "before": _values(ch["before"], every),
                "after": _values(ch["after"], every),
            }
            for ch in traces["channels"]
        ],
    }


def estimate_cost(prepared: PreparedFit) -> CalibrationCost:
    """The engine work of ``prepared``'s fit: with ``P`` fitted parameters, about ``2 (P+1)(P+4)`` engine
    batches of ``(P+1)(P+2)(P+4)`` cases in all (more parameters take more iterations, and one that the
    measurement does not determine takes a fit again without it), and about half that again for each
    start beyond the first (``starts``: one fit each, without the second pass), each case
    ``duration / dt`` steps at :func:`studies.run.costs.step_cost` of the fit's model. Rough: a factor of
    two either way."""
    model = prepared.model
    p = len(prepared.params)
    extra = prepared.starts - 1  # each further start: one case to scan its offset, then about a fit
    calls = 2 * (p + 1) * (p + 4) + extra * (1 + (p + 1) * (p + 4))
    cases = (p + 1) * (p + 2) * (p + 4) + extra * (1 + (p + 1) * (p + 2) * (p + 4) // 2)
    steps = max(1, round(model.duration / model.choice.dt))
    per_case = steps * step_cost(model.choice.fidelity, model.choice.integrator) + 1e-3
    return CalibrationCost(calls * CALL_OVERHEAD + cases * per_case, calls, cases, steps)


def price_request(body: Mapping[str, Any], limit: float = MAX_CALIBRATION_SECONDS) -> CalibrationCost:
    """Check a request body (every refusal :func:`calibrate_request` would make before the engine runs) and
    estimate its cost; raises :class:`DefinitionError` when the estimate exceeds ``limit`` s."""
    cost = estimate_cost(prepare_request(body))
    cost = CalibrationCost(cost.seconds, cost.engine_calls, cost.cases, cost.steps_per_case, float(limit))
    if cost.seconds > limit:
        choice = prepare_request(body).model.choice
        raise DefinitionError(
            [
                detail(
                    ["body"],
                    f"this calibration would take about {cost.seconds:.0f} s of engine time ({cost.cases} "
                    f"cases of {cost.steps_per_case} steps, {choice.fidelity}/{choice.integrator}), more "
                    "than "
                    f"the limit of {limit:.0f} s: fit fewer parameters (fit), give a shorter measurement "
                    "(measurement.time), a longer step (simulation.dt) or a cheaper model "
                    "(simulation.fidelity: lti, simulation.integrator: exact)",
                    "value_error.too_costly",
                )
            ]
        )
    return cost


def cancel_name(job_id: str) -> str:
    """The Dask ``Event`` that stops job ``job_id``'s fit."""
    return f"isolab-calibration-{job_id}-cancel"


def progress_name(job_id: str) -> str:
    """The Dask ``Variable`` holding job ``job_id``'s progress."""
    return f"isolab-calibration-{job_id}-progress"


def calibration_task(
    body: dict[str, Any], job_id: str, draw: Draw | None = None, time_limit: float = TIME_LIMIT_SECONDS
) -> dict[str, Any]:
    """Run on a Dask worker: the calibration of ``body``, its answer as JSON (``plot_png`` drawn by
    ``draw`` when the request asks for a plot). Raises :class:`CalibrationStopped` when job ``job_id``'s
    cancel event is set or the fit runs past ``time_limit`` s, :class:`DefinitionError` on a refusal."""
    from distributed import Event, Variable

    stop, progress = Event(cancel_name(job_id)), Variable(progress_name(job_id))
    started = time.monotonic()

    def watch(calls: int, cases: int) -> None:
        if stop.is_set():
            raise CalibrationStopped("cancelled")
        if time.monotonic() - started > time_limit:
            raise CalibrationStopped(f"stopped after {time_limit:.0f} s, the time limit of a calibration")
        progress.set({"engine_calls": calls, "cases": cases})

    watch(0, 0)
    prepared = prepare_request(body)
    prepared.model.watch = watch
    result = prepared.run()
    answer = result.to_json()
    answer["traces"] = decimated_traces(result.traces)
    answer["plot_png"] = None
    if body.get("plot", True) and draw is not None:
        answer["plot_png"] = base64.b64encode(draw(result.traces, answer)).decode("ascii")
    return answer


def _failure(err: BaseException) -> str:
    if isinstance(err, DefinitionError):
        return "; ".join(str(d.get("msg", d)) for d in err.details)
    if isinstance(err, CalibrationStopped):
        return str(err)
    return f"{type(err).__name__}: {err}"


class CalibrationJobs:
    """The calibration jobs of one service: stored in ``store``, run on ``client``'s Dask workers.

    Args:
        store: where the jobs live.
        client: the service's ``distributed.Client``.
        draw: draws a job's plot on the worker (None: no plot).
        time_limit: seconds a fit may run before it stops and fails.
    """

    def __init__(
        self,
        store: CalibrationStore,
        client: Any,
        draw: Draw | None = None,
        time_limit: float = TIME_LIMIT_SECONDS,
    ):
        self.store = store
        self.client = client
        self.draw = draw
        self.time_limit = float(time_limit)
        self._lock = threading.Lock()
        self._futures: dict[str, Any] = {}
        self._stopping = threading.Event()
        self._monitor: threading.Thread | None = None

    # ------------------------------------------------------------------------------------ life cycle
    def start(self) -> list[str]:
        """Submit again every stored job left queued or running; start reading progress. Returns their ids."""
        self._stopping.clear()
        resumed = self.store.ids(UNFINISHED_JOBS)
        for job_id in resumed:
            self.store.update(job_id, status="queued", started=None)
            self._launch(job_id)
        self._monitor = threading.Thread(target=self._watch, name="isolab-calibrations", daemon=True)
        self._monitor.start()
        if resumed:
            log.info("resuming %d calibrations: %s", len(resumed), ", ".join(resumed))
        return resumed

    def stop(self) -> None:
        """Stop the running fits (their jobs stay stored as queued: the next start runs them again)."""
        self._stopping.set()
        with self._lock:
            futures, self._futures = self._futures, {}
        for job_id, future in futures.items():
            self._signal_stop(job_id, future)
            self.store.update(job_id, status="queued", started=None)
        if self._monitor is not None:
            self._monitor.join(5 * PROGRESS_INTERVAL)
            self._monitor = None

    # ------------------------------------------------------------------------------------- requests
    def submit(self, body: Mapping[str, Any], cost: CalibrationCost) -> dict[str, Any]:
        """Store and start a priced request (:func:`price_request`); the job's record."""
        if self._stopping.is_set():
            raise RuntimeError("the service is stopping; submit the calibration again later")
        job = self.store.create(body, cost.to_json())
        self._launch(job["id"])
        return job

    def delete(self, job_id: str) -> bool:
        """Stop the job's fit (its worker stops at its next engine batch) and remove the job; False when
        there is no such job."""
        with self._lock:
            future = self._futures.pop(job_id, None)
        if future is not None:
            self._signal_stop(job_id, future)
        return self.store.delete(job_id)

    # ---------------------------------------------------------------------------------- worker side
    def _launch(self, job_id: str) -> None:
        body = self.store.request(job_id)
        future = self.client.submit(
            calibration_task,
            body,
            job_id,
            self.draw,
            self.time_limit,
            key=f"isolab-calibration-{job_id}",
            pure=False,
        )
        with self._lock:
            self._futures[job_id] = future
        future.add_done_callback(lambda f: self._finished(job_id, f))

    def _signal_stop(self, job_id: str, future: Any) -> None:
        from distributed import Event

        try:
            Event(cancel_name(job_id), client=self.client).set()
            future.cancel()
        except Exception as err:  # the cluster is going away: its workers stop with it
            log.info("calibration %s: could not signal its worker (%s)", job_id, err)

    def _finished(self, job_id: str, future: Any) -> None:
        with self._lock:
            current: Any = self._futures.get(job_id)
            if current is not future:
                return  # deleted, or the service is stopping: the store says what happens next
            del self._futures[job_id]
        if future.status == "cancelled":
            return
        try:
            answer = future.result()
        except BaseException as err:
            log.warning("calibration %s failed: %s", job_id, _failure(err))
            self.store.update(job_id, status="failed", finished=utc_now(), error=_failure(err))
            return
        evaluations = dict(answer.get("evaluations") or {})
        progress = {"engine_calls": evaluations.get("engine_calls", 0), "cases": evaluations.get("cases", 0)}
        self.store.finish(job_id, answer, progress=progress)
        self._forget(job_id)

    def _forget(self, job_id: str) -> None:
        from distributed import Variable

        try:
            Variable(progress_name(job_id), client=self.client).delete()
        except Exception as err:  # only memory on the scheduler
            log.debug("calibration %s: progress variable not removed (%s)", job_id, err)

    def _watch(self) -> None:
        from distributed import Variable

        while not self._stopping.wait(PROGRESS_INTERVAL):
            with self._lock:
                running = list(self._futures)
            for job_id in running:
                try:
                    got = Variable(progress_name(job_id), client=self.client).get(timeout=0)
                except Exception:  # not started yet
                    continue
                try:
                    job = self.store.get(job_id)
                except CalibrationNotFound:  # deleted meanwhile
                    continue
                fields: dict[str, Any] = {"progress": dict(got)}
                if job["status"] == "queued":
                    fields.update(status="running", started=utc_now())
                if fields["progress"] != job["progress"] or "status" in fields:
                    self.store.update(job_id, when=UNFINISHED_JOBS, **fields)
