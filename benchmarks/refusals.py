"""How fast ``POST /studies`` answers a big definition, and ``/health`` meanwhile (issue 13, item 4).

Run: ``python -m benchmarks.refusals [N ...]`` (default 600000 300000). Serves the app in a thread (one
Dask worker, a temporary store, the default limits: 1,000,000 cases, 10 MiB bodies) and POSTs, for each N,
a grid of 3 isolator types by N Y accelerations, once as numbers and once as text with units
(``"5000001 um/s^2"``), while a prober reads ``/health`` every 20 ms. Prints the status, the time to the
answer (upload included) and the prober's median and worst latency. An accepted study is cancelled at once.
"""

from __future__ import annotations

import json
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import httpx

from benchmarks.live_service import thread_server
from isolab.service.api.app import create_app
from isolab.service.api.schemas import EXAMPLE_SCENE
from isolab.service.settings import Settings


def big_study(n: int, units: bool) -> dict[str, Any]:
    """3 isolator types by ``n`` Y accelerations from 5 m/s^2 up in steps of 1 um/s^2 (3 n cases)."""
    values: list[Any] = [round(5.0 + i * 1e-6, 6) for i in range(n)]
    if units:  # the same accelerations in um/s^2: 600,000 of them fit in a 10 MiB body
        values = [f"{5_000_000 + i} um/s^2" for i in range(n)]
    scene = json.loads(json.dumps(EXAMPLE_SCENE))
    scene["simulation"] = {"fidelity": "lti", "integrator": "exact", "dt": "2 ms", "duration": "2 s"}
    return {
        "name": f"big-{n}",
        "scene": scene,
        "parameters": [
            {"path": "isolators.preset", "values": ["active", "air", "elastomer"]},
            {"path": "stages.y.profile.acceleration", "values": values},
        ],
        "design": {"type": "grid"},
    }


def post_and_probe(url: str, content: bytes) -> tuple[httpx.Response, float, list[float]]:
    """POST ``content`` to /studies while a prober reads /health: (response, seconds, probe latencies)."""
    latencies: list[float] = []
    stop = threading.Event()

    def probe() -> None:
        with httpx.Client(base_url=url, timeout=600.0) as h:
            while not stop.is_set():
                start = time.perf_counter()
                h.get("/health")
                latencies.append(time.perf_counter() - start)
                time.sleep(0.02)

    prober = threading.Thread(target=probe)
    prober.start()
    try:
        time.sleep(0.1)
        with httpx.Client(base_url=url, timeout=600.0) as http:
            start = time.perf_counter()
            r = http.post("/studies", content=content, headers={"content-type": "application/json"})
            took = time.perf_counter() - start
            if r.status_code == 202:
                http.delete(f"/studies/{r.json()['id']}")
        time.sleep(0.1)
    finally:
        stop.set()
        prober.join()
    return r, took, latencies


def main(argv: list[str]) -> None:
    sizes = [int(a) for a in argv] or [600_000, 300_000]
    with tempfile.TemporaryDirectory() as data:
        with thread_server(create_app(Settings(data_dir=Path(data), workers=1)), start_timeout=120.0) as url:
            httpx.get(f"{url}/health", timeout=60.0)
            for n in sizes:
                for units in (False, True):
                    content = json.dumps(big_study(n, units), separators=(",", ":")).encode()
                    r, took, lat = post_and_probe(url, content)
                    answer = r.json()
                    if r.status_code == 202:
                        what = f"{answer['n_cases']} cases"
                    else:
                        what = str(answer["detail"][0]["msg"] if r.status_code == 422 else answer["detail"])
                    print(
                        f"{n:>7} values as {'text' if units else 'numbers'} ({len(content) / 1e6:.1f} MB): "
                        f"{r.status_code} in {took:.2f} s ({what}); /health meanwhile: {len(lat)} reads, "
                        f"median {statistics.median(lat) * 1e3:.0f} ms, worst {max(lat) * 1e3:.0f} ms",
                        flush=True,
                    )


if __name__ == "__main__":
    main(sys.argv[1:])
