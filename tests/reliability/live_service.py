"""Real servers for the reliability tests: the app under uvicorn in a thread, or ``isolab serve`` as a
process of its own (which a test may kill), both on a free loopback port."""

from __future__ import annotations

import copy
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import httpx
import uvicorn

from isolab.service.api.schemas import EXAMPLE_SCENE

ISOLAB = Path(sys.executable).with_name("isolab")


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def quick_scene(
    duration: str = "2 s", dt: str = "2 ms", fidelity: str = "lti", integrator: str = "exact"
) -> dict:
    """The article's scriber (one Y stage), simulated cheaply (LTI, exact discretisation)."""
    scene = copy.deepcopy(EXAMPLE_SCENE)
    scene["simulation"] = {"fidelity": fidelity, "integrator": integrator, "dt": dt, "duration": duration}
    return scene


@contextmanager
def thread_server(app, start_timeout: float = 90.0) -> Iterator[str]:
    """Serve ``app`` (with its lifespan) under uvicorn in a thread; yields its base URL."""
    port = free_port()
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning"))
    thread = threading.Thread(target=server.run, name="uvicorn", daemon=True)
    thread.start()
    deadline = time.monotonic() + start_timeout
    while not server.started:
        assert thread.is_alive(), "the server stopped while starting"
        assert time.monotonic() < deadline, "the server did not start"
        time.sleep(0.05)
    try:
        yield f"http://127.0.0.1:{port}"
    finally:
        server.should_exit = True
        thread.join(60)
        assert not thread.is_alive(), "the server did not stop"


class ServiceProcess:
    """``isolab serve`` in a session (process group) of its own, so that the uvicorn process, the Dask
    scheduler and the worker processes can be killed together."""

    def __init__(
        self, data_dir: Path, workers: int = 2, env: dict[str, str] | None = None, log: Path | None = None
    ):
        self.data_dir = Path(data_dir)
        self.workers = workers
        self.env = {**os.environ, **(env or {})}
        self.env.pop("DASK_SCHEDULER_ADDRESS", None)
        self.log = log or self.data_dir.with_name(self.data_dir.name + "-serve.log")
        self.port = 0
        self.proc: subprocess.Popen | None = None

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def start(self, timeout: float = 90.0) -> ServiceProcess:
        self.port = free_port()
        cmd = [
            str(ISOLAB),
            "serve",
            "--host",
            "127.0.0.1",
            "--port",
            str(self.port),
            "--workers",
            str(self.workers),
            "--data",
            str(self.data_dir),
        ]
        with open(self.log, "ab") as log:
            self.proc = subprocess.Popen(
                cmd, stdout=log, stderr=subprocess.STDOUT, env=self.env, start_new_session=True
            )
        deadline = time.monotonic() + timeout
        while True:
            assert self.proc.poll() is None, f"isolab serve exited with {self.proc.returncode}: {self.tail()}"
            try:
                if httpx.get(self.url + "/health", timeout=2.0).status_code == 200:
                    return self
            except httpx.HTTPError:
                pass
            assert time.monotonic() < deadline, f"isolab serve did not become healthy: {self.tail()}"
            time.sleep(0.1)

    def tail(self, n: int = 2000) -> str:
        try:
            return self.log.read_text(errors="replace")[-n:]
        except OSError:
            return ""

    def group_alive(self) -> bool:
        """Some process of the server's process group is still running."""
        if self.proc is None:
            return False
        try:
            os.killpg(self.proc.pid, 0)
        except ProcessLookupError:
            return False
        return True

    def kill(self) -> None:
        """SIGKILL the whole process group (server, scheduler, nannies, workers) and reap the server."""
        assert self.proc is not None
        try:
            os.killpg(self.proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        self.proc.wait(30)
        deadline = time.monotonic() + 30
        while self.group_alive():  # the worker processes die with their group
            assert time.monotonic() < deadline, "processes of the killed server are still running"
            time.sleep(0.05)

    def stop(self) -> None:
        """Stop gracefully (SIGTERM), else kill."""
        if self.proc is None or self.proc.poll() is not None:
            if self.proc is not None and self.group_alive():
                self.kill()
            return
        try:
            os.killpg(self.proc.pid, signal.SIGTERM)
            self.proc.wait(60)
        except subprocess.TimeoutExpired:
            pass
        if self.group_alive():
            self.kill()

    def __enter__(self) -> ServiceProcess:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


def wait_finished(http: httpx.Client, study_id: str, timeout: float = 60.0) -> dict:
    """Poll a study until it is done, failed or cancelled; its last status."""
    deadline = time.monotonic() + timeout
    while True:
        info = http.get(f"/studies/{study_id}").json()
        if info["status"] in ("done", "failed", "cancelled"):
            return info
        assert time.monotonic() < deadline, f"study still {info['status']} after {timeout} s: {info}"
        time.sleep(0.1)
