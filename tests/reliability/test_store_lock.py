"""One service per data directory: a second ``isolab serve`` on a directory a running service holds
refuses to start, with a message naming the holder; a killed service does not block its restart."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import httpx
import pytest
from fastapi.testclient import TestClient

from benchmarks.live_service import ServiceProcess, free_port, serve_command
from isolab.service.api.app import create_app
from isolab.service.settings import Settings
from isolab.studies.results.store import StoreInUse, StoreLock

HOLDER = textwrap.dedent(
    """
    import sys, time
    from isolab.studies.results.store import StoreLock
    StoreLock(sys.argv[1]).acquire()
    print("held", flush=True)
    time.sleep(60)
    """
)


def test_the_store_lock_is_one_process_at_a_time_and_dies_with_its_holder(tmp_path: Path) -> None:
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(tmp_path)], stdout=subprocess.PIPE, text=True
    )
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(StoreInUse, match=f"in use by another isolab service \\(pid {holder.pid} on "):
            StoreLock(tmp_path).acquire()
        # the app refuses to start on it (before it starts a cluster)
        app = create_app(Settings(data_dir=tmp_path, workers=1))
        with pytest.raises(StoreInUse), TestClient(app):
            pass
        holder.kill()  # SIGKILL: the kernel releases the lock
        holder.wait(10)
        with StoreLock(tmp_path) as lock, StoreLock(tmp_path):  # shared within one process
            assert f"pid {os.getpid()} on " in lock.path.read_text()
        with StoreLock(tmp_path):  # released by the last holder of this process
            pass
    finally:
        holder.kill()
        holder.wait(10)


def serve(data: Path) -> subprocess.Popen:
    """``isolab serve`` on ``data`` with its output to read (it is expected to refuse to start)."""
    return subprocess.Popen(
        serve_command(free_port(), data, workers=1),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,
    )


@pytest.mark.slow  # services of their own
def test_a_second_service_on_the_same_data_directory_refuses_to_start(tmp_path: Path) -> None:
    data = tmp_path / "data"
    first = ServiceProcess(data, workers=1).start()
    try:
        second = serve(data)
        try:
            out, _ = second.communicate(timeout=30)  # it refuses before it starts a cluster
        except subprocess.TimeoutExpired:
            os.killpg(second.pid, signal.SIGKILL)
            out, _ = second.communicate()
            pytest.fail(f"a second service started on a data directory in use: {out[-2000:]}")
        assert second.returncode != 0
        assert "in use by another isolab service" in out, out
        assert str(data.resolve()) in out and f"pid {first.proc.pid}" in out, out
        assert "Traceback" not in out, out
        # the first one is untouched
        assert httpx.get(first.url + "/health", timeout=10).status_code == 200
        first.kill()  # SIGKILL: no clean-up, the lock goes with the process
        t0 = time.monotonic()
        with ServiceProcess(data, workers=1) as again:
            assert httpx.get(again.url + "/health", timeout=10).status_code == 200
        assert time.monotonic() - t0 < 90
    finally:
        first.stop()
