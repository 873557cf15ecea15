"""Load on the REST API: many clients submitting small studies while a 100,000-case study runs.

Run: ``python -m benchmarks.load [--clients 50] [--window 60] [--big-cases 100000]`` (``make load``).

Starts ``isolab serve`` as a subprocess on a free loopback port with a temporary data directory and 2 Dask
workers, runs a warm-up study (the workers load the compiled kernels), submits the big study, then:

* ``--clients`` clients (asyncio tasks sharing one httpx client pool), started at random moments of the
  first poll period, each submit a small study (4 cases), poll it every ``--poll`` s (+- 10 %) until it
  is done, and start the next, until ``--window`` s have passed; then the studies still running are
  waited for (at most ``--drain`` s);
* a probe in a process of its own reads ``GET /studies/{big}`` every 20 ms while the big study runs: its
  latencies are the figure of merit (target: p99 < 100 ms).

At the end the big study is cancelled if it is still running and the server is stopped. Everything is
bounded: the whole run stops by itself within ``--budget`` s (default 120). Prints the latency
percentiles, studies per second, request counts and errors; exits 1 when a request failed, a small study
did not end done, or the probe's p99 is over the target.
"""

from __future__ import annotations

import argparse
import asyncio
import copy
import json
import multiprocessing as mp
import os
import random
import shutil
import signal
import statistics
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx

from benchmarks.live_service import ServiceProcess
from isolab.service.api.schemas import EXAMPLE_SCENE

TARGET_P99_S = 0.100
CLIENT_NICENESS = 0
"""Nice value of the clients' process (``--client-niceness``): 0, the clients compete with the server."""
PROBE_PERIOD_S = 0.020

SCENE: dict[str, Any] = {
    **copy.deepcopy(EXAMPLE_SCENE),
    "simulation": {"fidelity": "lti", "integrator": "exact", "dt": "2 ms", "duration": "1 s"},
}
"""The API's example scene (the article's scriber with its Y stage), simulated for 1 s."""


def small_study(n: int) -> dict[str, Any]:
    """4 cases: two isolator types x two Y accelerations."""
    return {
        "name": f"load-small-{n}",
        "scene": copy.deepcopy(SCENE),
        "parameters": [
            {"path": "isolators.preset", "values": ["air", "elastomer"]},
            {"path": "stages.y.profile.acceleration", "values": ["1 g", "2 g"]},
        ],
    }


def big_study(cases: int) -> dict[str, Any]:
    """A Latin hypercube over isolator frequency and Y stage mass."""
    return {
        "name": "load-big",
        "scene": copy.deepcopy(SCENE),
        "parameters": [
            {"path": "isolators.f_vertical", "range": {"start": "2 Hz", "stop": "6 Hz"}},
            {"path": "stages.y.mass", "range": {"start": "500 kg", "stop": "1500 kg"}},
        ],
        "design": {"type": "lhs", "samples": cases, "seed": 1},
    }


def percentile(values: list[float], q: float) -> float:
    if not values:
        return float("nan")
    s = sorted(values)
    return s[min(len(s) - 1, max(0, round(q / 100.0 * (len(s) - 1))))]


# -------------------------------------------------------------------------------------------- probe
def probe(url: str, study_id: str, until: float, out: mp.Queue) -> None:
    """In a process of its own: GET the big study every PROBE_PERIOD_S while it runs; put
    (latencies in s, statuses seen, errors, (time, latency) of answers over the target) on ``out``."""
    latencies: list[float] = []
    slow: list[tuple[float, float]] = []  # (Unix time, latency) of the answers over the target
    errors: list[str] = []
    statuses: dict[str, int] = {}
    with httpx.Client(base_url=url, timeout=10.0) as http:
        while time.time() < until:
            t0 = time.perf_counter()
            try:
                r = http.get(f"/studies/{study_id}")
                dt = time.perf_counter() - t0
                if r.status_code != 200:
                    errors.append(f"GET /studies/{{big}}: {r.status_code}")
                else:
                    status = r.json()["status"]
                    statuses[status] = statuses.get(status, 0) + 1
                    if status != "running":
                        if status in ("done", "failed", "cancelled"):
                            break
                        time.sleep(PROBE_PERIOD_S)
                        continue
                    latencies.append(dt)
                    if dt > TARGET_P99_S:
                        slow.append((round(time.time(), 3), round(dt, 4)))
            except httpx.HTTPError as err:
                errors.append(f"GET /studies/{{big}}: {type(err).__name__}: {err}")
            time.sleep(max(0.0, PROBE_PERIOD_S - (time.perf_counter() - t0)))
    out.put((latencies, statuses, errors, slow))


