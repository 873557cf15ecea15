"""CPU priority of the Dask workers the service starts on its own machine.

The LocalCluster's workers run the engine flat out, one process per core; the API process on the same
cores answers requests. :class:`LowerPriority` (a Dask worker plugin, so a worker the nanny restarts gets
it too) raises the nice value of every thread of a worker process to :data:`WORKER_NICENESS`: the kernel
then runs the API first when it has work, and the engine gets every cycle the API leaves, so throughput
is the same and request latency no longer waits for a worker's time slice.
"""

from __future__ import annotations

import os
from pathlib import Path

from distributed.diagnostics.plugin import WorkerPlugin

WORKER_NICENESS = 10
"""Nice value of the worker processes (0 is the default priority, 19 the lowest)."""


def lower_thread_priorities(niceness: int = WORKER_NICENESS) -> int:
    """Raise the nice value of every thread of this process to at least ``niceness`` (Linux sets it per
    thread; threads started later inherit it from the thread that starts them). Returns the number of
    threads changed; threads whose priority cannot be changed are left as they are."""
    tasks = Path("/proc/self/task")
    ids = [int(t) for t in os.listdir(tasks) if t.isdigit()] if tasks.is_dir() else [0]
    changed = 0
    for tid in ids:
        try:
            if os.getpriority(os.PRIO_PROCESS, tid) < niceness:
                os.setpriority(os.PRIO_PROCESS, tid, niceness)
                changed += 1
        except OSError:  # the thread ended meanwhile, or the platform refuses
            continue
    return changed


class LowerPriority(WorkerPlugin):
    """Worker plugin: run the worker's threads at nice ``niceness`` (see the module docstring)."""

    name = "isolab-lower-priority"

    def __init__(self, niceness: int = WORKER_NICENESS):
        self.niceness = int(niceness)

    def setup(self, worker) -> None:
        lower_thread_priorities(self.niceness)
