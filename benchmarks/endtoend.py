"""End-to-end study throughput and memory through the service, against the engine alone.

Run: ``python -m benchmarks endtoend [--cases 10000 100000] [--rk4-cases 10000] [--duration 3]``.

Starts ``isolab serve`` as a subprocess on a free loopback port with a temporary data directory and the
default 2 Dask workers, and the timing journal on (``ISOLAB_TIMINGS``, see :mod:`studies.run.fanout`). It runs
a small warm-up study first (the workers load the compiled kernels), then Latin hypercube studies based on
``studies/examples/lhs-10000.yaml`` (scene inlined; lti/exact at every size in ``--cases``, lti/rk4 at
``--rk4-cases``), each submitted over REST and waited for with the client's wait (a status request the
service answers as soon as the study ends). Per study it prints:

* wall time (POST to done seen by polling) and cases per second;
* where the wall time went along the critical path (accepting the study, dispatch, the compute window,
  transfer of the last result, chunk and dataset storage, assembly), and how the workers spent the
  compute window (engine, in-task overhead, scheduling gaps, tail);
* the peak resident memory (RSS) of the service process and of each worker (the kernel's high-water
  mark over the study), checked against 2 GB, and that the stored dataset holds no time histories;
* the single-core kernel throughput on the same scene and settings, measured just before and just after
  the study in child processes with BLAS limited to one thread (as the Dask workers run; the median of
  ``--kernel-repeats`` processes on each side, 3 by default: this machine's speed drifts by up to 6 %
  from one study to the next, and a reference taken on one side only moved the ratio with it), batched
  like the workers
  (``ENGINE_BATCH_CASES``), and the ratio of end-to-end throughput to twice that (target >= 85 % at 10,000 cases, >= 90 % at 100,000);
* the CPU other jobs took on the machine meanwhile (the machine may be shared).

The summary ends with one verdict per kind of study: the median ratio of its runs against its target, and
the median of the runs whose engine the host did not slow (its CPU per case in the workers within 5 % of
the reference's; a slowed run is marked ``host``).
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.live_service import ServiceProcess

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "studies" / "examples" / "lhs-10000.yaml"
GB = 1e9
MEMORY_LIMIT = 2 * GB
RATIO_TARGETS = {10_000: 0.85, 100_000: 0.90}
"""End-to-end throughput over twice the single-core kernel's, by study size (the nearest size's applies)."""


def verdicts(runs: list[StudyRun], n_workers: int) -> list[str]:
    """One line per kind of study (integrator and size): the median ratio of its runs against its target,
    and the median of those the host did not slow (:data:`HOST_SLOWER`)."""
    lines = []
    for integrator, n in sorted({(r.integrator, r.n_cases) for r in runs}):
        same = [r for r in runs if (r.integrator, r.n_cases) == (integrator, n)]
        target = ratio_target(n)
        ratios = [r.ratio(n_workers) for r in same]
        steady = [r.ratio(n_workers) for r in same if not r.host_slowdown > HOST_SLOWER]
        median = float(np.median(ratios))
        line = (
            f"{integrator} {n} cases: median {median * 100:.1f} % over {len(same)} run(s), "
            f"{sum(x >= target for x in ratios)} at or above {target * 100:.0f} %"
        )
        if steady and len(steady) < len(same):
            line += f"; {float(np.median(steady)) * 100:.1f} % over the {len(steady)} the host did not slow"
        lines.append(f"{line} -> {'meets' if median >= target else 'MISSES'} the target")
    return lines


def study_size(text: str) -> int:
    """A study size given on the command line: a whole number of cases, at least 1."""
    n = int(text)
    if n < 1:
        raise argparse.ArgumentTypeError(
            f"{text}: a study has at least 1 case (leave the sizes out for none)"
        )
    return n


def ratio_target(n_cases: int) -> float:
    """The target ratio for a study of ``n_cases``: that of the nearest listed size."""
    return RATIO_TARGETS[min(RATIO_TARGETS, key=lambda n: abs(np.log(n / max(n_cases, 1))))]


ONE_THREAD = {
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "NUMBA_NUM_THREADS": "1",
}


# ------------------------------------------------------------------------------------------ studies
def study_definition(n_cases: int, integrator: str, duration: float, name: str | None = None) -> dict:
    """The LHS example study with ``n_cases`` samples, its scene inlined, at ``integrator`` and
    ``duration`` (s) of simulated time."""
    from isolab.service.client import read_study_file

    d = read_study_file(EXAMPLE)
    d["name"] = name or f"endtoend-{integrator}-{n_cases}"
    d["design"] = {**d["design"], "samples": int(n_cases)}
    d["simulation"] = {**d.get("simulation", {}), "integrator": integrator, "duration": f"{duration:g} s"}
    return d


# -------------------------------------------------------------------------------- kernel reference
def kernel_reference(definition: dict, n_cases: int) -> dict[str, float]:
    """Single-core engine throughput on ``n_cases`` cases spread evenly over the study's design, run as
    the workers run them (batches of ``ENGINE_BATCH_CASES``); timing covers the engine call only.

    Run it where BLAS is limited to one thread (see :func:`measure_kernel`). Returns seconds per case of
    wall and CPU time and the number of cases."""
    from isolab.engine import simulate
    from isolab.studies.inputs.study import Study
    from isolab.studies.run.fanout import ENGINE_BATCH_CASES

    study = Study.model_validate(definition)
    sim = study.simulation
    m = min(int(n_cases), study.n_cases)
    idx = np.unique(np.linspace(0, study.n_cases - 1, m).round().astype(np.int64))
    batches = [study.batch(idx[s : s + ENGINE_BATCH_CASES]) for s in range(0, idx.size, ENGINE_BATCH_CASES)]
    run = {"fidelity": sim.fidelity, "integrator": sim.integrator, "dt": sim.dt, "auto_step": sim.auto_step}
    simulate(study.batch(idx[:8]), **run)  # load the compiled kernels
    wall = cpu = 0.0
    ok = 0
    for b in batches:
        t0, c0 = time.perf_counter(), time.thread_time()
        r = simulate(b, **run)
        cpu += time.thread_time() - c0
        wall += time.perf_counter() - t0
        ok += int(np.count_nonzero(r.status == 0))
    return {
        "cases": int(idx.size),
        "ok": ok,
        "wall_per_case": wall / idx.size,
        "cpu_per_case": cpu / idx.size,
    }


def measure_kernel(definition: dict, n_cases: int) -> dict[str, float]:
    """:func:`kernel_reference` in a child process whose BLAS, OpenMP and Numba use one thread."""
    env = {
        **os.environ,
        **ONE_THREAD,
        "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
    }
    code = (
        "import json, sys; from benchmarks.endtoend import kernel_reference; "
        "a = json.load(sys.stdin); print(json.dumps(kernel_reference(a['definition'], a['n'])))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        input=json.dumps({"definition": definition, "n": n_cases}),
        capture_output=True,
        text=True,
        cwd=ROOT,
        env=env,
        check=False,
    )
    if out.returncode != 0:
        raise RuntimeError(f"kernel reference failed:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def kernel_runs(definition: dict, n_cases: int, repeats: int) -> list[dict[str, float]]:
    """:func:`measure_kernel` ``repeats`` times, each in a fresh process (where its arrays land differs from
    one process to the next)."""
    return [measure_kernel(definition, n_cases) for _ in range(max(1, int(repeats)))]


def median_run(runs: list[dict[str, float]]) -> dict[str, float]:
    """The run of median wall time per case among ``runs`` (of :func:`measure_kernel`), with the fastest and
    slowest beside it (``wall_min``, ``wall_max``, s per case) and their number (``repeats``). Of an even
    number, the lower middle: the faster reference, the lower ratio."""
    runs = sorted(runs, key=_per_case)
    middle = dict(runs[(len(runs) - 1) // 2])
    middle.update(wall_min=_per_case(runs[0]), wall_max=_per_case(runs[-1]), repeats=len(runs))
    return middle


def _per_case(run: dict[str, float]) -> float:
    return float(run["wall_per_case"])


# ------------------------------------------------------------------------------------------ service
class Service(ServiceProcess):
    """``isolab serve`` (:class:`~benchmarks.live_service.ServiceProcess`) with its study store
    (``data``), its log (``service.log``) and its timing journal (``timings.jsonl``, ``ISOLAB_TIMINGS``)
    in ``workdir``."""

    def __init__(self, workdir: Path, workers: int = 2):
        self.journal = workdir / "timings.jsonl"
        super().__init__(
            workdir / "data", workers, env={"ISOLAB_TIMINGS": str(self.journal)}, log=workdir / "service.log"
        )

    def journal_events(self) -> list[dict[str, Any]]:
        """The records of the timing journal so far."""
        if not self.journal.exists():
            return []
        return [json.loads(line) for line in self.journal.read_text().splitlines() if line.strip()]


# ----------------------------------------------------------------------------------------- sampling
@dataclass
class ProcessSample:
    label: str
    peak_rss: int = 0
    cpu_start: float | None = None
    cpu_end: float = 0.0


class MemorySampler:
    """Peak RSS and CPU time of a process and its descendants per phase (one per study), read from the
    kernel at the phase's ends: its high-water mark of resident memory (``VmHWM``, reset at each phase's
    start through ``/proc/<pid>/clear_refs``) and its CPU times. Nothing runs between (a sampling thread
    took about 1 ms of CPU five times a second on the machine it measured); where the peak cannot be
    reset, it is the process's peak since it started."""

    def __init__(self, pid: int):
        import psutil

        self._psutil = psutil
        self.root = psutil.Process(pid)
        self.samples: dict[int, ProcessSample] = {}
        self._sample()

    def phase(self) -> dict[int, ProcessSample]:
        """Start a new phase; returns the samples of the one that ends."""
        self._sample()
        done, self.samples = self.samples, {}
        self._sample(reset=True)
        return done

    def close(self) -> dict[int, ProcessSample]:
        return self.phase()

    def _sample(self, reset: bool = False) -> None:
        ps = self._psutil
        try:
            procs = [self.root, *self.root.children(recursive=True)]
        except ps.Error:
            return
        for p in procs:
            try:
                with p.oneshot():
                    t = p.cpu_times()
                    cpu = t.user + t.system
                    label = _label(p, self.root.pid)
                peak = _peak_rss(p.pid, reset)
            except (ps.Error, OSError):
                continue
            s = self.samples.setdefault(p.pid, ProcessSample(label))
            s.peak_rss = max(s.peak_rss, peak)
            if s.cpu_start is None:
                s.cpu_start = cpu
            s.cpu_end = cpu