# ------------------------------------------------------------------------------------------ clients
@dataclass
class Tally:
    submitted: int = 0
    finished: dict[str, int] = field(default_factory=dict)
    unfinished: int = 0
    requests: int = 0
    errors: list[str] = field(default_factory=list)
    post_latency: list[float] = field(default_factory=list)
    get_latency: list[float] = field(default_factory=list)
    turnaround: list[float] = field(default_factory=list)


async def timed(
    tally: Tally, what: str, latencies: list[float], expected: int, request: Any
) -> httpx.Response | None:
    """Await ``request``, count it, and keep its latency (s) in ``latencies``; None (and the error
    tallied under ``what``) when it fails or answers another status than ``expected``."""
    t0 = time.perf_counter()
    try:
        r = await request
    except httpx.HTTPError as err:
        tally.requests += 1
        tally.errors.append(f"{what}: {type(err).__name__}: {err}")
        return None
    tally.requests += 1
    latencies.append(time.perf_counter() - t0)
    if r.status_code != expected:
        tally.errors.append(f"{what}: {r.status_code} {r.text[:200]}")
        return None
    return r


async def client(
    n: int, http: httpx.AsyncClient, tally: Tally, window_end: float, drain_end: float, poll: float
) -> None:
    # engineers do not start their clients in the same millisecond: each starts at a random moment of
    # the first poll period and polls every poll s +- 10 % (else 50 clients poll in lockstep)
    rng = random.Random(n)
    await asyncio.sleep(rng.uniform(0.0, poll))
    k = 0
    while time.monotonic() < window_end:
        k += 1
        t0 = time.perf_counter()  # the study's turnaround starts with its POST
        r = await timed(
            tally,
            "POST /studies",
            tally.post_latency,
            202,
            http.post("/studies", json=small_study(n * 1000 + k)),
        )
        if r is None:
            continue
        tally.submitted += 1
        sid = r.json()["id"]
        status = "queued"
        while time.monotonic() < drain_end:
            await asyncio.sleep(poll * rng.uniform(0.9, 1.1))
            r = await timed(tally, "GET /studies/{id}", tally.get_latency, 200, http.get(f"/studies/{sid}"))
            if r is None:
                continue
            status = r.json()["status"]
            if status in ("done", "failed", "cancelled"):
                break
        if status in ("done", "failed", "cancelled"):
            tally.finished[status] = tally.finished.get(status, 0) + 1
            tally.turnaround.append(time.perf_counter() - t0)
        else:
            tally.unfinished += 1
            return


async def run_clients(url: str, clients: int, window_end: float, drain_end: float, poll: float) -> Tally:
    tally = Tally()
    limits = httpx.Limits(
        max_connections=clients + 10, max_keepalive_connections=clients + 10, keepalive_expiry=2.0
    )
    async with httpx.AsyncClient(base_url=url, timeout=30.0, limits=limits) as http:
        await asyncio.gather(*(client(n, http, tally, window_end, drain_end, poll) for n in range(clients)))
    return tally


def wait_done(url: str, study_id: str, deadline: float) -> dict[str, Any]:
    with httpx.Client(base_url=url, timeout=10.0) as http:
        while True:
            info = http.get(f"/studies/{study_id}").json()
            if info["status"] in ("done", "failed", "cancelled") or time.monotonic() > deadline:
                return info
            time.sleep(0.1)


