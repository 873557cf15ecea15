"""The service's study queue: studies run in background threads on the app's Dask client.

A :class:`JobQueue` belongs to one app (its lifespan starts and stops it). ``submit(id)`` queues a study
already in the catalog; a few worker threads take ids in order and run them with
:func:`studies.run.runner.run_study`, each with its own cancel event. The catalog is the source of truth:

* at start-up every study whose catalog status is ``queued`` or ``running`` is queued again, oldest
  first; it resumes from the chunks it had finished, so no study is silently lost;
* ``cancel(id)`` stops a queued or running study for good (status ``cancelled``);
* ``stop()`` interrupts running studies and puts them back to ``queued`` (never ``cancelled``), so the
  next start resumes them; studies waiting in the queue keep their ``queued`` status.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import queue
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

from isolab.studies.results.catalog import CATALOG_FILE, StudyNotFound, utc_now
from isolab.studies.results.store import Store, StudyFilter, StudyRecord

log = logging.getLogger(__name__)

#: Studies whose catalog status means "not finished": the queue takes them up again at start-up.
UNFINISHED = ("queued", "running")

RUNNING_STUDIES = 8
"""Studies the service runs at once (one thread each, mostly waiting for chunks). Their chunks share the
cluster chunk by chunk (see :mod:`studies.run.fanout`), so a small study submitted while large ones run waits
for one chunk, not for them to finish; more studies than this wait in the queue."""

_PAGE = 1000


def _default_runner(study: Any, store: Store, client: Any, study_id: str, cancel: threading.Event) -> str:
    from isolab.studies.run.runner import run_study

    return run_study(study, store, client, study_id=study_id, cancel=cancel)


def _default_loader(definition: Any) -> Any:
    from isolab.studies.inputs.study import parse_study

    # parsed only: a stored definition was checked when it was submitted, and has its scene inline
    return parse_study(definition)


class JobQueue:
    """Runs catalog studies in the background on one Dask client.

    Args:
        store: the study store (catalog, chunks, datasets), or its root directory: then the store is
            opened on first use (a data directory without a catalog stays untouched until a study comes).
        client: the app's ``distributed.Client``.
        concurrency: studies run at the same time (worker threads); their chunks share the cluster.
        runner: ``runner(study, store, client, study_id, cancel)`` runs one study (default
            :func:`studies.run.runner.run_study`).
        loader: turns a catalog definition into a study (default :func:`studies.inputs.study.load_study`).
    """

    def __init__(
        self,
        store: Store | str | Path,
        client: Any,
        concurrency: int = 2,
        runner: Callable[..., Any] | None = None,
        loader: Callable[[Any], Any] | None = None,
    ):
        if int(concurrency) < 1:
            raise ValueError(f"concurrency: {concurrency} must be at least 1")
        self._store = store if isinstance(store, Store) else None
        self._root = store.root if isinstance(store, Store) else Path(store)
        self._store_lock = threading.Lock()
        self.client = client
        self.concurrency = int(concurrency)
        self._runner = runner or _default_runner
        self._loader = loader or _default_loader
        self._queue: queue.Queue[str | None] = queue.Queue()
        self._lock = threading.Lock()
        self._pending: list[str] = []  # queued ids, in order, not yet taken by a worker thread
        self._running: dict[str, threading.Event] = {}  # id -> its cancel event
        self._finished: dict[str, threading.Event] = {}  # id -> set when its run returns
        self._listeners: dict[str, list[Callable[[], None]]] = {}  # id -> called when its run returns
        self._user_cancelled: set[str] = set()
        self._threads: list[threading.Thread] = []
        self._stopping = False
        #: Ids the last :meth:`start` took up again from the catalog.
        self.resumed: list[str] = []

    @property
    def store(self) -> Store:
        """The study store (opened now if it is not open yet)."""
        if self._store is None:
            with self._store_lock:
                if self._store is None:
                    self._store = Store(self._root)
        return self._store

    # ------------------------------------------------------------------------------------ life cycle
    def start(self) -> list[str]:
        """Queue every unfinished catalog study again (oldest first) and start the worker threads.

        Returns the ids taken up again.
        """
        if self._threads:
            raise RuntimeError("the job queue is already started")
        resumed = self._unfinished_ids()
        if self._has_catalog():
            self.store.sweep_chunks()  # what a stop between a study's end and its clean-up left
        self.resumed = list(resumed)
        with self._lock:
            self._stopping = False
            for study_id in resumed:
                self._enqueue_locked(study_id)
        for i in range(self.concurrency):
            thread = threading.Thread(target=self._work, name=f"isolab-study-{i}", daemon=True)
            thread.start()
            self._threads.append(thread)
        if resumed:
            log.info("resuming %d unfinished studies: %s", len(resumed), ", ".join(resumed))
        return resumed

    def stop(self, timeout: float = 60.0) -> None:
        """Interrupt running studies (they go back to ``queued`` and resume at the next start), then
        wait up to ``timeout`` seconds for the worker threads to end. Queued studies stay queued."""
        with self._lock:
            self._stopping = True
            self._pending.clear()
            for event in self._running.values():
                event.set()
        for _ in self._threads:
            self._queue.put(None)
        for thread in self._threads:
            thread.join(timeout)
            if thread.is_alive():
                log.warning("study thread %s did not stop within %.0f s", thread.name, timeout)
        self._threads = []

    def _has_catalog(self) -> bool:
        """The store is open or its catalog exists (a data directory without one stays untouched)."""
        return self._store is not None or (self._root / CATALOG_FILE).exists()

    def _unfinished_ids(self) -> list[str]:
        if not self._has_catalog():
            return []  # no catalog yet: nothing to resume
        rows: list[StudyRecord] = []
        for status in UNFINISHED:
            offset = 0
            while True:
                page = self.store.list(StudyFilter(status=status), limit=_PAGE, offset=offset)
                rows += page
                if len(page) < _PAGE:
                    break
                offset += _PAGE
        rows.sort(key=lambda r: r.created)
        return [r.id for r in rows]

    # ------------------------------------------------------------------------------------- requests
    def submit(self, study_id: str) -> None:
        """Queue a study that is in the catalog with status ``queued``."""
        with self._lock:
            if self._stopping:
                raise RuntimeError("the job queue is stopping; the study stays queued for the next start")
            self._enqueue_locked(study_id)

    def _enqueue_locked(self, study_id: str) -> None:
        if study_id in self._pending or study_id in self._running:
            return
        self._pending.append(study_id)
        self._queue.put(study_id)

    def cancel(self, study_id: str, wait: float = 30.0) -> bool:
        """Cancel a queued or running study (catalog status ``cancelled``; finished chunks stay saved).

        Waits up to ``wait`` seconds for a running study to stop. Returns False when the queue holds no
        such study (it is finished, or unknown).
        """
        with self._lock:
            if study_id in self._pending:
                self._pending.remove(study_id)
                self._user_cancelled.add(study_id)
                try:
                    self.store.update(study_id, status="cancelled", finished=utc_now())
                except StudyNotFound:
                    pass
                return True
            event = self._running.get(study_id)
            if event is None:
                return False
            self._user_cancelled.add(study_id)
            event.set()
            finished = self._finished[study_id]
        finished.wait(wait)
        return True

    def on_end(self, study_id: str, callback: Callable[[], None]) -> Callable[[], None] | None:
        """Have ``callback()`` called, in the study's thread, when the run of ``study_id`` returns; None (and
        no call) when the study is neither queued nor running. Returns a function that takes the callback
        back (a study cancelled while queued never runs: its callbacks are only taken back)."""
        with self._lock:
            if study_id not in self._pending and study_id not in self._running:
                return None
            self._listeners.setdefault(study_id, []).append(callback)

        def forget() -> None:
            with self._lock:
                calls = self._listeners.get(study_id, [])
                if callback in calls:
                    calls.remove(callback)
                if not calls:
                    self._listeners.pop(study_id, None)

        return forget

    def is_active(self, study_id: str) -> bool:
        """The study is queued or running in this queue."""
        with self._lock:
            return study_id in self._pending or study_id in self._running

    def queued(self) -> list[str]:
        """Ids waiting to run, in order."""
        with self._lock:
            return list(self._pending)

    def running(self) -> list[str]:
        """Ids running now."""
        with self._lock:
            return list(self._running)

    # ---------------------------------------------------------------------------------- worker side
    def _work(self) -> None:
        while True:
            study_id = self._queue.get()
            if study_id is None:
                return
            with self._lock:
                if self._stopping:
                    return
                if study_id not in self._pending:  # cancelled while queued
                    continue
                self._pending.remove(study_id)
                cancel = threading.Event()
                self._running[study_id] = cancel
                self._finished[study_id] = threading.Event()
            try:
                self._run(study_id, cancel)
            except Exception:  # one study's failure must not stop the queue
                log.exception("study %s: unexpected error in the job queue", study_id)
            finally:
                self._remove_if_deleted(study_id)
                with self._lock:
                    self._running.pop(study_id, None)
                    self._finished.pop(study_id).set()
                    self._user_cancelled.discard(study_id)
                    listeners = self._listeners.pop(study_id, [])
                for call in listeners:
                    try:
                        call()
                    except Exception:  # a waiting request's loop closed meanwhile
                        log.debug("study %s: a listener to its end failed", study_id, exc_info=True)

    def _remove_if_deleted(self, study_id: str) -> None:
        """Remove what a study deleted while it ran wrote after its deletion (chunks, a dataset)."""
        try:
            self.store.get(study_id)
        except StudyNotFound:
            try:
                self.store.delete(study_id)
            except Exception as err:  # leftovers only: the study is gone for every route already
                log.warning("study %s: files left after its deletion: %s", study_id, err)
        except Exception as err:  # the catalog cannot answer now: keep the files
            log.info("study %s: not checked for deletion (%s)", study_id, err)

    def _run(self, study_id: str, cancel: threading.Event) -> None:
        try:
            row = self.store.get(study_id)
        except StudyNotFound:
            log.info("study %s: removed from the catalog before it ran", study_id)
            return
        if row["status"] not in UNFINISHED:
            return
        try:
            study = self._loader(row["definition"])
        except Exception as err:
            log.warning("study %s: its definition no longer loads: %s", study_id, err)
            self.store.update(
                study_id, status="failed", finished=utc_now(), error=f"{type(err).__name__}: {err}"
            )
            return
        try:
            self._runner(study, self.store, self.client, study_id, cancel)
        except Exception as err:
            if self._interrupted(study_id):
                self._requeue(study_id)
                return
            log.warning("study %s failed: %s", study_id, err)
            return
        if cancel.is_set() and self._interrupted(study_id):
            self._requeue(study_id)

    def _interrupted(self, study_id: str) -> bool:
        """The run stopped because the queue is stopping (not because a user cancelled it)."""
        with self._lock:
            return self._stopping and study_id not in self._user_cancelled

    def _requeue(self, study_id: str) -> None:
        try:
            row = self.store.get(study_id)
        except StudyNotFound:
            return
        if row["status"] in ("cancelled", "failed", "running"):
            self.store.update(study_id, status="queued", finished=None, error=None)
            log.info("study %s: interrupted by shutdown, stays queued to resume at the next start", study_id)


class Disconnectable(Protocol):
    """What a waiting request is asked: whether its client has gone away (a Starlette ``Request``)."""

    async def is_disconnected(self) -> bool: ...


GONE_STEP_S = 0.5
"""How often a waiting status request looks whether its client has gone away, s (asking the connection);
the study's end itself wakes it at once (:meth:`JobQueue.on_end`)."""


async def wait_for_end(
    jobs: JobQueue, study_id: str, seconds: float, request: Disconnectable | None = None
) -> bool:
    """Wait up to ``seconds`` (s) while the study is queued or running in ``jobs``; True when it is not
    (any more), False at the bound or when the client of ``request`` has gone away (looked at every
    :data:`GONE_STEP_S`). The end of the study's run wakes the wait at once, without polling."""
    loop = asyncio.get_running_loop()
    ended = asyncio.Event()

    def wake() -> None:  # called in the study's thread
        loop.call_soon_threadsafe(ended.set)

    forget = jobs.on_end(study_id, wake)
    if forget is None:
        return True
    try:
        deadline = time.monotonic() + seconds
        while jobs.is_active(study_id):
            left = deadline - time.monotonic()
            if left <= 0:
                return False
            if request is not None and await request.is_disconnected():
                return False
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(ended.wait(), min(GONE_STEP_S, left))
        return True
    finally:
        forget()