def _peak_rss(pid: int, reset: bool) -> int:
    """A process's peak resident memory (bytes) since it started or its peak was last reset; with
    ``reset``, reset first (Linux: ``clear_refs`` 5), which leaves its resident memory now."""
    if reset:
        try:
            Path(f"/proc/{pid}/clear_refs").write_text("5")
        except OSError:
            pass  # not this user's process to reset: its peak counts from its start
    status = Path(f"/proc/{pid}/status").read_text()
    return int(next(line.split()[1] for line in status.splitlines() if line.startswith("VmHWM:"))) * 1024


def _label(p, root_pid: int) -> str:
    if p.pid == root_pid:
        return "service (API, scheduler, nannies)"
    cmd = " ".join(p.cmdline())
    if "resource_tracker" in cmd:
        return "multiprocessing resource tracker"
    if "spawn_main" in cmd or "forkserver" in cmd:
        return "Dask worker"
    return p.name()


def machine_busy_seconds() -> float:
    """CPU seconds the whole machine has spent busy (all cores, not idle or iowait)."""
    import psutil

    t = psutil.cpu_times()
    return float(sum(t) - t.idle - getattr(t, "iowait", 0.0))


# ---------------------------------------------------------------------------------------- one study
HOST_SLOWER = 1.05
"""A study whose engine ran this much slower per case in the workers than in its bracketing reference
(CPU time, the same code): the host slowed it during the study; the summary marks it and gives the median
without it beside the median of every run."""