# --------------------------------------------------------------------------------------------- main
def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.load", description=__doc__.split("\n\n")[0])
    parser.add_argument("--clients", type=int, default=50, help="concurrent clients (default 50)")
    parser.add_argument("--window", type=float, default=60.0, help="seconds of submitting (default 60)")
    parser.add_argument("--drain", type=float, default=25.0, help="seconds to wait for the last studies")
    parser.add_argument(
        "--poll",
        type=float,
        default=0.5,
        help="seconds between a client's polls (default 0.5, as the Python client)",
    )
    parser.add_argument("--big-cases", type=int, default=100_000, help="cases of the big study")
    parser.add_argument("--workers", type=int, default=2, help="Dask workers of the server")
    parser.add_argument("--budget", type=float, default=120.0, help="hard limit of the whole run, s")
    parser.add_argument("--json", type=Path, default=None, help="also write the figures to this file")
    parser.add_argument(
        "--client-niceness",
        type=int,
        default=CLIENT_NICENESS,
        help="nice value of the clients' process (default 0: at the server's priority)",
    )
    args = parser.parse_args(argv)
    # stopped from outside (`timeout`, Ctrl-C): still stop the server and its workers
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))

    start = time.monotonic()
    hard_end = start + args.budget
    tmp = Path(tempfile.mkdtemp(prefix="isolab-load-"))
    server = ServiceProcess(tmp / "data", args.workers, log=tmp / "serve.log")
    result: dict[str, Any] = {}
    failures: list[str] = []
    try:
        server.start(timeout=min(hard_end - time.monotonic(), 60.0))
        url = server.url
        with httpx.Client(base_url=url, timeout=30.0) as http:
            warm = http.post("/studies", json=small_study(0)).json()["id"]
            wait_done(url, warm, time.monotonic() + 30)
            t_big = time.monotonic()
            r = http.post("/studies", json=big_study(args.big_cases))
            if r.status_code != 202:
                raise RuntimeError(f"the big study was refused: {r.status_code} {r.text[:300]}")
            big = r.json()["id"]
        setup_s = time.monotonic() - start
        # leave room for draining and stopping within the budget
        window = max(5.0, min(args.window, args.budget - setup_s - args.drain - 20.0))
        window_end = time.monotonic() + window
        drain_end = min(window_end + args.drain, hard_end - 15.0)
        results: mp.Queue = mp.get_context("spawn").Queue()
        prober = mp.get_context("spawn").Process(
            target=probe, args=(url, big, time.time() + (drain_end - time.monotonic()), results)
        )
        prober.start()
        # the clients stand in for machines on the network; on this machine they share its cores with the
        # server, at the same priority unless --client-niceness says otherwise
        if args.client_niceness:
            os.nice(args.client_niceness)
        t0 = time.monotonic()
        tally = asyncio.run(run_clients(url, args.clients, window_end, drain_end, args.poll))
        elapsed = time.monotonic() - t0
        latencies, probe_statuses, probe_errors, slow = results.get(
            timeout=max(5.0, drain_end - time.monotonic() + 10)
        )
        prober.join(10)
        with httpx.Client(base_url=url, timeout=30.0) as http:
            info = http.get(f"/studies/{big}").json()
            big_rate = info["progress"]["done"] / max(1e-9, time.monotonic() - t_big)
            if info["status"] in ("queued", "running"):
                http.delete(f"/studies/{big}")
    finally:
        server.stop(timeout=20.0)
        shutil.rmtree(tmp / "data", ignore_errors=True)  # the server's log stays, for a failed run

    done = tally.finished.get("done", 0)
    result = {
        "clients": args.clients,
        "window_s": round(window, 1),
        "small_studies": {"submitted": tally.submitted, **tally.finished, "unfinished": tally.unfinished},
        "studies_per_s": round(done / elapsed, 2),
        "requests": tally.requests + sum(probe_statuses.values()),
        "errors": len(tally.errors) + len(probe_errors),
        "big_study": {
            "cases": args.big_cases,
            "status_at_end": info["status"],
            "cases_done": info["progress"]["done"],
            "cases_per_s": round(big_rate, 1),
        },
        "probe_get_big": {
            "n": len(latencies),
            "p50_ms": round(1e3 * percentile(latencies, 50), 1),
            "p99_ms": round(1e3 * percentile(latencies, 99), 1),
            "max_ms": round(1e3 * max(latencies, default=float("nan")), 1),
        },
        "clients_get": {
            "n": len(tally.get_latency),
            "p50_ms": round(1e3 * percentile(tally.get_latency, 50), 1),
            "p99_ms": round(1e3 * percentile(tally.get_latency, 99), 1),
        },
        "clients_post": {
            "n": len(tally.post_latency),
            "p50_ms": round(1e3 * percentile(tally.post_latency, 50), 1),
            "p99_ms": round(1e3 * percentile(tally.post_latency, 99), 1),
        },
        "turnaround_s": {
            "p50": round(percentile(tally.turnaround, 50), 2),
            "p99": round(percentile(tally.turnaround, 99), 2),
            "mean": round(statistics.fmean(tally.turnaround), 2) if tally.turnaround else None,
        },
        "slow_probe_answers": slow,
        "total_s": round(time.monotonic() - start, 1),
    }
    print(
        f"load: {args.clients} clients for {window:.0f} s on {url} ({args.workers} workers), "
        f"big study of {args.big_cases} cases running"
    )
    print(
        f"  small studies: {tally.submitted} submitted, {done} done, "
        f"{tally.finished.get('failed', 0)} failed, {tally.unfinished} unfinished; "
        f"{result['studies_per_s']} studies/s; turnaround p50 {result['turnaround_s']['p50']} s, "
        f"p99 {result['turnaround_s']['p99']} s"
    )
    print(f"  requests: {result['requests']}, errors: {result['errors']}")
    print(
        f"  GET /studies/{{big}} while it runs (probe, {len(latencies)} requests): "
        f"p50 {result['probe_get_big']['p50_ms']} ms, p99 {result['probe_get_big']['p99_ms']} ms, "
        f"max {result['probe_get_big']['max_ms']} ms (target p99 < {TARGET_P99_S * 1e3:.0f} ms)"
    )
    print(
        f"  clients' GET /studies/{{id}}: p50 {result['clients_get']['p50_ms']} ms, "
        f"p99 {result['clients_get']['p99_ms']} ms; POST /studies: p50 {result['clients_post']['p50_ms']} ms, "
        f"p99 {result['clients_post']['p99_ms']} ms"
    )
    print(
        f"  big study: {info['progress']['done']} of {args.big_cases} cases in the run "
        f"({result['big_study']['cases_per_s']} cases/s), {info['status']} at the end"
    )
    print(f"  total {result['total_s']} s")
    for e in (tally.errors + probe_errors)[:10]:
        print(f"  error: {e}")
    if tally.errors or probe_errors:
        failures.append(f"{len(tally.errors) + len(probe_errors)} requests failed")
    if tally.unfinished or tally.finished.get("failed") or tally.finished.get("cancelled"):
        failures.append("not every small study ended done")
    if not latencies:
        failures.append("the probe saw the big study running no time")
    elif percentile(latencies, 99) > TARGET_P99_S:
        failures.append(f"p99 of GET /studies/{{big}} is {1e3 * percentile(latencies, 99):.0f} ms")
    result["failures"] = failures
    if args.json is not None:
        args.json.write_text(json.dumps(result, indent=2))
    print("PASS" if not failures else "FAIL: " + "; ".join(failures))
    return 0 if not failures else 1


if __name__ == "__main__":
    sys.exit(main())
