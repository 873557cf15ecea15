"""The first study of a fresh service and small studies over REST, through a real ``isolab serve``.

Run: ``python -m benchmarks first_study [--cases 1000] [--repeats 3] [--budget 200] [--cold]``.

Starts ``isolab serve`` (2 Dask workers, the timing journal on) and prints, each against its target:

* start-up: seconds to the first ``/health`` 200, and until ``/health`` says the kernels are ready;
* the first study, submitted as soon as ``/health`` answers: seconds from its POST to its first reported
  progress (target: within 60 s even on an empty kernel cache) and to done;
* a worker's first chunk: seconds from the chunk being handed to Dask to its engine starting (target:
  under 2 s on a warm cache), against the same for a later chunk;
* ``--repeats`` studies of ``--cases`` cases (the LHS example, lti/exact), each POST -> done seen by a
  client polling every 50 ms, with where the time went (median; target: under 2 s for 1,000 cases);
* an optimisation (the air-mount tuning example, ``--budget`` cases in generations of 40): each
  generation's wall time minus its engine time on the busiest worker, the fixed overhead of a generation
  (median; target: under 100 ms).

``--cold`` runs the service on an empty kernel cache of its own (a temporary ``NUMBA_CACHE_DIR``), as a
fresh install does; the kernels then compile once, on the workers, while the first study waits.
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np

from benchmarks.endtoend import ROOT, Service, StudyRun, analyse, study_definition

FIRST_PROGRESS_TARGET_S = 60.0
FIRST_CHUNK_TARGET_S = 2.0
SMALL_STUDY_TARGET_S = 2.0
GENERATION_OVERHEAD_TARGET_S = 0.100
POLL_S = 0.05


def _met(ok: bool) -> str:
    return "met" if ok else "MISSED"


def submit_and_wait(
    http: httpx.Client, definition: dict, timeout: float = 900.0
) -> tuple[str, dict[str, Any], float, float, float]:
    """POST ``definition`` and poll it until it finishes; (id, last status, POST time, first progress
    time, done-seen time), as Unix times."""
    t_post = time.time()
    answer = http.post("/studies", json=definition)
    answer.raise_for_status()
    sid = answer.json()["id"]
    first_progress = float("nan")
    deadline = time.monotonic() + timeout
    while True:
        info = http.get(f"/studies/{sid}").json()
        progress = info.get("progress", {})
        if not np.isfinite(first_progress) and (progress.get("done", 0) > 0 or info["status"] == "done"):
            first_progress = time.time()
        if info["status"] in ("done", "failed", "cancelled"):
            return sid, info, t_post, first_progress, time.time()
        if time.monotonic() > deadline:
            raise RuntimeError(f"study {sid} still {info['status']} after {timeout} s")
        time.sleep(POLL_S)


def wait_kernels_ready(http: httpx.Client, timeout: float = 900.0) -> float:
    """Poll ``/health`` until its ``kernels.state`` is ``ready``; the Unix time it was seen (NaN when the
    service does not report its kernels)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        kernels = http.get("/health").json().get("kernels")
        if kernels is None:
            return float("nan")
        if kernels.get("state") in ("ready", "failed"):
            return time.time()
        time.sleep(POLL_S)
    return float("nan")


def first_chunk_figures(events: list[dict[str, Any]], sid: str) -> dict[str, float]:
    """How long a chunk waits to start computing once its worker could take it: from the later of its
    hand-over to Dask and the end of the worker's previous chunk of the study, to its engine starting
    (the worker's own start-up cost, imports and structures, is in the task's preparation). For each
    worker's first chunk of study ``sid`` (the largest), and the median of the later ones, in s."""
    chunks = [e for e in events if e["event"] == "chunk" and e.get("key_prefix") == f"isolab-{sid}"]
    by_worker: dict[int, list[dict[str, Any]]] = {}
    for e in chunks:
        if np.isfinite(e["task_start"]):
            by_worker.setdefault(int(e["worker_pid"]), []).append(e)
    first, later = [], []
    for tasks in by_worker.values():
        tasks.sort(key=lambda e: e["task_start"])
        free = [tasks[0]["submitted"]] + [
            max(e["submitted"], p["task_end"]) for p, e in zip(tasks, tasks[1:], strict=False)
        ]
        delays = [e["task_start"] - f + e["prepare_s"] for e, f in zip(tasks, free, strict=True)]
        first.append(delays[0])
        later += delays[1:]
    return {
        "first": max(first) if first else float("nan"),
        "later": statistics.median(later) if later else float("nan"),
        "prepare_first": max((t[0]["prepare_s"] for t in by_worker.values()), default=float("nan")),
    }


def generation_overheads(events: list[dict[str, Any]], sid: str) -> list[float]:
    """Per optimisation generation: its wall time (one fan-out start to the next, the last to its end)
    minus the engine time of its busiest worker, in s."""
    prefix = f"isolab-{sid}-g"
    starts = sorted(
        (
            e
            for e in events
            if e["event"] == "fanout_start" and str(e.get("key_prefix", "")).startswith(prefix)
        ),
        key=lambda e: e["t"],
    )
    ends = {e["key_prefix"]: e["t"] for e in events if e["event"] == "fanout_end"}
    out = []
    for i, start in enumerate(starts):
        key = start["key_prefix"]
        stop = starts[i + 1]["t"] if i + 1 < len(starts) else ends.get(key, float("nan"))
        per_worker: dict[int, float] = {}
        for e in events:
            if e["event"] == "chunk" and e.get("key_prefix") == key:
                per_worker[int(e["worker_pid"])] = per_worker.get(int(e["worker_pid"]), 0.0) + e["engine_s"]
        out.append(stop - start["t"] - max(per_worker.values(), default=0.0))
    return [x for x in out if np.isfinite(x)]


