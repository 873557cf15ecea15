"""Warming the engine's kernels on the Dask workers when the service starts, once per machine.

A fresh install has no compiled kernels on disk: the first chunk of each fidelity and integrator pair on
each worker would compile them itself (minutes on 2 cores, the same work in every worker). At start the
service instead hands the workers the warm-up, in the background (``/health`` answers at once):

1. on an empty cache, one task per pair the example studies use (and the reference pair every error
   estimate reruns), spread over the workers, compiles it and saves it in the machine's kernel cache, so
   each kernel compiles once, on one worker;
2. then one task pinned to each worker loads them all from the cache, imports the studies and the libraries
   that write a study's dataset and builds the engine's structures, so a worker's first chunk starts
   computing at once and its first study's dataset is assembled without waiting for imports; the
   service process then writes a small dataset too (it adds each study's error estimate to its file).

The warm-up tasks run at a priority below every study task: a study submitted meanwhile runs first, and
its chunk compiles (or loads) what it needs itself, as without the warm-up. ``ISOLAB_KERNEL_WARMUP=off``
in the environment turns the warm-up off (state ``off``; the test suite does, as its many short-lived
services would each warm their workers). :class:`KernelWarmup` holds where it is: ``/health``
reports it, a study waiting for it says so, and the web page shows "compiling the engine's kernels (first
start only)".
"""

from __future__ import annotations

import logging
import os
import threading
import time
import uuid
from typing import Any, Literal

from isolab.studies.run.kernel_cache import warm_datasets, warm_kernels, warmup_plan

log = logging.getLogger(__name__)

KernelState = Literal["starting", "compiling", "loading", "ready", "failed", "off"]
"""``starting``: the warm-up has not looked at the cache yet; ``compiling``: kernels are missing from the
cache and compile on the workers (first start only); ``loading``: they are cached and the workers load
them (seconds); ``ready``: every worker holds them; ``failed``: the warm-up failed (studies compile what
they need themselves); ``off``: no warm-up (``ISOLAB_KERNEL_WARMUP=off``)."""

WARMUP_PRIORITY = -1_000_000_000
"""Dask priority of the warm-up tasks: below every study task (a study's chunks go at minus its number of
chunks), so a worker takes the warm-up only when no study waits."""
WARMUP_ENV = "ISOLAB_KERNEL_WARMUP"
"""Environment variable: ``off`` (or ``0``, ``false``, ``no``) turns the warm-up off; anything else, or
unset, leaves it on."""
COMPILING_NOTE = "compiling the engine's kernels (first start only)"
"""What a study that waits for the warm-up and the web page say while kernels compile."""
LOADING_NOTE = "loading the engine's kernels on the workers"


class KernelWarmup:
    """The background warm-up of one service's Dask workers (see the module docstring); thread-safe.

    Attributes:
        state: where the warm-up is (:data:`KernelState`).
        pairs: the (fidelity, integrator) pairs warmed, ``"fidelity/integrator"``.
        seconds: seconds from :meth:`start` to ready (or failed); None while it runs.
        error: why it failed.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.state: KernelState = "starting"
        self.pairs: list[str] = []
        self.seconds: float | None = None
        self.error: str | None = None
        self._started = 0.0
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()

    def start(self, client: Any) -> None:
        """Start warming ``client``'s workers in a background thread (unless :func:`warmup_enabled` says
        no: then the state is ``off``)."""
        self._started = time.monotonic()
        if not warmup_enabled():
            self._set(state="off", seconds=0.0)
            return
        self._thread = threading.Thread(target=self._run, args=(client,), name="isolab-kernels", daemon=True)
        self._thread.start()

    def stop(self, timeout: float = 5.0) -> None:
        """Stop waiting for the warm-up tasks (they are left to the cluster, which closes next)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)

    @property
    def busy(self) -> bool:
        """The kernels are not ready on the workers yet (starting, compiling or loading)."""
        return self.state in ("starting", "compiling", "loading")

    def note(self) -> str | None:
        """What a study waiting for its first chunk says meanwhile; None once ready (or failed)."""
        if self.state == "compiling":
            return COMPILING_NOTE
        return LOADING_NOTE if self.state in ("starting", "loading") else None

    def report(self) -> dict[str, Any]:
        """``state``, ``pairs``, ``seconds``, ``error`` and ``note``, as ``/health`` shows them."""
        with self._lock:
            elapsed = self.seconds if self.seconds is not None else time.monotonic() - self._started
            return {
                "state": self.state,
                "pairs": list(self.pairs),
                "seconds": round(elapsed, 1) if self._started else None,
                "error": self.error,
                "note": self.note(),
            }

    def _set(self, **fields: Any) -> None:
        with self._lock:
            for name, value in fields.items():
                setattr(self, name, value)

    def _run(self, client: Any) -> None:
        try:
            self._warm(client)
        except Exception as err:  # studies still run: each worker compiles what it needs itself
            if self._stop.is_set():
                return
            log.warning("warming the engine's kernels failed: %s", err)
            self._set(state="failed", error=f"{type(err).__name__}: {err}", seconds=self._elapsed())
            return
        if not self._stop.is_set():
            self._set(state="ready", seconds=self._elapsed())
            log.info("engine kernels ready on the workers after %.1f s", self.seconds)

    def _elapsed(self) -> float:
        return time.monotonic() - self._started

    def _wait(self, futures: list[Any]) -> list[Any]:
        results = []
        for future in futures:
            while not future.done():
                if self._stop.wait(0.1):
                    raise RuntimeError("the service is stopping")
            results.append(future.result())
        return results

    def _warm(self, client: Any) -> None:
        # the pairs and the cache check run on a worker: the API process stays free to answer requests
        [(pairs, cached)] = self._wait(
            [client.submit(warmup_plan, pure=False, priority=WARMUP_PRIORITY, key=_key("plan"))]
        )
        self._set(pairs=[f"{f}/{i}" for f, i in pairs], state="loading" if cached else "compiling")
        if not cached:  # each pair compiles once, on one worker, into the machine's kernel cache
            log.info("compiling the engine's kernels for %s (first start only)", ", ".join(self.pairs))
            self._wait(
                [
                    client.submit(
                        warm_kernels, [pair], pure=False, priority=WARMUP_PRIORITY, key=_key("compile")
                    )
                    for pair in pairs
                ]
            )
        workers = list(client.nthreads())  # asked of the scheduler (see fanout.worker_threads)
        self._wait(
            [
                client.submit(
                    warm_kernels,
                    pairs,
                    datasets=True,
                    pure=False,
                    priority=WARMUP_PRIORITY,
                    workers=[address],
                    allow_other_workers=False,
                    key=_key("load"),
                )
                for address in workers
            ]
        )
        # this process adds each study's error estimate to its dataset: its first one waits less too
        warm_datasets()


def warmup_enabled() -> bool:
    """Whether the service warms its workers at start (:data:`WARMUP_ENV`)."""
    return os.environ.get(WARMUP_ENV, "").strip().lower() not in ("off", "0", "false", "no")


def _key(what: str) -> str:
    return f"isolab-kernels-{what}-{uuid.uuid4().hex[:8]}"
