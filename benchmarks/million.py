"""A 1,000,000-case study through the service, with the peak memory of every process.

Run: ``python -m benchmarks million [--cases 1000000] [--duration 0.5] [--dt 1ms] [--no-query]``.

Starts ``isolab serve`` (2 Dask workers, temporary data directory, timing journal on; see
:mod:`benchmarks.endtoend`), runs a small warm-up study (the workers load the compiled kernels), then the
Latin hypercube study of ``studies/examples/lhs-10000.yaml`` (article scene inlined) with ``--cases``
samples at lti/exact, ``--duration`` of simulated time at ``--dt``, submitted over REST and polled until
done. It prints the wall time, cases per second, the dataset file's size and dimensions, the finishing
steps from the journal (reading the chunk statuses, the streamed netCDF write), and the peak resident
memory (RSS, sampled every 0.2 s) of every process: the service (API, Dask scheduler and nannies run in
it) and each Dask worker, checked against 2 GB.

Unless ``--no-query``, it then asks the service for the first rows of the case table (``GET
/studies/{id}/cases``) and reports the service's peak RSS for that query separately: the case table is
built from the whole dataset in the service.
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import time
from pathlib import Path

from benchmarks.endtoend import (
    GB,
    MEMORY_LIMIT,
    MemorySampler,
    ProcessSample,
    Service,
    check_dataset,
    machine_busy_seconds,
    run_study,
    study_definition,
)


def million_definition(n_cases: int, duration: float, dt: str, name: str | None = None) -> dict:
    """The LHS example study with ``n_cases`` samples at lti/exact, ``duration`` (s) simulated at ``dt``."""
    d = study_definition(n_cases, "exact", duration, name=name or f"million-{n_cases}")
    d["simulation"] = {**d["simulation"], "fidelity": "lti", "dt": dt, "auto_step": False}
    return d


def print_memory(title: str, memory: dict[int, ProcessSample]) -> float:
    """Print each process's peak RSS; returns the largest."""
    print(title)
    peak = 0.0
    for pid, s in sorted(memory.items(), key=lambda kv: kv[1].label):
        flag = "ok" if s.peak_rss < MEMORY_LIMIT else "OVER 2 GB"
        print(f"  {s.label:36s} pid {pid:>7d}  peak RSS {s.peak_rss / GB:6.2f} GB  {flag}")
        peak = max(peak, s.peak_rss)
    return peak


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(prog="python -m benchmarks million")
    ap.add_argument("--cases", type=int, default=1_000_000, help="Latin hypercube samples")
    ap.add_argument("--duration", type=float, default=0.5, help="simulated time per case, s")
    ap.add_argument("--dt", default="1 ms", help="time step")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--warmup-cases", type=int, default=200)
    ap.add_argument("--no-query", action="store_true", help="skip the case-table query after the study")
    ap.add_argument("--keep", action="store_true", help="keep the temporary data directory and journal")
    a = ap.parse_args(argv)

    print(
        f"million benchmark: {a.cases:,} cases, lti/exact, {a.duration:g} s at {a.dt}; {os.cpu_count()} "
        f"cores, load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}; {a.workers} Dask workers"
    )
    workdir = Path(tempfile.mkdtemp(prefix="isolab-million-"))
    svc = sampler = None
    try:
        svc = Service(workdir, workers=a.workers).start(timeout=120.0)
        print(f"isolab serve up at {svc.url} (data in {svc.data_dir})")
        sampler = MemorySampler(svc.pid)
        warm = million_definition(a.warmup_cases, a.duration, a.dt, name="million-warmup")
        _, row, tp, ts = run_study(svc, warm)
        print(f"warm-up study ({a.warmup_cases} cases): {ts - tp:.2f} s, {row['status']}")

        sampler.phase()
        busy0 = machine_busy_seconds()
        sid, row, t_post, t_seen = run_study(svc, million_definition(a.cases, a.duration, a.dt), timeout=7200)
        busy1 = machine_busy_seconds()
        memory = sampler.phase()
        wall = t_seen - t_post
        path = svc.data_dir / "studies" / f"{sid}.nc"
        print(f"\nstudy {sid}: {row['status']}, {row['progress']['failed']} failed cases")
        print(f"  wall time          {wall:10.1f} s (POST to done seen by polling)")
        print(f"  throughput         {a.cases / wall:10.1f} cases/s")
        print(f"  machine busy       {(busy1 - busy0) / wall:10.2f} cores on average (all jobs)")
        if path.exists():
            info = check_dataset(path)
            print(f"  dataset file       {info['mb']:10.1f} MB, dims {info['dims']}")
        events = [e for e in svc.journal_events() if e.get("study_id") == sid]
        for kind in ("load_chunks", "write_dataset", "clear_chunks"):
            found = [e for e in events if e["event"] == kind]
            if found:
                print(f"  {kind:18s} {found[-1]['seconds']:10.1f} s")
        chunks = [
            e
            for e in svc.journal_events()
            if e["event"] == "chunk" and e.get("key_prefix") == f"isolab-{sid}"
        ]
        if chunks:
            sizes = sorted(int(e["n_cases"]) for e in chunks)
            print(f"  chunks             {len(chunks):10d} of {sizes[-1]} cases at most")
        peak = print_memory("peak RSS during the study (every process):", memory)
        print(f"  largest: {peak / GB:.2f} GB ({'under' if peak < MEMORY_LIMIT else 'OVER'} the 2 GB target)")

        if not a.no_query and row["status"] == "done":
            from isolab.service.client import Client

            t0 = time.perf_counter()
            with Client(svc.url, timeout=1800.0) as api:
                rows = api.cases(sid, limit=5)
            took = time.perf_counter() - t0
            print(f"\ncase table query (first {len(rows)} rows): {took:.1f} s")
            print_memory("peak RSS during the query:", sampler.phase())
    finally:
        if sampler is not None:
            sampler.close()
        if svc is not None:
            svc.stop()
        if a.keep:
            print(f"\nkept {workdir}")
        else:
            shutil.rmtree(workdir, ignore_errors=True)
