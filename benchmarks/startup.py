"""Start-up: how soon the command line answers, warm and on a fresh install, against its targets.

Run: ``python -m benchmarks startup [--repeat 3] [--cold-repeat 3] [--no-cold]``. Prints, each the median of
``--repeat`` fresh processes with the CPU model and the load average beside it:

- the wall time of a whole ``isolab simulate studies/examples/article-scriber.yaml`` on a warm kernel cache
  (and its CPU time, user + system, which another process's load changes far less);
- the import time of every ``isolab`` command (the CLI module, then what the command's function imports);
- the first ``isolab simulate`` on an empty kernel cache (a temporary folder: a fresh install), wall and CPU
  time;
- what a fresh process pays on a warm cache before its first case computes (kernels loaded from disk);
- the time from a fresh service's first study to its first progress (not measured here).
"""

from __future__ import annotations

import argparse
import ast
import inspect
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

from benchmarks.pairs import EXAMPLE

ISOLAB = Path(sys.executable).with_name("isolab")
TARGETS = {"warm simulate": 1.5, "imports": 0.8, "cold simulate": 45.0, "per process": 2.0}
"""Targets, s."""


def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo``) and the number of cores."""
    name = "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                name = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{name}, {os.cpu_count()} cores"


def load() -> str:
    """The 1-, 5- and 15-minute load averages."""
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def _verdict(seconds: float | None, target: float) -> str:
    if seconds is None:
        return "not measured"
    return f"{seconds:7.2f} s  target < {target:g} s  {'met' if seconds < target else 'MISSED'}"


def _timed(cmd: list[str], env: dict[str, str] | None = None) -> tuple[float, float]:
    """(wall, CPU) seconds of running ``cmd``: the CPU time (user + system of the process and its
    children) is what the command costs whatever else the machine runs, the wall time what a user waits."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=1800)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if out.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed: {out.stderr[-2000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def _wall(cmd: list[str], env: dict[str, str] | None = None) -> float:
    return _timed(cmd, env)[0]


def warm_simulate(repeat: int) -> list[tuple[float, float]]:
    """(wall, CPU) seconds of ``isolab simulate`` on the article scene after one run that fills the cache."""
    cmd = [str(ISOLAB), "simulate", str(EXAMPLE)]
    _wall(cmd)
    return [_timed(cmd) for _ in range(repeat)]


def command_imports() -> dict[str, list[str]]:
    """Each ``isolab`` command and the modules its function imports (read from its source with ``ast``)."""
    from isolab.service.cli import app

    out = {}
    for command in app.registered_commands:
        fn = command.callback
        assert fn is not None
        tree = ast.parse(textwrap.dedent(inspect.getsource(fn)))
        mods = []
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                mods += [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                mods.append(node.module)
        out[command.name or fn.__name__] = sorted(set(mods))
    return out


def import_time(modules: list[str]) -> float:
    """Seconds a fresh process takes to import the CLI, then ``modules``."""
    lines = ["import time", "t0 = time.perf_counter()", "import isolab.service.cli"]
    lines += [f"import {m}" for m in modules]
    lines += ["print(time.perf_counter() - t0)"]
    out = subprocess.run(
        [sys.executable, "-c", "\n".join(lines)], capture_output=True, text=True, timeout=300
    )
    if out.returncode != 0:
        raise RuntimeError(out.stderr[-2000:])
    return float(out.stdout.split()[-1])


def cold_simulate(repeat: int) -> list[tuple[float, float]]:
    """(wall, CPU) seconds of the first ``isolab simulate`` of the article scene with an empty kernel
    cache."""
    runs = []
    for _ in range(repeat):
        with tempfile.TemporaryDirectory(prefix="isolab-cold-") as folder:
            env = {**os.environ, "NUMBA_CACHE_DIR": folder}
            runs.append(_timed([str(ISOLAB), "simulate", str(EXAMPLE)], env))
    return runs


_PER_PROCESS = f"""
import time
t0 = time.perf_counter()
from isolab.engine import simulate
from isolab.studies.inputs.study import load_scene, scene_batch
batch, _ = scene_batch(load_scene({str(EXAMPLE)!r}))
t1 = time.perf_counter()
simulate(batch, "ltv", "rk4", 1e-3)
t2 = time.perf_counter()
simulate(batch, "ltv", "rk4", 1e-3)
t3 = time.perf_counter()
print(t1 - t0, (t2 - t1) - (t3 - t2))
"""


def per_process(repeat: int) -> list[tuple[float, float]]:
    """(imports and scene, s; first call minus second call, s) of fresh processes on a warm cache."""
    out = []
    for _ in range(repeat):
        r = subprocess.run([sys.executable, "-c", _PER_PROCESS], capture_output=True, text=True, timeout=1800)
        if r.returncode != 0:
            raise RuntimeError(r.stderr[-2000:])
        a, b = (float(x) for x in r.stdout.split())
        out.append((a, b))
    return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="python -m benchmarks startup", description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3, help="fresh processes per warm figure (median)")
    ap.add_argument("--cold-repeat", type=int, default=3, help="empty-cache runs (median)")
    ap.add_argument("--no-cold", action="store_true", help="skip the empty-cache runs (minutes each)")
    args = ap.parse_args(argv)
    from isolab.engine import kernel_cache_folder

    print(f"start-up of the command line ({cpu_model()}; load {load()})")
    print(f"kernel cache: {kernel_cache_folder()}")
    med = statistics.median
    warm = warm_simulate(args.repeat)
    print(
        f"warm `isolab simulate article-scriber.yaml`, whole process: {_verdict(med(w for w, _ in warm), 1.5)}"
        f"  (CPU {med(c for _, c in warm):.2f} s; load {load()})"
    )
    print("imports of each command (CLI module and the command's own imports):")
    for name, mods in command_imports().items():
        t = med([import_time(mods) for _ in range(args.repeat)])
        print(f"  {name:<12} {_verdict(t, TARGETS['imports'])}")
    pp = per_process(args.repeat)
    print(
        f"fresh process, warm cache: imports and scene {med(a for a, _ in pp):.2f} s; first simulate call beyond a second one: {_verdict(med(b for _, b in pp), TARGETS['per process'])}"
    )
    if args.no_cold:
        print(f"cold first `isolab simulate` (empty cache): {_verdict(None, TARGETS['cold simulate'])}")
    else:
        cold = cold_simulate(args.cold_repeat)
        print(
            f"cold first `isolab simulate` (empty cache): "
            f"{_verdict(med(w for w, _ in cold), TARGETS['cold simulate'])}"
            f"  (CPU {med(c for _, c in cold):.1f} s, the figure to judge on a busy machine; load {load()})"
        )
    print(
        "fresh service, first study to first progress: not measured here (`python -m benchmarks first_study`)"
    )


if __name__ == "__main__":
    main()
