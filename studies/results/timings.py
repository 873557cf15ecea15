"""The timing journal: where a study's time goes, as JSON lines for the end-to-end benchmark.

When the environment variable ``ISOLAB_TIMINGS`` names a file, the fan-out (chunks submitted, arrived,
fetched) and the store (chunk and dataset writes and reads) append one JSON line per event to it;
``python -m benchmarks endtoend`` reads that journal from a running service. Unset or empty: nothing is
written.
"""

from __future__ import annotations

import json
import os
import threading
import time
from typing import Any

import numpy as np

TIMINGS_ENV = "ISOLAB_TIMINGS"
"""Environment variable naming the timing journal file (JSON lines); unset or empty: no journal."""
_journal_lock = threading.Lock()


def record_timing(event: str, **fields: Any) -> None:
    """Append ``{"event": event, "t": <Unix time, s>, "pid": <process id>, **fields}`` as one JSON line to
    the journal named by ``ISOLAB_TIMINGS``; does nothing when the variable is unset or empty.

    Durations are in seconds, times are Unix times in seconds. A journal that cannot be written is skipped
    silently: timings never stop a study."""
    path = os.environ.get(TIMINGS_ENV, "")
    if not path:
        return
    record = {"event": str(event), "t": time.time(), "pid": os.getpid(), **fields}
    line = json.dumps(record, default=_json_number) + "\n"
    try:
        with _journal_lock, open(path, "a", encoding="utf-8") as f:
            f.write(line)
    except OSError:
        pass


def _json_number(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return str(value)
