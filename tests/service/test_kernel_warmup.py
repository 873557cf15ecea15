"""The service warms the engine's kernels on its workers at start: compiled once per machine (one worker per
pair), then loaded on every worker; ``/health``, a waiting study and the web page say so meanwhile."""

from __future__ import annotations

import sys
import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

import pytest
from fastapi.testclient import TestClient

from isolab.service.api import kernel_warmup
from isolab.service.api.app import create_app
from isolab.service.api.kernel_warmup import COMPILING_NOTE, KernelWarmup
from isolab.service.settings import Settings
from isolab.studies.run.error_estimate import REFERENCE_PAIR
from isolab.studies.run.kernel_cache import example_pairs
from tests.service.test_api import scene, wait_done


@pytest.fixture(autouse=True)
def warmup_on(monkeypatch: pytest.MonkeyPatch) -> None:
    """The suite turns the warm-up off (tests/conftest.py); here it is what is tested."""
    monkeypatch.setenv(kernel_warmup.WARMUP_ENV, "on")


class StubClient:
    """A Dask client's ``submit`` and ``nthreads`` on a thread pool: the plan answers ``cached``,
    and each compile or load task waits for ``release`` and records what it warmed and where."""

    def __init__(self, cached: bool, fail: bool = False):
        self.cached = cached
        self.fail = fail
        self.release = threading.Event()
        self.calls: list[tuple[str, list[tuple[str, str]], Any]] = []
        self.pool = ThreadPoolExecutor(4)

    def nthreads(self) -> dict[str, int]:
        return {"tcp://a": 1, "tcp://b": 1}

    def submit(self, func: Any, *args: Any, workers: list[str] | None = None, **kw: Any) -> Future:
        if func is kernel_warmup.warmup_plan:
            return self.pool.submit(lambda: ([("lti", "exact"), ("ltv", "rk4"), REFERENCE_PAIR], self.cached))
        assert func is kernel_warmup.warm_kernels
        assert kw["priority"] < -1e6, "the warm-up goes after every study task"
        # each worker's own task also imports what writes a study's dataset (its first finish waits less)
        assert kw.get("datasets", False) is (workers is not None)

        def warm() -> dict[str, float]:
            self.release.wait(30)
            if self.fail:
                raise RuntimeError("no memory")
            kind = "load" if workers is not None else "compile"
            self.calls.append((kind, list(args[0]), workers))
            return {}

        return self.pool.submit(warm)


ONE_CASE = {
    "name": "warm-up",
    "scene": scene(),
    "parameters": [{"path": "isolators.preset", "values": ["air"]}],
    "design": {"type": "grid"},
}