@dataclass
class StudyRun:
    """Figures of one study run through the service."""

    name: str
    integrator: str
    n_cases: int
    n_workers: int = 2
    wall: float = 0.0
    status: str = ""
    n_failed: int = 0
    kernel: dict[str, float] = field(default_factory=dict)
    phases: list[tuple[str, float]] = field(default_factory=list)
    workers: dict[str, float] = field(default_factory=dict)
    side: dict[str, float] = field(default_factory=dict)
    memory: dict[int, ProcessSample] = field(default_factory=dict)
    chunks: list[int] = field(default_factory=list)
    other_cores: float = float("nan")
    dataset: dict[str, Any] = field(default_factory=dict)

    @property
    def cases_per_s(self) -> float:
        return self.n_cases / self.wall

    @property
    def host_slowdown(self) -> float:
        """The engine's CPU per case in the workers over the bracketing reference's (1: as fast; NaN when
        either is missing): above :data:`HOST_SLOWER`, the host ran the engine slower during the study."""
        cpu, per_case = self.workers.get("engine_cpu_s"), self.kernel.get("cpu_per_case")
        return cpu / self.n_cases / per_case if cpu and per_case else float("nan")

    @property
    def engine_share(self) -> float:
        """Engine time summed over the chunks over (workers x wall): how much of the workers' time the
        study spent in the engine. Other jobs on the machine change it little, unlike the ratio."""
        return self.workers.get("engine_s", float("nan")) / (self.n_workers * self.wall)

    def ratio(self, cores: float = 2.0) -> float:
        """End-to-end throughput over ``cores`` times the single-core kernel throughput."""
        return self.cases_per_s * self.kernel["wall_per_case"] / cores if self.kernel else float("nan")

    def ratio_left(self, n_workers: int) -> float:
        """End-to-end throughput over the kernel throughput of the cores other jobs left free (an
        estimate: it assumes the other jobs took their CPU from the workers)."""
        return (
            self.ratio(max(n_workers - self.other_cores, 0.1))
            if np.isfinite(self.other_cores)
            else float("nan")
        )


