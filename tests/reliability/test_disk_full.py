"""A full disk while a study writes: at chunk-write time and at dataset-write time, for real (a small
tmpfs filled up, where the test may mount one) and by injecting ENOSPC into the write (everywhere).

Each time the study must end ``failed`` with the cause in ``error`` ("no space left on device: ... needs
about N MB ..."), the catalog must keep answering (never 500), ``/health`` must say the store is degraded
while the disk is full, and once there is room again the same study, resubmitted, must complete."""

from __future__ import annotations

import errno
import os
import subprocess
from pathlib import Path

import pytest
from dask.distributed import WorkerPlugin
from fastapi.testclient import TestClient

from benchmarks.live_service import quick_scene, wait_finished
from isolab.service.api.app import create_app
from isolab.service.settings import Settings

pytestmark = pytest.mark.slow  # a service with a cluster of its own

STAGES = {"chunk": "-chunk-", "dataset": "-finish-"}
"""Where the disk fills: as a chunk task starts (its results are saved at its end), or as the task that
assembles and writes the study's dataset starts."""


def definition(name: str) -> dict:
    return {
        "name": name,
        "scene": quick_scene(),
        "parameters": [{"path": "isolators.preset", "values": ["air", "elastomer"]}],
    }


def fill(path: str) -> None:
    """Write ``path`` until the file system has no byte left."""
    with open(path, "ab") as f:
        for block in (1 << 20, 1 << 16, 1 << 12, 1):
            try:
                while True:
                    f.write(b"\0" * block)
                    f.flush()
            except OSError as err:
                assert err.errno == errno.ENOSPC, err


class FillDisk(WorkerPlugin):
    """Fills the disk (a ballast file) when its worker starts a task whose key holds ``key_part``, once
    (the marker file, elsewhere, says it happened)."""

    name = "fill-disk"

    def __init__(self, ballast: str, key_part: str, marker: str):
        self.ballast, self.key_part, self.marker = ballast, key_part, marker

    def transition(self, key, start, finish, **kwargs) -> None:
        if finish == "executing" and self.key_part in str(key) and not os.path.exists(self.marker):
            Path(self.marker).write_text(str(key))
            fill(self.ballast)


class NoSpace(WorkerPlugin):
    """Makes its worker's chunk saves (``numpy.savez``) or netCDF writes (``Dataset.to_netcdf``) raise
    ``OSError(ENOSPC)`` until it is removed."""

    name = "no-space"

    def __init__(self, stage: str):
        self.stage = stage

    def setup(self, worker) -> None:
        import numpy
        import xarray

        def refuse(*args, **kwargs):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

        owner, attr = (numpy, "savez") if self.stage == "chunk" else (xarray.Dataset, "to_netcdf")
        self.restore = (owner, attr, getattr(owner, attr))
        setattr(owner, attr, refuse)

    def teardown(self, worker) -> None:
        owner, attr, original = self.restore
        setattr(owner, attr, original)


def check_failed_for_want_of_space(http: TestClient, sid: str) -> None:
    info = wait_finished(http, sid, timeout=120)
    assert info["status"] == "failed", info
    assert info["error"].startswith("no space left on device: writing "), info["error"]
    assert " MB" in info["error"] and info["finished"] is not None
    # the catalog keeps answering
    assert http.get(f"/studies/{sid}").status_code == 200
    listing = http.get("/studies")
    assert listing.status_code == 200 and sid in [s["id"] for s in listing.json()["items"]]


def check_a_resubmission_completes(http: TestClient, name: str) -> None:
    r = http.post("/studies", json=definition(name + "-again"))
    assert r.status_code == 202, r.text
    info = wait_finished(http, r.json()["id"], timeout=120)
    assert info["status"] == "done" and info["progress"] == {"done": 2, "total": 2, "failed": 0}, info
    assert http.get(f"/studies/{r.json()['id']}/dataset").status_code == 200


# ------------------------------------------------------------------------------- ENOSPC injected
@pytest.fixture(scope="module")
def app_client(tmp_path_factory: pytest.TempPathFactory):
    app = create_app(Settings(data_dir=tmp_path_factory.mktemp("data"), workers=1))
    with TestClient(app) as http:
        yield app, http


@pytest.mark.parametrize("stage", list(STAGES))
def test_enospc_injected_fails_the_study_with_the_cause_and_a_resubmission_completes(
    app_client, stage: str
) -> None:
    app, http = app_client
    app.state.dask.register_plugin(NoSpace(stage))
    try:
        sid = http.post("/studies", json=definition(f"enospc-{stage}")).json()["id"]
        check_failed_for_want_of_space(http, sid)
    finally:
        app.state.dask.unregister_worker_plugin(NoSpace.name)
    assert http.get("/health").status_code == 200  # the disk itself has room
    check_a_resubmission_completes(http, f"enospc-{stage}")


# ------------------------------------------------------------------------------- a real full disk
@pytest.fixture(scope="module")
def small_disk(tmp_path_factory: pytest.TempPathFactory):
    """A 16 MB tmpfs (mounting needs root, or CAP_SYS_ADMIN); skipped where mounting is not permitted."""
    mnt = tmp_path_factory.mktemp("small-disk")
    run = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=16m", "tmpfs", str(mnt)], capture_output=True, text=True
    )
    if run.returncode != 0:
        pytest.skip(
            f"cannot mount a small tmpfs here ({run.stderr.strip() or run.returncode}); "
            "the ENOSPC-injection tests cover the behaviour"
        )
    try:
        yield mnt
    finally:
        if subprocess.run(["umount", str(mnt)], capture_output=True).returncode != 0:
            subprocess.run(["umount", "-l", str(mnt)], check=True)  # a file still open: detach it


@pytest.fixture(scope="module")
def full_disk_client(small_disk: Path):
    app = create_app(Settings(data_dir=small_disk / "data", workers=1))
    with TestClient(app) as http:
        yield app, http


@pytest.mark.parametrize("stage", list(STAGES))
def test_a_full_disk_fails_the_study_with_the_cause_and_a_resubmission_completes(
    full_disk_client, small_disk: Path, tmp_path: Path, stage: str
) -> None:
    app, http = full_disk_client
    ballast = small_disk / "ballast"
    marker = tmp_path / "filled"
    app.state.dask.register_plugin(FillDisk(str(ballast), STAGES[stage], str(marker)))
    try:
        sid = http.post("/studies", json=definition(f"full-{stage}")).json()["id"]
        check_failed_for_want_of_space(http, sid)
        assert marker.read_text().startswith(f"isolab-{sid}{STAGES[stage]}")  # it filled at that stage
        # /health says the store cannot take writes, and why; other routes answer, never with a 500
        health = http.get("/health")
        assert health.status_code == 503, health.text
        store = health.json().get("store")
        if store is not None:  # (without the token a health answer may carry the status only)
            assert store["writable"] is False and "no space left on device" in store["error"]
        for path in ("/studies", f"/studies/{sid}", f"/studies/{sid}/cases", f"/studies/{sid}/dataset"):
            assert http.get(path).status_code != 500, path
        r = http.post("/studies", json=definition(f"full-{stage}-while-full"))
        assert r.status_code in (202, 503), r.text
        if r.status_code == 202:
            wait_finished(http, r.json()["id"], timeout=120)
    finally:
        app.state.dask.unregister_worker_plugin(FillDisk.name)
        ballast.unlink(missing_ok=True)
    # room again: healthy, and the study runs to the end
    health = http.get("/health")
    assert health.status_code == 200, health.text
    check_a_resubmission_completes(http, f"full-{stage}")
