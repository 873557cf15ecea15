"""Faults done for real: a Dask worker process SIGKILLed while it runs a chunk, the service process group
SIGKILLed mid-study and started again on its data, a process SIGKILLed while it writes a study's netCDF
file, and studies the engine refuses at run time. Each study must end with every case exactly once."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import httpx
import numpy as np
import pytest
import xarray as xr
from dask.distributed import WorkerPlugin
from fastapi.testclient import TestClient

from benchmarks.live_service import ServiceProcess, quick_scene, wait_finished
from isolab.engine import simulate
from isolab.service.api.app import create_app
from isolab.service.settings import Settings
from isolab.studies.inputs.study import Study
from isolab.studies.results.store import Store, write_netcdf
from isolab.studies.run.fanout import LOST_WORKER_TIMEOUT_S, local_cluster

pytestmark = pytest.mark.slow  # services, clusters or processes of their own: `make test-fast` skips them

N = 240
MARK = "saved before the service was killed"


def long_chunks(duration: str = "2 s") -> dict:
    """240 cases of LTV, RK4 at 1 ms over 2 s (``duration`` to change it): the chunk plan's two chunks of 120
    cases at 2 s (four of 60 at 4 s), so that a fault lands while chunks run."""
    return {
        "name": "fault",
        "scene": quick_scene(duration=duration, dt="1 ms", fidelity="ltv", integrator="rk4"),
        "parameters": [
            {"path": "isolators.f_vertical", "range": {"start": "2 Hz", "stop": "6 Hz"}},
            {"path": "stages.y.mass", "range": {"start": "500 kg", "stop": "1500 kg"}},
        ],
        "design": {"type": "lhs", "samples": N, "seed": 11},
    }


def check_every_case_once(ds: xr.Dataset, definition: dict, sample: list[int]) -> None:
    """The dataset holds cases 0..N-1 once each, with the design's values and the engine's numbers."""
    study = Study.model_validate(definition)
    design = study.design()
    np.testing.assert_array_equal(ds.case.values, np.arange(study.n_cases))
    for name in design.names:
        np.testing.assert_array_equal(ds[name].values, design.values[name])
    assert int(np.count_nonzero(ds.status.values != 0)) == 0
    sim = study.simulation
    direct = simulate(study.batch(sample), fidelity=sim.fidelity, integrator=sim.integrator, dt=sim.dt)
    np.testing.assert_allclose(
        ds.peak_displacement.values[sample], direct.peak_displacement, rtol=1e-9, atol=1e-15
    )
    np.testing.assert_allclose(ds.natural_frequency.values[sample], direct.natural_frequency, rtol=1e-12)


# ----------------------------------------------------------------------------------- in-process app
@pytest.fixture(scope="module")
def app_client(tmp_path_factory: pytest.TempPathFactory):
    data = tmp_path_factory.mktemp("data")
    app = create_app(Settings(data_dir=data, workers=2))
    with TestClient(app) as http:
        yield app, http, data


def test_a_killed_workers_replacement_slower_than_dasks_wait_is_kept() -> None:
    """Dask closes a killed worker's nanny for good when the replacement has not joined within its
    ``lost-worker-timeout`` (15 s by default; a loaded machine's spawn and imports took longer). Here the
    process's setting is 0.5 s, shorter than any replacement takes: the cluster isolab starts waits
    ``LOST_WORKER_TIMEOUT_S`` instead, and keeps both workers."""
    import dask
    from distributed import Client

    with dask.config.set({"distributed.deploy.lost-worker-timeout": "0.5s"}):
        with local_cluster(2) as cluster, Client(cluster) as client:
            killed = next(iter(client.run(os.getpid).values()))
            os.kill(killed, signal.SIGKILL)
            deadline = time.monotonic() + 60
            while len(pids := set(client.run(os.getpid, on_error="ignore").values()) - {killed}) < 2:
                assert time.monotonic() < deadline, f"workers after the kill: {pids}"
                time.sleep(0.2)
            time.sleep(1.0)  # longer than the process's 0.5 s: Dask would have closed the nanny by now
            assert len(client.nthreads()) == 2 and len(cluster.workers) == 2
    assert LOST_WORKER_TIMEOUT_S >= 60


def test_a_worker_killed_mid_chunk_is_replaced_and_the_study_completes(app_client) -> None:
    app, http, data = app_client
    dask = app.state.dask
    before = dask.run(os.getpid)
    definition = long_chunks()
    sid = http.post("/studies", json=definition).json()["id"]
    # wait until a worker is running a chunk of this study (not merely holding one in its queue)
    deadline = time.monotonic() + 60
    victim = None
    while victim is None:
        executing = dask.run(
            lambda dask_worker: [k for k, ts in dask_worker.state.tasks.items() if ts.state == "executing"]
        )
        for address, keys in executing.items():
            if any(str(k).startswith(f"isolab-{sid}-chunk") for k in keys):
                victim = address
        assert time.monotonic() < deadline, "no chunk of the study started within 60 s"
        time.sleep(0.02)
    pid = before[victim]
    os.kill(pid, signal.SIGKILL)
    info = wait_finished(http, sid, timeout=120)
    assert info["status"] == "done", info
    assert info["progress"] == {"done": N, "total": N, "failed": 0}
    dask.wait_for_workers(2, timeout=60)  # the study may end on the other worker before the new one is up
    after = dask.run(os.getpid)
    assert pid not in after.values() and len(after) == 2  # the nanny started a new worker process
    ds = Store(data).open_dataset(sid)
    check_every_case_once(ds, definition, [0, N // 3, N - 1])
    assert not Store(data).chunk_dir(sid).exists()


class KillOnFinish(WorkerPlugin):
    """Kills its worker process (SIGKILL) when the worker starts a study's finishing task (or the task of
    ``kind``: ``"writer"``, the one that writes the dataset as the chunks land), once: the marker file says
    it happened (the nanny's new worker gets the plugin too, and must let the rerun through)."""

    name = "kill-on-finish"

    def __init__(self, marker: str, kind: str = "finish"):
        self.marker, self.kind = marker, kind

    def transition(self, key, start, finish, **kwargs) -> None:
        if finish == "executing" and f"-{self.kind}-" in str(key) and not os.path.exists(self.marker):
            Path(self.marker).write_text(str(key))
            os.kill(os.getpid(), signal.SIGKILL)


def run_killing(app, http, tmp_path: Path, kind: str, definition: dict) -> tuple[str, dict]:
    """Run ``definition`` on the app with the worker that starts the study's task of ``kind`` killed as it
    starts it (:class:`KillOnFinish`); the study's id and its final status, which must be done."""
    dask = app.state.dask
    marker = tmp_path / "killed"
    dask.wait_for_workers(2, timeout=60)  # a worker killed by the test before is back
    dask.register_plugin(KillOnFinish(str(marker), kind))
    try:
        sid = http.post("/studies", json=definition).json()["id"]
        info = wait_finished(http, sid, timeout=120)
    finally:
        dask.unregister_worker_plugin(KillOnFinish.name)
    assert marker.exists(), f"no {kind} task of study {sid} started: {info}"
    assert marker.read_text().startswith(f"isolab-{sid}-{kind}-")  # the kill happened, in that task
    assert info["status"] == "done", info
    return sid, info


def test_a_worker_killed_as_it_finishes_a_study_is_replaced_and_the_study_completes(
    app_client, tmp_path: Path
) -> None:
    # the dataset is assembled and written by a worker: kill that worker as the task starts
    app, http, data = app_client
    dask = app.state.dask
    before = set(dask.run(os.getpid).values())
    definition = long_chunks()
    sid, info = run_killing(app, http, tmp_path, "finish", definition)
    assert info["progress"] == {"done": N, "total": N, "failed": 0}
    # the nanny replaces the killed worker: the study may end on the other one before the new one is up
    dask.wait_for_workers(2, timeout=60)
    after = set(dask.run(os.getpid).values())
    assert len(after) == 2 and len(after - before) == 1
    check_every_case_once(Store(data).open_dataset(sid), definition, [0, N // 2, N - 1])
    assert not Store(data).chunk_dir(sid).exists()


# study definitions that pass validation and fail when the chunks run
ENGINE_REFUSES = {
    "mounts farther than the engine's 100 m": {
        # every position given is within the schema's 100 m; the mounts the layout puts around the
        # block's c.g. (x = 99.3 m +- 1.1 m) are not
        "name": "far-mounts",
        "scene": quick_scene()
        | {
            "machine": {
                "block": {
                    "size": ["2.6 m", "4.2 m", "0.34 m"],
                    "density": "2700 kg/m^3",
                    "corner": ["98 m", 0, 0],
                }
            },
            "stages": [
                {
                    "name": "y",
                    "mass": "1000 kg",
                    "home": ["99.3 m", "0.6 m", "0.47 m"],
                    "axis": [0, 1, 0],
                    "profile": {
                        "type": "trapezoid",
                        "travel": "3 m",
                        "velocity": "2 m/s",
                        "acceleration": "2 g",
                    },
                }
            ],
            "points": {"tool": ["99.3 m", 0.6, 0.6]},
        },
    },
}

COMBINATIONS_NO_MOUNT_CAN_CARRY = {
    "name": "combinations",
    "scene": quick_scene(),
    "parameters": [
        # each range alone is a valid scene; together the weight lies outside the mounts
        {"path": "stages.y.mass", "range": {"start": "4000 kg", "stop": "5000 kg"}},
        {"path": "isolators.layout.span_y", "range": {"start": "0.4 m", "stop": "0.5 m"}},
    ],
    "design": {"type": "lhs", "samples": 200_001},
}


def test_a_worker_killed_as_it_starts_writing_a_study_as_its_chunks_land_is_replaced(
    app_client, tmp_path: Path, monkeypatch
) -> None:
    # 2,400 cases in several chunks: the dataset is written as they land, by a task on one worker; kill that
    # worker as the task starts (the chunks it ran go elsewhere, the writer starts again on another)
    app, http, data = app_client
    monkeypatch.setenv("ISOLAB_LANDING_CASES", "2400")  # read by the runner, in this process
    definition = {
        **long_chunks(),
        "name": "landing-fault",
        "scene": quick_scene(duration="0.5 s", dt="1 ms", fidelity="lti", integrator="exact"),
        "design": {"type": "lhs", "samples": 2400, "seed": 11},
    }
    sid, info = run_killing(app, http, tmp_path, "writer", definition)
    assert info["progress"] == {"done": 2400, "total": 2400, "failed": 0}
    check_every_case_once(Store(data).open_dataset(sid), definition, [0, 1200, 2399])
    assert not Store(data).chunk_dir(sid).exists()


def test_combinations_no_mount_can_carry_are_refused_at_submission(app_client) -> None:
    # above the dry-run size, yet the cases that span the ranges (their corners) are built at submission:
    # a study whose every spanning case puts a mount under tension is a 422 naming the isolators, at once
    _, http, _ = app_client
    r = http.post("/studies", json=COMBINATIONS_NO_MOUNT_CAN_CARRY)
    assert r.status_code == 422, r.text
    (detail,) = r.json()["detail"]
    assert detail["loc"][:3] == ["body", "scene", "isolators"]
    assert "would carry a static load" in detail["msg"]


@pytest.mark.parametrize("definition", list(ENGINE_REFUSES.values()), ids=list(ENGINE_REFUSES))
def test_a_study_the_engine_refuses_is_failed_with_the_reason(app_client, definition: dict) -> None:
    app, http, data = app_client
    r = http.post("/studies", json=definition)
    assert r.status_code == 202, r.text  # valid as a definition
    info = wait_finished(http, r.json()["id"], timeout=120)
    assert info["status"] == "failed", info
    assert info["error"].startswith("FanoutError: every chunk failed")
    assert ("coordinates beyond 100" in info["error"]) or ("would carry a static load" in info["error"])
    assert info["finished"] is not None
    # the service keeps serving: healthy, and the next study runs to the end
    assert http.get("/health").status_code == 200
    good = {
        "name": "after-a-failure",
        "scene": quick_scene(),
        "parameters": [{"path": "isolators.preset", "values": ["air", "elastomer"]}],
    }
    info = wait_finished(http, http.post("/studies", json=good).json()["id"])
    assert info["status"] == "done" and info["progress"] == {"done": 2, "total": 2, "failed": 0}


# ---------------------------------------------------------------------- the service process killed
def test_the_service_killed_mid_study_resumes_from_its_saved_chunks(tmp_path: Path) -> None:
    data = tmp_path / "data"
    definition = long_chunks("4 s")  # four chunks: the kill comes after the first two at most
    service = ServiceProcess(data, workers=2).start()
    try:
        with httpx.Client(base_url=service.url, timeout=30.0) as http:
            sid = http.post("/studies", json=definition).json()["id"]
            deadline = time.monotonic() + 90
            while (info := http.get(f"/studies/{sid}").json())["progress"]["done"] < N // 4:
                assert info["status"] in ("queued", "running"), info
                assert time.monotonic() < deadline, info
                time.sleep(0.02)
        service.kill()  # SIGKILL to the server, the scheduler, the nannies and the workers at once
        assert not service.group_alive()
    finally:
        service.stop()

    store = Store(data)
    row = store.get(sid)
    assert row["status"] == "running" and row["finished"] is None  # nobody had the chance to tidy up
    plan = store.load_chunk_plan(sid)
    saved = store.load_chunks(sid)
    assert plan is not None and 1 <= len(saved) < len(plan)
    # mark the saved chunks: a resumed run keeps them, a rerun from scratch would overwrite the mark
    kept = []
    for k, arrays in saved.items():
        arrays = dict(arrays)
        arrays["message"] = np.array([MARK] * len(arrays["status"]))
        store.save_chunk(sid, k, arrays)
        kept += plan[k].tolist()

    with ServiceProcess(data, workers=2) as again, httpx.Client(base_url=again.url, timeout=30.0) as http:
        info = wait_finished(http, sid, timeout=120)
        assert info["status"] == "done", info
        assert info["progress"] == {"done": N, "total": N, "failed": 0}
        rows = http.get(
            f"/studies/{sid}/cases", params={"columns": "case,status,message", "limit": N}
        ).json()["rows"]
    assert [r["case"] for r in rows] == list(range(N))  # every case, once, in order
    assert {r["status"] for r in rows} == {"ok"}
    assert sorted(r["case"] for r in rows if r["message"] == MARK) == sorted(kept)
    assert all(r["message"] == "" for r in rows if r["case"] not in set(kept))
    ds = Store(data).open_dataset(sid)
    fresh = [c for c in range(N) if c not in set(kept)]
    check_every_case_once(ds, definition, [kept[0], kept[-1], fresh[0], fresh[-1]])
    assert not Store(data).chunk_dir(sid).exists()


# ---------------------------------------------------------------------------- a write interrupted
WRITER = textwrap.dedent(
    """
    import sys
    import numpy as np
    import xarray as xr
    from isolab.studies.results.store import write_netcdf

    target, rows = sys.argv[1], int(sys.argv[2])
    rng = np.random.default_rng(7)
    ds = xr.Dataset(
        {f"v{i}": (("case", "k"), rng.standard_normal((rows, 64))) for i in range(4)},
        coords={"case": np.arange(rows)},
        attrs={"version": "new"},
    )
    print("writing", flush=True)
    write_netcdf(ds, target)
    print("written", flush=True)
    """
)


def new_dataset(rows: int) -> xr.Dataset:
    rng = np.random.default_rng(7)
    return xr.Dataset(
        {f"v{i}": (("case", "k"), rng.standard_normal((rows, 64))) for i in range(4)},
        coords={"case": np.arange(rows)},
        attrs={"version": "new"},
    )


def temp_files(directory: Path, target: Path) -> list[Path]:
    return sorted(directory.glob(f".{target.name}.*.tmp"))


@pytest.mark.parametrize("kill_at_bytes", [0, 1_000_000], ids=["as-it-starts", "part-way"])
def test_a_write_killed_half_way_leaves_the_old_file_whole(tmp_path: Path, kill_at_bytes: int) -> None:
    store = Store(tmp_path)
    sid = store.create({"name": "old"}, name="old", n_cases=3)
    target = store.path(sid)
    old = xr.Dataset({"v0": (("case",), np.array([1.0, 2.0, 3.0]))}, attrs={"version": "old"})
    write_netcdf(old, target)
    rows = 16_000  # 4 x 16,000 x 64 float64: about 33 MB to compress and write, about a second
    writer = subprocess.Popen(
        [sys.executable, "-c", WRITER, str(target), str(rows)], stdout=subprocess.PIPE, text=True
    )
    try:
        assert writer.stdout.readline().strip() == "writing"
        deadline = time.monotonic() + 60
        while True:
            tmp = temp_files(target.parent, target)
            if tmp and tmp[0].stat().st_size >= kill_at_bytes:
                break
            assert writer.poll() is None, "the writer finished before it could be interrupted"
            assert time.monotonic() < deadline
            time.sleep(0.002)
        writer.send_signal(signal.SIGKILL)
        writer.wait(30)
    finally:
        if writer.poll() is None:
            writer.kill()
    assert writer.returncode == -signal.SIGKILL
    # the visible file is the old one, whole
    with xr.open_dataset(target) as ds:
        assert ds.attrs["version"] == "old"
        np.testing.assert_array_equal(ds.v0.values, [1.0, 2.0, 3.0])
    assert store.open_dataset(sid).attrs["version"] == "old"
    # the torn temporary file is left behind, hidden, and nothing takes it for a study
    leftovers = temp_files(target.parent, target)
    assert len(leftovers) == 1
    assert store.dataset_ids() == [sid]
    assert [r["id"] for r in store.list()] == [sid]
    assert store.done_chunks(sid) == set()

    # the same write, not interrupted, replaces the file whole
    done = subprocess.run(
        [sys.executable, "-c", WRITER, str(target), str(rows)], capture_output=True, text=True
    )
    assert done.returncode == 0 and done.stdout.split() == ["writing", "written"], done.stderr
    with xr.open_dataset(target) as ds:
        assert ds.attrs["version"] == "new"
        expected = new_dataset(rows)
        for name in expected.data_vars:
            np.testing.assert_array_equal(ds[name].values, expected[name].values)
    assert temp_files(target.parent, target) == leftovers  # only the killed writer's file remains
    assert store.dataset_ids() == [sid]


def test_a_chunk_write_killed_half_way_is_not_taken_for_a_saved_chunk(tmp_path: Path) -> None:
    store = Store(tmp_path)
    sid = store.create({"name": "chunks"}, name="chunks", n_cases=10)
    script = textwrap.dedent(
        f"""
        import numpy as np
        from isolab.studies.results.store import Store
        store = Store({str(tmp_path)!r})
        store.save_chunk({sid!r}, 0, {{"status": np.zeros(10, dtype=np.int8)}})
        print("saved", flush=True)
        store.save_chunk({sid!r}, 1, {{"status": np.zeros(20_000_000, dtype=np.int8),
                                       "big": np.ones((20_000_000,), dtype=np.float64)}})
        print("saved", flush=True)
        """
    )
    writer = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    try:
        assert writer.stdout.readline().strip() == "saved"
        chunk_dir = store.chunk_dir(sid)
        deadline = time.monotonic() + 60
        while not [p for p in chunk_dir.glob(".1.npz.*.tmp") if p.stat().st_size > 1_000_000]:
            assert writer.poll() is None, "the writer finished before it could be interrupted"
            assert time.monotonic() < deadline
            time.sleep(0.001)
        os.kill(writer.pid, signal.SIGKILL)
        writer.wait(30)
    finally:
        if writer.poll() is None:
            writer.kill()
    assert store.done_chunks(sid) == {0}
    chunks = store.load_chunks(sid)
    assert list(chunks) == [0] and chunks[0]["status"].shape == (10,)


# --------------------------------------------------------------------- netCDF from several threads
HAMMER = textwrap.dedent(
    """
    import sys, threading, time
    import numpy as np, xarray as xr
    from isolab.studies.answers.history import netcdf_bytes
    from isolab.studies.results.store import Store

    store = Store(sys.argv[1])
    ids = [store.create({"n": i}, name=f"s{i}", n_cases=2000) for i in range(3)]

    def dataset(i):
        return xr.Dataset({"v": (("case", "k"), np.full((2000, 50), float(i)))}, attrs={"i": i})

    for i, sid in enumerate(ids):
        store.write_dataset(sid, dataset(i))
    stop = time.monotonic() + float(sys.argv[2])
    wrong = []

    def writer(i):  # a study finishing: its dataset is written
        while time.monotonic() < stop:
            store.write_dataset(ids[i], dataset(i))

    def reader(i):  # a request reading a finished study
        while time.monotonic() < stop:
            if float(store.open_dataset(ids[i]).v[0, 0]) != i:
                wrong.append(i)

    def download(i):  # a request for a case's time histories as netCDF
        while time.monotonic() < stop:
            netcdf_bytes(dataset(i))

    threads = [threading.Thread(target=f, args=(i,)) for i in range(3) for f in (writer, reader, download)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    print("wrong", len(wrong))
    """
)


def test_netcdf_reads_and_writes_from_many_threads_do_not_crash_the_process(tmp_path: Path) -> None:
    """The service writes finished studies from its job threads while request threads read datasets and
    build netCDF downloads; the netCDF-C library is not thread-safe, so without one lock around it the
    process dies of a segmentation fault within seconds."""
    run = subprocess.run(
        [sys.executable, "-c", HAMMER, str(tmp_path), "3"], capture_output=True, text=True, timeout=120
    )
    assert run.returncode == 0, (run.returncode, run.stderr[-2000:])
    assert run.stdout.split() == ["wrong", "0"]