def _unix(iso: str | None) -> float:
    if not iso:
        return float("nan")
    return _dt.datetime.fromisoformat(iso.replace("Z", "+00:00")).timestamp()


def run_study(
    svc: Service, definition: dict, poll: float | None = None, timeout: float = 3600.0
) -> tuple[str, dict[str, Any], float, float]:
    """Submit ``definition`` and wait until it finishes with the client's wait, as ``isolab submit --wait``
    does (each status request waits on the service for the study to end, and comes back every ``poll`` s
    meanwhile: the client's default, 0.5 s, when None); returns (id, final row, POST time, done-seen
    time)."""
    from isolab.service.client import Client

    def alive(info: dict[str, Any]) -> None:
        if not svc.running():
            raise RuntimeError(f"the service exited:\n{svc.tail(3000)}")

    with Client(svc.url, timeout=600.0) as api:
        t_post = time.time()
        sid = api.submit(definition)["id"]
        polled = {} if poll is None else {"poll": poll}
        info = api.wait(sid, progress=alive, timeout=timeout, **polled)
        return sid, info, t_post, time.time()


def analyse(
    run: StudyRun,
    sid: str,
    row: dict[str, Any],
    t_post: float,
    t_seen: float,
    events: list[dict[str, Any]],
    n_workers: int,
) -> None:
    """Fill ``run`` with the wall-time decomposition from the journal events of study ``sid``."""
    prefix = f"isolab-{sid}"
    chunks = [e for e in events if e["event"] == "chunk" and e.get("key_prefix") == prefix]
    mine = [e for e in events if e.get("study_id") == sid]

    def total(kind: str) -> float:
        return float(sum(e["seconds"] for e in mine if e["event"] == kind))

    def last(kind: str) -> dict[str, Any] | None:
        found = [e for e in mine if e["event"] == kind]
        return found[-1] if found else None

    run.wall = t_seen - t_post
    run.status, run.n_failed = row["status"], int(row["progress"]["failed"])
    finished = _unix(row["finished"])
    run.chunks = sorted(int(e["n_cases"]) for e in chunks)
    if not chunks:
        run.phases = [("whole study (no chunk timings in the journal)", run.wall)]
        return
    submitted = min(e["submitted"] for e in chunks)
    starts = [e["task_start"] for e in chunks if np.isfinite(e["task_start"])]
    ends = [e["task_end"] for e in chunks if np.isfinite(e["task_end"])]
    first_start, last_end = min(starts), max(ends)
    last_chunk = max(chunks, key=lambda e: e["arrived"] + e["fetch_s"] + e["handled_s"])
    fetched = last_chunk["arrived"] + last_chunk["fetch_s"]
    handled = fetched + last_chunk["handled_s"]
    load, write, clear = last("load_chunks"), last("write_dataset"), last("clear_chunks")
    publish = last("publish_dataset")
    load_s = load["seconds"] if load and load["t"] >= handled else 0.0
    write_s = write["seconds"] if write else 0.0
    # a study's chunks are removed once it is marked done: on the critical path only in an older service
    clear_s = clear["seconds"] if clear and clear["t"] <= finished + 1e-3 else 0.0
    # a dataset written as the chunks land (studies.run.landing) began with the run: what is left of its
    # writing once the last chunk is in (its block, the file's closing) is on the critical path
    landed = bool(write) and write["t"] - write["seconds"] < handled
    if write and landed:
        write_s = max(write["t"] - handled, 0.0)
    publish_s = publish["seconds"] if publish else 0.0
    # the error estimate's reruns run beside the finishing task; what they take beyond its write
    rerun_s = max(publish["t"] - publish_s - write["t"], 0.0) if publish and write else 0.0
    finish = max(finished - handled, 0.0)
    run.phases = [
        ("accept (POST, validation, catalog, queue, chunk plan)", submitted - t_post),
        ("dispatch (submitted -> first task starts)", first_start - submitted),
        ("compute window (first task start -> last task end)", last_end - first_start),
        (
            "transfer of the last chunk (task end -> fetched)",
            max(fetched - max(last_end, last_chunk["task_end"]), 0),
        ),
        ("store the last chunk + catalog update", last_chunk["handled_s"]),
        ("load the saved chunks", load_s),
        (
            "assemble the dataset (+ catalog)",
            max(finish - load_s - write_s - rerun_s - publish_s - clear_s, 0.0),
        ),
        (
            "write the netCDF dataset" + (" (what is left once the last chunk is in)" if landed else ""),
            write_s,
        ),
        ("error estimate's reruns, beyond the write", rerun_s),
        ("add the error estimate to the file, move it into place", publish_s),
        ("remove the chunk files (before the study is marked done)", clear_s),
        ("poll latency (finished -> seen)", max(t_seen - finished, 0.0)),
    ]
    # the workers' time in the compute window, per worker process
    by_worker: dict[int, list[dict]] = {}
    for e in chunks:
        by_worker.setdefault(int(e["worker_pid"]), []).append(e)
    window = (last_end - first_start) * n_workers
    engine = float(sum(e["engine_s"] for e in chunks))
    in_task = float(sum(e["task_end"] - e["task_start"] for e in chunks)) - engine
    gaps = tail = 0.0
    for tasks in by_worker.values():
        tasks.sort(key=lambda e: e["task_start"])
        gaps += tasks[0]["task_start"] - first_start
        gaps += sum(max(b["task_start"] - a["task_end"], 0.0) for a, b in zip(tasks, tasks[1:], strict=False))
        tail += last_end - tasks[-1]["task_end"]
    tail += (n_workers - len(by_worker)) * (last_end - first_start)
    run.workers = {
        "engine": engine / window,
        "in-task overhead (study rebuild, batch build, packing)": in_task / window,
        "scheduling gaps between tasks": gaps / window,
        "tail (idle after its last task)": tail / window,
        "engine_cpu_s": float(sum(e["engine_cpu_s"] for e in chunks)),
        "engine_s": engine,
        "prepare_s": float(sum(e["prepare_s"] for e in chunks)),
        "pack_s": float(sum(e["pack_s"] for e in chunks)),
    }
    run.side = {
        "fetch_s": float(sum(e["fetch_s"] for e in chunks)),
        "notify_s": float(sum(max(e["arrived"] - e["task_end"], 0.0) for e in chunks)),
        "result_mb": float(sum(e["result_bytes"] for e in chunks)) / 1e6,
        "save_chunk_s": total("save_chunk"),
        "handled_s": float(sum(e["handled_s"] for e in chunks)),
        "load_chunks_s": load_s,
        "write_dataset_s": write_s,
        "write_dataset_cpu_s": float(write.get("cpu_s", float("nan"))) if write else float("nan"),
        "publish_dataset_s": publish_s,
        "clear_chunks_s": clear_s,
        "dataset_mb": (write["bytes"] / 1e6) if write else float("nan"),
    }


