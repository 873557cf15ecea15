"""A service restart in the middle of a study: the next start resumes it from its saved chunks and the
dataset holds every case exactly once."""

from __future__ import annotations

import copy
import time
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient

from isolab.engine import simulate
from isolab.service.api.app import create_app
from isolab.service.api.schemas import EXAMPLE_SCENE
from isolab.service.settings import Settings
from isolab.studies.inputs.study import Study
from isolab.studies.results.store import Store

pytestmark = pytest.mark.slow  # services, clusters or processes of their own: `make test-fast` skips them

N = 480
MARK = "kept from the first run"


def definition() -> dict:
    scene = copy.deepcopy(EXAMPLE_SCENE)
    # 4,000 RK4 steps a case: the runner sizes chunks of 85 cases (about 1 s each by its cost model), so
    # 480 cases make 6 chunks and most of the study is still to run when the service stops after the first
    # chunk (the two workers may finish the chunks they hold meanwhile), even on a quiet machine
    scene["simulation"] = {"fidelity": "ltv", "integrator": "rk4", "dt": "1 ms", "duration": "4 s"}
    return {
        "name": "restart",
        "scene": scene,
        "parameters": [
            {"path": "isolators.f_vertical", "range": {"start": "2 Hz", "stop": "6 Hz"}},
            {"path": "stages.y.mass", "range": {"start": "500 kg", "stop": "1500 kg"}},
        ],
        "design": {"type": "lhs", "samples": N, "seed": 3},
    }


def test_restart_mid_study_resumes_and_loses_nothing(tmp_path: Path) -> None:
    settings = Settings(data_dir=tmp_path, workers=2)
    with TestClient(create_app(settings)) as http:
        sid = http.post("/studies", json=definition()).json()["id"]
        deadline = time.monotonic() + 60
        while True:
            info = http.get(f"/studies/{sid}").json()
            if info["progress"]["done"] > 0 or info["status"] not in ("queued", "running"):
                break
            assert time.monotonic() < deadline, "no chunk finished within 60 s"
            time.sleep(0.05)
        assert info["status"] == "running", info
    # the app is shut down: the study waits to resume, its finished chunks are on disk
    store = Store(tmp_path)
    row = store.get(sid)
    assert row["status"] == "queued" and row["finished"] is None
    saved = store.load_chunks(sid)
    plan = store.load_chunk_plan(sid)
    assert saved and plan is not None and len(saved) < len(plan)
    # (workers save their chunks themselves: one running at the shutdown may land after the last count)
    assert 0 < row["n_done"] <= sum(len(a["status"]) for a in saved.values()) < N
    # mark the saved chunks: a resumed run keeps them, a rerun from scratch would overwrite the mark
    kept = []
    for k, arrays in saved.items():
        arrays = dict(arrays)
        arrays["message"] = np.array([MARK] * len(arrays["status"]))
        store.save_chunk(sid, k, arrays)
        kept += plan[k].tolist()

    app = create_app(settings)
    with TestClient(app) as http:
        assert app.state.jobs.resumed == [sid]
        deadline = time.monotonic() + 60
        while (info := http.get(f"/studies/{sid}").json())["status"] in ("queued", "running"):
            assert time.monotonic() < deadline, info
            time.sleep(0.1)
        assert info["status"] == "done", info
        assert info["progress"] == {"done": N, "total": N, "failed": 0}
        rows = http.get(
            f"/studies/{sid}/cases", params={"columns": "case,status,message,peak_displacement_y", "limit": N}
        ).json()["rows"]

    # every case exactly once, in order, all computed
    assert [r["case"] for r in rows] == list(range(N))
    assert {r["status"] for r in rows} == {"ok"}
    assert sorted(r["case"] for r in rows if r["message"] == MARK) == sorted(kept)
    assert all(r["message"] == "" for r in rows if r["case"] not in set(kept))
    ds = Store(tmp_path).open_dataset(sid)
    study = Study.model_validate(definition())
    design = study.design()
    np.testing.assert_array_equal(ds.case.values, np.arange(N))
    for name in design.names:
        np.testing.assert_array_equal(ds[name].values, design.values[name])
    # cases from the first run and from the resumed one carry the engine's numbers
    sample = [kept[0], kept[-1], *[c for c in (0, N // 2, N - 1) if c not in kept][:2]]
    sim = study.simulation
    direct = simulate(study.batch(sample), fidelity=sim.fidelity, integrator=sim.integrator, dt=sim.dt)
    np.testing.assert_allclose(
        ds.peak_displacement.values[sample], direct.peak_displacement, rtol=1e-9, atol=1e-15
    )
    assert not Store(tmp_path).chunk_dir(sid).exists()


def test_job_queue_order_cancel_and_stop(tmp_path: Path) -> None:
    """The queue's own bookkeeping, with a runner that works until it is cancelled (no cluster)."""
    from isolab.service.api.jobs import JobQueue

    started: list[str] = []

    def runner(study, store, client, study_id, cancel) -> str:
        started.append(study_id)
        store.update(study_id, status="running")
        cancel.wait(30)
        store.update(study_id, status="cancelled")  # as run_study does when cancelled
        return study_id

    store = Store(tmp_path)
    ids = [
        store.create({"name": f"s{i}"}, name=f"s{i}", n_cases=1, created=f"2030-01-01T00:00:0{i}")
        for i in range(3)
    ]
    finished = store.create({"name": "f"}, name="f", n_cases=1)  # done, its chunks left by a stop
    store.save_chunk(finished, 0, {"status": np.zeros(1, np.int8)})
    store.update(finished, status="done")
    jobs = JobQueue(tmp_path, client=None, concurrency=1, runner=runner, loader=dict)
    assert jobs.start() == ids  # oldest first
    assert not store.chunk_dir(finished).exists()  # swept at the start
    deadline = time.monotonic() + 10
    while started != ids[:1]:
        assert time.monotonic() < deadline
        time.sleep(0.01)
    assert jobs.queued() == ids[1:] and jobs.running() == ids[:1]
    # a queued study is cancelled for good and never runs
    assert jobs.cancel(ids[1]) is True
    assert store.get(ids[1])["status"] == "cancelled" and jobs.queued() == [ids[2]]
    assert jobs.cancel("f" * 32) is False
    # shutdown: the running study goes back to queued (not cancelled), the waiting one stays queued
    jobs.stop(timeout=10)
    assert started == ids[:1]
    assert [store.get(i)["status"] for i in ids] == ["queued", "cancelled", "queued"]
    # the next start takes both up again, in order; a user's cancel of the running one sticks
    again = JobQueue(tmp_path, client=None, concurrency=1, runner=runner, loader=dict)
    assert again.start() == [ids[0], ids[2]]
    while started != [ids[0], ids[0]]:
        assert time.monotonic() < deadline
        time.sleep(0.01)
    assert again.cancel(ids[0], wait=10) is True
    assert store.get(ids[0])["status"] == "cancelled"
    while started != [ids[0], ids[0], ids[2]]:
        assert time.monotonic() < deadline
        time.sleep(0.01)
    again.stop(timeout=10)
    assert store.get(ids[2])["status"] == "queued"
