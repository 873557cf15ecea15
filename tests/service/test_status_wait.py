"""``GET /studies/{id}?wait=``: a status request that waits on the service for its study to end.

The routes run on a small app with the studies router and a real :class:`JobQueue` whose runner holds a
study running until the test lets it end (no cluster): the answer must come as soon as the study ends,
at the bound while it runs, at once for a study that is not queued or running, and a bad ``wait`` is a
422 naming it.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

import anyio
import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient

from isolab.service.api.jobs import GONE_STEP_S, JobQueue, wait_for_end
from isolab.service.api.routes import studies
from isolab.service.api.routes.studies import MAX_WAIT_S
from isolab.service.client import STATUS_WAIT_S, Client
from isolab.studies.results.store import Store


class HeldStudies:
    """A job queue whose runner keeps each study ``running`` until :meth:`end` lets it be ``done``."""

    def __init__(self, root: Path):
        self.store = Store(root)
        self.release = threading.Event()
        self.started = threading.Event()

        def runner(study, store, client, study_id, cancel) -> str:
            store.update(study_id, status="running")
            self.started.set()
            self.release.wait(60)
            store.update(study_id, status="done", n_done=1)
            return study_id

        self.jobs = JobQueue(root, client=None, concurrency=1, runner=runner, loader=dict)
        self.jobs.start()

    def new_study(self) -> str:
        study_id = self.store.create({"name": "held"}, name="held", n_cases=1)
        self.jobs.submit(study_id)
        assert self.started.wait(10), "the study did not start"
        return study_id

    def end_after(self, seconds: float) -> None:
        threading.Timer(seconds, self.release.set).start()


@pytest.fixture
def held(tmp_path: Path):
    queue = HeldStudies(tmp_path)
    yield queue
    queue.release.set()
    queue.jobs.stop(timeout=10)


@pytest.fixture
def http(held: HeldStudies):
    app = FastAPI()
    app.include_router(studies.router)
    app.state.jobs = held.jobs  # what the lifespan sets; the store is the queue's
    with TestClient(app) as client:
        yield client


def test_the_bound_of_the_service_and_of_the_client_agree() -> None:
    assert MAX_WAIT_S == STATUS_WAIT_S == 30.0


def test_a_waiting_status_answers_as_soon_as_the_study_ends(held: HeldStudies, http: TestClient) -> None:
    study_id = held.new_study()
    held.end_after(0.5)
    t0 = time.monotonic()
    r = http.get(f"/studies/{study_id}", params={"wait": 20})
    seconds = time.monotonic() - t0
    assert r.status_code == 200, r.text
    assert r.json()["status"] == "done" and r.json()["progress"]["done"] == 1
    assert 0.45 <= seconds < 2.0, seconds  # not before the end, and far from the 20 s bound


def test_a_waiting_status_answers_at_its_bound_while_the_study_runs(
    held: HeldStudies, http: TestClient
) -> None:
    study_id = held.new_study()
    t0 = time.monotonic()
    r = http.get(f"/studies/{study_id}", params={"wait": 0.4})
    seconds = time.monotonic() - t0
    assert r.status_code == 200 and r.json()["status"] == "running"
    assert 0.4 <= seconds < 1.5, seconds
    # without wait the answer comes at once
    t0 = time.monotonic()
    assert http.get(f"/studies/{study_id}").json()["status"] == "running"
    assert time.monotonic() - t0 < 0.4


def test_a_study_not_running_answers_at_once(held: HeldStudies, http: TestClient) -> None:
    study_id = held.new_study()
    held.release.set()
    t0 = time.monotonic()
    while held.jobs.is_active(study_id):
        assert time.monotonic() - t0 < 10
        time.sleep(0.01)
    t0 = time.monotonic()
    assert http.get(f"/studies/{study_id}", params={"wait": 20}).json()["status"] == "done"
    r = http.get(f"/studies/{'f' * 32}", params={"wait": 20})
    assert r.status_code == 404
    assert time.monotonic() - t0 < 1.0


def test_the_clients_wait_sees_the_end_at_once(held: HeldStudies, http: TestClient) -> None:
    """With 5 s between progress reports, the client still learns of the end within a moment of it."""
    api = Client("http://testserver")
    api._http = http  # the in-process app's transport
    study_id = held.new_study()
    seen: list[str] = []
    held.end_after(0.5)
    t0 = time.monotonic()
    info = api.wait(study_id, progress=lambda s: seen.append(s["status"]), poll=5.0, timeout=20)
    assert info["status"] == "done" and seen == ["done"]
    assert time.monotonic() - t0 < 2.0


@pytest.mark.parametrize("wait", ["-1", "31", "nan", "inf", "soon"])
def test_a_bad_wait_is_refused_naming_it(held: HeldStudies, http: TestClient, wait: str) -> None:
    study_id = held.new_study()
    r = http.get(f"/studies/{study_id}", params={"wait": wait})
    assert r.status_code == 422, r.text
    assert r.json()["detail"][0]["loc"] == ["query", "wait"]


def test_a_waiting_status_stops_when_its_client_goes_away(held: HeldStudies) -> None:
    study_id = held.new_study()

    class GoneClient:
        async def is_disconnected(self) -> bool:
            return True

    t0 = time.monotonic()
    assert anyio.run(wait_for_end, held.jobs, study_id, 20.0, GoneClient()) is False
    assert time.monotonic() - t0 < 0.5
    held.end_after(0.2)
    assert anyio.run(wait_for_end, held.jobs, study_id, 20.0) is True
    assert held.store.get(study_id)["status"] == "done"


def test_a_client_that_goes_away_while_waiting_is_let_go_within_half_a_second(held: HeldStudies) -> None:
    study_id = held.new_study()
    gone_at = time.monotonic() + 0.3

    class LeavingClient:
        async def is_disconnected(self) -> bool:
            return time.monotonic() >= gone_at

    assert anyio.run(wait_for_end, held.jobs, study_id, 20.0, LeavingClient()) is False
    assert time.monotonic() - gone_at < GONE_STEP_S + 0.3
    held.end_after(0.0)
    assert anyio.run(wait_for_end, held.jobs, study_id, 5.0) is True


def test_the_end_of_a_run_calls_its_listeners_once_and_a_taken_back_one_never(held: HeldStudies) -> None:
    study_id = held.new_study()
    called: list[str] = []
    assert held.jobs.on_end("0" * 32, lambda: called.append("never")) is None  # not queued nor running
    held.jobs.on_end(study_id, lambda: called.append("kept"))
    forget = held.jobs.on_end(study_id, lambda: called.append("taken back"))
    assert forget is not None
    forget()
    t0 = time.monotonic()
    held.end_after(0.0)
    while not called and time.monotonic() - t0 < 10:
        time.sleep(0.01)
    time.sleep(0.1)
    assert called == ["kept"] and held.store.get(study_id)["status"] == "done"
    assert held.jobs.on_end(study_id, lambda: called.append("late")) is None