def check_dataset(path: Path) -> dict[str, Any]:
    """Dimensions and size of a stored dataset, and whether it holds anything along time."""
    import xarray as xr

    with xr.open_dataset(path) as ds:
        dims = dict(ds.sizes)
    return {
        "dims": dims,
        "time_dims": [d for d in dims if "time" in d.lower() or d in ("t", "step")],
        "mb": path.stat().st_size / 1e6,
    }


# ------------------------------------------------------------------------------------------ report
def _mb(b: float) -> str:
    return f"{b / 1e6:8.0f} MB"


def print_run(run: StudyRun, n_workers: int, duration: float) -> None:
    k = run.kernel
    print(
        f"\n=== {run.name}: {run.n_cases} cases, lti/{run.integrator}, {duration:g} s at 1 ms "
        f"({len(run.chunks)} chunks of {run.chunks[-1] if run.chunks else 0}-{run.chunks[0] if run.chunks else 0} "
        f"cases) -> {run.status}, {run.n_failed} failed"
    )
    print(f"wall {run.wall:8.2f} s   {run.cases_per_s:8.1f} cases/s end to end")
    print(
        f"single-core kernel ({k['cases']} cases, batched, one thread, median of {k.get('repeats', 1)} "
        f"processes before and after): {k['wall_per_case'] * 1e3:.3f} ms/case wall ({1 / k['wall_per_case']:.1f} cases/s; "
        f"{k.get('wall_min', k['wall_per_case']) * 1e3:.3f}-{k.get('wall_max', k['wall_per_case']) * 1e3:.3f}), "
        f"{k['cpu_per_case'] * 1e3:.3f} ms/case CPU"
    )
    ratio = run.ratio(n_workers)
    target = ratio_target(run.n_cases)
    verdict = "meets" if ratio >= target else "MISSES"
    print(
        f"end to end / ({n_workers} x single-core kernel) = {ratio * 100:.1f} %  ({verdict} the "
        f"{target * 100:.0f} % target)"
    )
    if run.workers:
        print(
            f"engine share of the workers' wall time (the fan-out's efficiency): {run.engine_share * 100:.1f} %"
        )
    if np.isfinite(run.other_cores):
        print(
            f"other jobs on the machine used {run.other_cores:.2f} cores on average during the study; "
            f"end to end / ({n_workers - run.other_cores:.2f} x single-core kernel) = "
            f"{run.ratio_left(n_workers) * 100:.1f} %"
        )
    print("wall time along the critical path:")
    for name, sec in run.phases:
        print(f"  {name:58s} {sec:8.3f} s  {sec / run.wall * 100:5.1f} %")
    if run.workers:
        w = run.workers
        print(f"workers in the compute window ({n_workers} x window = 100 %):")
        for name in list(w)[:4]:
            print(f"  {name:58s} {w[name] * 100:5.1f} %")
        print(
            f"  engine CPU / engine wall in the workers: {w['engine_cpu_s'] / w['engine_s'] * 100:.0f} %; engine "
            f"{w['engine_s'] / run.n_cases * 1e3:.3f} ms/case wall, {w['engine_cpu_s'] / run.n_cases * 1e3:.3f} "
            f"ms/case CPU (kernel alone: {k['cpu_per_case'] * 1e3:.3f})"
        )
        s = run.side
        sched = dict(run.phases)
        sched_s = (
            sched["dispatch (submitted -> first task starts)"]
            + w["scheduling gaps between tasks"] * sched["compute window (first task start -> last task end)"]
        )
        transfer_s = sched["transfer of the last chunk (task end -> fetched)"]
        storage_s = (
            sched["store the last chunk + catalog update"]
            + s["load_chunks_s"]
            + s["write_dataset_s"]
            + s["publish_dataset_s"]
            + s["clear_chunks_s"]
        )
        print(
            "shares of the wall time (critical path):  "
            f"scheduling {sched_s / run.wall * 100:.1f} %, transfer {transfer_s / run.wall * 100:.1f} %, "
            f"storage {storage_s / run.wall * 100:.1f} %"
        )
        print(
            f"off the critical path (service thread, overlapping compute): fetch {s['fetch_s']:.3f} s for "
            f"{s['result_mb']:.1f} MB of results, completion notice {s['notify_s']:.2f} s in total, "
            f"save_chunk {s['save_chunk_s']:.3f} s, on_chunk (save + catalog) {s['handled_s']:.3f} s; "
            f"dataset {s['dataset_mb']:.1f} MB, written in {s['write_dataset_cpu_s']:.3f} s of CPU"
        )
    print("peak RSS per process:")
    worst = 0
    for pid, smp in sorted(run.memory.items(), key=lambda kv: kv[1].label):
        cpu = smp.cpu_end - (smp.cpu_start or 0.0)
        print(
            f"  {smp.label:36s} pid {pid:7d} {_mb(smp.peak_rss)}   CPU {cpu:7.1f} s "
            f"({cpu / run.wall:4.2f} cores)"
        )
        worst = max(worst, smp.peak_rss)
    histories = run.n_cases * 12 * 8 * (duration / 1e-3)
    ok = worst < MEMORY_LIMIT and not run.dataset.get("time_dims")
    print(
        f"memory: largest process {worst / GB:.2f} GB, {'under' if worst < MEMORY_LIMIT else 'OVER'} "
        f"{MEMORY_LIMIT / GB:.0f} GB; time histories of every case would take {histories / GB:.0f} GB; the "
        f"dataset has dims {run.dataset.get('dims')} (no time axis: {not run.dataset.get('time_dims')}) "
        f"-> {'OK' if ok else 'FAILED'}"
    )


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(prog="python -m benchmarks endtoend")
    ap.add_argument(
        "--cases", type=study_size, nargs="+", default=[10_000, 100_000], help="lti/exact study sizes"
    )
    ap.add_argument(
        "--rk4-cases",
        type=study_size,
        nargs="*",
        default=[10_000],
        help="lti/rk4 study sizes (none: no rk4 study)",
    )
    ap.add_argument("--duration", type=float, default=3.0, help="simulated time per case, s")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--kernel-cases", type=int, default=2000, help="cases of the single-core kernel run")
    ap.add_argument(
        "--kernel-repeats",
        type=int,
        default=3,
        help="single-core kernel runs before and again after each study (median of all)",
    )
    ap.add_argument("--warmup-cases", type=int, default=200)
    ap.add_argument("--keep", action="store_true", help="keep the temporary data directory and journal")
    ap.add_argument("--json", type=Path, help="also write the figures to this JSON file")
    a = ap.parse_args(argv)

    plan = [("exact", n) for n in a.cases] + [("rk4", n) for n in a.rk4_cases]
    print(
        f"end-to-end benchmark: {os.cpu_count()} cores, load average "
        f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}; {a.workers} Dask workers (1 thread each)"
    )
    workdir = Path(tempfile.mkdtemp(prefix="isolab-endtoend-"))
    svc = None
    sampler = None
    runs: list[StudyRun] = []
    t_all = time.perf_counter()
    try:
        t0 = time.perf_counter()
        svc = Service(workdir, workers=a.workers).start(timeout=120.0)
        print(f"isolab serve up at {svc.url} in {time.perf_counter() - t0:.1f} s (data in {svc.data_dir})")
        sampler = MemorySampler(svc.pid)
        warm = study_definition(a.warmup_cases, "exact", a.duration, name="endtoend-warmup")
        sid, row, tp, ts = run_study(svc, warm)
        warm_rk4 = study_definition(a.warmup_cases, "rk4", a.duration, name="endtoend-warmup-rk4")
        if a.rk4_cases:
            run_study(svc, warm_rk4)
        print(
            f"warm-up study ({a.warmup_cases} cases, first use of the workers): {ts - tp:.2f} s, {row['status']}"
        )
        kernels: dict[str, dict[str, float]] = {}
        for integrator, n in plan:
            definition = study_definition(n, integrator, a.duration)
            kdef = study_definition(min(n, 10_000), integrator, a.duration)
            before = kernel_runs(kdef, min(a.kernel_cases, n), a.kernel_repeats)
            sampler.phase()
            busy0, mine0 = machine_busy_seconds(), time.process_time()
            sid, row, t_post, t_seen = run_study(svc, definition)
            busy1, mine1 = machine_busy_seconds(), time.process_time()
            kernels[integrator] = median_run(
                before + kernel_runs(kdef, min(a.kernel_cases, n), a.kernel_repeats)
            )
            run = StudyRun(definition["name"], integrator, n, a.workers, kernel=kernels[integrator])
            run.memory = sampler.phase()
            ours = sum(s.cpu_end - (s.cpu_start or 0.0) for s in run.memory.values()) + (mine1 - mine0)
            analyse(run, sid, row, t_post, t_seen, svc.journal_events(), a.workers)
            run.other_cores = max(busy1 - busy0 - ours, 0.0) / run.wall
            path = svc.data_dir / "studies" / f"{sid}.nc"
            run.dataset = check_dataset(path) if path.exists() else {}
            print_run(run, a.workers, a.duration)
            runs.append(run)
    finally:
        if sampler is not None:
            sampler.close()
        if svc is not None:
            svc.stop()
        if a.keep:
            print(f"\nkept {workdir}")
        else:
            shutil.rmtree(workdir, ignore_errors=True)
    print(
        f"\nsummary ({time.perf_counter() - t_all:.0f} s in all; load average now "
        f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}):"
    )
    print(
        f"{'study':24s} {'wall s':>8s} {'cases/s':>9s} {'kernel/s':>9s} {'ratio':>7s} {'engine':>7s} "
        f"{'others':>7s} {'ratio*':>7s} {'peak RSS':>10s}"
    )
    for r in runs:
        peak = max((s.peak_rss for s in r.memory.values()), default=0)
        host = " host" if r.host_slowdown > HOST_SLOWER else ""
        print(
            f"{r.name:24s} {r.wall:8.2f} {r.cases_per_s:9.1f} {1 / r.kernel['wall_per_case']:9.1f} "
            f"{r.ratio(a.workers) * 100:6.1f}% {r.engine_share * 100:6.1f}% {r.other_cores:7.2f} "
            f"{r.ratio_left(a.workers) * 100:6.1f}% "
            f"{peak / GB:8.2f} GB{host}"
        )
    print(
        "ratio: end to end / (workers x single-core kernel); engine: engine share of the workers' wall "
        "time; others: cores other jobs used meanwhile; ratio*: end to end / (cores they left x kernel); "
        f"host: the engine ran more than {(HOST_SLOWER - 1) * 100:.0f} % slower per case in the workers than "
        "in its reference"
    )
    for line in verdicts(runs, a.workers):
        print(line)
    if a.json:
        a.json.write_text(
            json.dumps(
                [
                    {
                        "name": r.name,
                        "integrator": r.integrator,
                        "n_cases": r.n_cases,
                        "wall_s": r.wall,
                        "cases_per_s": r.cases_per_s,
                        "kernel": r.kernel,
                        "ratio": r.ratio(a.workers),
                        "ratio_left": r.ratio_left(a.workers),
                        "engine_share": r.engine_share,
                        "phases": r.phases,
                        "workers": r.workers,
                        "side": r.side,
                        "other_cores": r.other_cores,
                        "chunks": r.chunks,
                        "memory": {
                            str(p): {
                                "label": s.label,
                                "peak_rss": s.peak_rss,
                                "cpu_s": s.cpu_end - (s.cpu_start or 0),
                            }
                            for p, s in r.memory.items()
                        },
                    }
                    for r in runs
                ],
                indent=1,
            )
        )