def wait_state(warmup: KernelWarmup, *states: str, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while warmup.state not in states:
        assert time.monotonic() < deadline, f"still {warmup.state}, not {states}"
        time.sleep(0.01)


def test_an_empty_cache_compiles_each_pair_once_then_every_worker_loads_them():
    client = StubClient(cached=False)
    warmup = KernelWarmup()
    assert warmup.busy and warmup.report()["seconds"] is None
    warmup.start(client)
    wait_state(warmup, "compiling")
    report = warmup.report()
    assert report["note"] == COMPILING_NOTE == "compiling the engine's kernels (first start only)"
    assert report["pairs"] == ["lti/exact", "ltv/rk4", "nonlinear/reference"]
    client.release.set()
    wait_state(warmup, "ready")
    compiled = [pairs for kind, pairs, _ in client.calls if kind == "compile"]
    loaded = {tuple(where) for kind, _, where in client.calls if kind == "load"}
    # each pair compiles in one task (one worker), then each worker loads them all once
    assert sorted(p for pairs in compiled for p in pairs) == sorted(
        [("lti", "exact"), ("ltv", "rk4"), REFERENCE_PAIR]
    )
    assert all(len(pairs) == 1 for pairs in compiled)
    assert loaded == {("tcp://a",), ("tcp://b",)}
    assert [kind for kind, _, _ in client.calls].index("load") == len(compiled), "loads follow the compiles"
    assert not warmup.busy and warmup.note() is None and warmup.report()["seconds"] >= 0


def test_a_warm_cache_only_loads_and_a_failure_leaves_studies_to_compile_themselves():
    client = StubClient(cached=True)
    warmup = KernelWarmup()
    warmup.start(client)
    wait_state(warmup, "loading")
    assert warmup.note() == kernel_warmup.LOADING_NOTE
    client.release.set()
    wait_state(warmup, "ready")
    assert {kind for kind, _, _ in client.calls} == {"load"}

    broken = StubClient(cached=True, fail=True)  # a worker that cannot warm
    broken.release.set()
    warmup = KernelWarmup()
    warmup.start(broken)
    wait_state(warmup, "failed")
    assert "no memory" in (warmup.error or "") and warmup.note() is None and not warmup.busy


def test_the_warm_up_covers_the_examples_pairs_and_the_reference():
    pairs = example_pairs()
    assert ("ltv", "rk4") in pairs and ("lti", "exact") in pairs  # article-scriber.yaml, lhs-10000.yaml
    assert pairs[-1] == REFERENCE_PAIR and len(set(pairs)) == len(pairs)


@pytest.mark.slow
def test_a_study_submitted_while_the_workers_warm_up_says_so_and_finishes(tmp_path):
    settings = Settings(data_dir=tmp_path / "data", workers=2)
    with TestClient(create_app(settings)) as http:
        health = http.get("/health")
        assert health.status_code == 200  # the warm-up never makes the service unhealthy
        first = health.json()["kernels"]
        assert first["state"] in ("starting", "loading", "compiling", "ready")
        sid = http.post("/studies", json=ONE_CASE).json()["id"]
        notes, states = set(), [first["state"]]
        deadline = time.monotonic() + 100
        while True:
            info = http.get(f"/studies/{sid}").json()
            notes.add(info["note"])
            states.append(http.get("/health").json()["kernels"]["state"])
            if states[-1] == "ready" and info["status"] == "done":
                break
            assert time.monotonic() < deadline, (info, states)
            time.sleep(0.05)
        done = wait_done(http, sid)
        assert done["progress"]["done"] == 1 and done["note"] is None
        assert states.index("ready") >= 0 and "failed" not in states
        # the order of states only moves forward
        order = ["starting", "compiling", "loading", "ready"]
        assert [order.index(s) for s in states] == sorted(order.index(s) for s in states)
        # a note only while waiting, and only the warm-up's
        assert notes <= {None, kernel_warmup.LOADING_NOTE, COMPILING_NOTE}
        # every worker has the studies and the engine imported before its first chunk
        dask = http.app.state.dask
        imported = dask.run(
            lambda: "isolab.studies.run.fanout" in sys.modules and "isolab.engine" in sys.modules
        )
        assert all(imported.values()) and len(imported) == 2
        report = http.get("/health").json()["kernels"]
        assert report["pairs"][-1] == "nonlinear/reference" and report["seconds"] > 0


def test_the_warm_up_can_be_turned_off(monkeypatch):
    monkeypatch.setenv(kernel_warmup.WARMUP_ENV, "off")
    client = StubClient(cached=False)
    warmup = KernelWarmup()
    warmup.start(client)
    assert warmup.state == "off" and not warmup.busy and warmup.note() is None and not client.calls


def test_a_workers_warm_up_writes_a_dataset_first_and_leaves_no_file(tmp_path, monkeypatch):
    # a fresh process: the first dataset it writes loads xarray's array-library lookups and the netCDF
    # backend; after the warm-up those are loaded, and its temporary folder is gone
    import subprocess

    script = (
        "import sys, tempfile\n"
        "from isolab.studies.run.kernel_cache import warm_datasets\n"
        "before = {m for m in ('xarray', 'netCDF4') if m in sys.modules}\n"
        "warm_datasets()\n"
        "print(sorted(before), 'xarray' in sys.modules, 'netCDF4' in sys.modules)\n"
    )
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    out = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=60, check=True
    )
    assert out.stdout.split() == ["[]", "True", "True"], out.stdout + out.stderr
    assert list(tmp_path.iterdir()) == []


def test_a_dataset_warm_up_that_cannot_write_is_no_error(tmp_path, monkeypatch):
    # a full temporary disk: the warm-up says so and goes on (the first study pays the imports instead)
    import tempfile

    from isolab.studies.run.kernel_cache import warm_datasets

    def full(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(tempfile, "TemporaryDirectory", full)
    assert warm_datasets() is False


def test_a_warm_up_loads_both_drivers_of_a_linear_pair() -> None:
    # a fresh process: the warm-up's case goes through the output map's driver, its recorded rerun through
    # the general observer's, so a worker has either at hand for its first chunk (a moving floor, say)
    import subprocess

    script = (
        "from isolab.engine.integrators.stepping import ENTRIES\n"
        "from isolab.studies.run.kernel_cache import warm_kernels\n"
        "warm_kernels([('lti', 'exact'), ('nonlinear', 'euler')])\n"
        "print([len(d.signatures) for d in ENTRIES['exact', 'lti'] + ENTRIES['euler', 'nonlinear']])\n"
        "print([len(d.signatures) for d in ENTRIES['rk4', 'ltv']])\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=110, check=False
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.split("\n")[:2] == ["[1, 1, 1]", "[0, 0]"]