def optimisation_definition(budget: int) -> dict:
    """The air-mount tuning example with a budget of ``budget`` cases (generations of 40)."""
    from isolab.service.client import read_study_file

    d = read_study_file(ROOT / "studies" / "examples" / "tune-air-mounts.yaml")
    d["name"] = f"first-study-optimise-{budget}"
    d["design"] = {**d["design"], "budget": int(budget)}
    return d


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(prog="python -m benchmarks first_study")
    ap.add_argument("--cases", type=int, default=1000, help="cases of each small study")
    ap.add_argument("--repeats", type=int, default=3, help="small studies run after the first")
    ap.add_argument("--budget", type=int, default=200, help="cases of the optimisation (0: none)")
    ap.add_argument("--duration", type=float, default=3.0, help="simulated time per case, s")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--cold", action="store_true", help="start on an empty kernel cache of its own")
    a = ap.parse_args(argv)

    print(
        f"first-study benchmark: {os.cpu_count()} cores, load average "
        f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}; {a.workers} Dask workers; "
        f"{'empty' if a.cold else 'warm'} kernel cache"
    )
    # a SIGTERM (timeout, Ctrl-C from a wrapper) still stops the service below
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    workdir = Path(tempfile.mkdtemp(prefix="isolab-first-study-"))
    svc = Service(workdir, workers=a.workers)
    if a.cold:
        svc.env["NUMBA_CACHE_DIR"] = str(workdir / "numba-cache")
    try:
        t0 = time.time()
        svc.start(timeout=300.0)
        t_health = time.time()
        print(f"isolab serve: /health 200 after {t_health - t0:.1f} s")
        with httpx.Client(base_url=svc.url, timeout=120.0) as http:
            definition = study_definition(a.cases, "exact", a.duration, name="first-study")
            sid, row, t_post, t_progress, t_done = submit_and_wait(http, definition)
            t_ready = wait_kernels_ready(http)
            print(f"kernels ready (/health) {t_ready - t0:.1f} s after start")
            took = t_progress - t_post
            print(
                f"first study ({a.cases} cases, submitted at /health 200): first progress after {took:.1f} s "
                f"[target <= {FIRST_PROGRESS_TARGET_S:.0f} s: {_met(took <= FIRST_PROGRESS_TARGET_S)}], "
                f"done after {t_done - t_post:.1f} s ({row['status']})"
            )
            first = first_chunk_figures(svc.journal_events(), sid)
            print(
                f"first study, a worker's first chunk: free worker -> engine starts {first['first']:.2f} s "
                f"(of which preparing {first['prepare_first']:.2f} s; it waits for the warm-up first); "
                f"a later chunk {first['later']:.2f} s"
            )
            walls, runs = [], []
            for i in range(a.repeats):
                d = study_definition(a.cases, "exact", a.duration, name=f"small-{i}")
                sid, row, t_post, _, t_done = submit_and_wait(http, d)
                if i == 0:
                    warm = first_chunk_figures(svc.journal_events(), sid)
                    print(
                        f"next study, warm workers: first chunk handed -> engine starts {warm['first']:.2f} s "
                        f"(preparing {warm['prepare_first']:.2f} s) "
                        f"[target <= {FIRST_CHUNK_TARGET_S:.0f} s: {_met(warm['first'] <= FIRST_CHUNK_TARGET_S)}]"
                    )
                run = StudyRun(d["name"], "exact", a.cases, a.workers)
                analyse(run, sid, row, t_post, t_done, svc.journal_events(), a.workers)
                walls.append(t_done - t_post)
                runs.append(run)
            if walls:
                median = statistics.median(walls)
                print(
                    f"{a.cases}-case study POST -> done: median {median:.2f} s of "
                    f"{', '.join(f'{w:.2f}' for w in walls)} [target < {SMALL_STUDY_TARGET_S:.0f} s: "
                    f"{_met(median < SMALL_STUDY_TARGET_S)}]"
                )
                mid = runs[walls.index(median)] if median in walls else runs[0]
                for name, seconds in mid.phases:
                    print(f"    {name:58s} {seconds:7.3f} s")
            if a.budget > 0:
                sid, row, t_post, _, t_done = submit_and_wait(http, optimisation_definition(a.budget))
                over = generation_overheads(svc.journal_events(), sid)
                med = statistics.median(over) if over else float("nan")
                print(
                    f"optimisation ({a.budget} cases, {len(over)} generations, {t_done - t_post:.1f} s, "
                    f"{row['status']}): fixed overhead per generation median {med * 1e3:.0f} ms "
                    f"[target < {GENERATION_OVERHEAD_TARGET_S * 1e3:.0f} ms: "
                    f"{_met(med < GENERATION_OVERHEAD_TARGET_S)}]"
                )
    finally:
        svc.stop()
        shutil.rmtree(workdir, ignore_errors=True)
    print(f"load average now {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
