"""Real services for the tests and the benchmarks: ``isolab serve`` as a process of its own
(:class:`ServiceProcess`), or an app under uvicorn in a thread (:func:`thread_server`), each on a free
loopback port.

This is the one place that starts a live service: the benchmarks import it as ``benchmarks.live_service``,
and so do the tests (pytest puts the checkout on ``sys.path``), the browser tests among them. It lives
with the benchmarks, not the tests, because the benchmarks run without the test suite
(``python -m benchmarks ...``) while the tests already reuse the benchmarks' harness.
"""

from __future__ import annotations

import copy
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Self

import httpx
import uvicorn

from isolab.service.api.schemas import EXAMPLE_SCENE

ISOLAB = Path(sys.executable).with_name("isolab")
"""The ``isolab`` console script of the running interpreter's environment."""
HOST = "127.0.0.1"
SETTINGS_NOT_INHERITED = ("DASK_SCHEDULER_ADDRESS", "ISOLAB_API_TOKEN", "ISOLAB_DATA_DIR")
"""Settings of the caller's environment a started service does not take (it runs its own cluster on its
own data directory, without a token), unless the caller's ``env`` gives them."""
FINISHED = ("done", "failed", "cancelled")


class ServiceDidNotStart(RuntimeError):
    """``isolab serve`` exited, or did not answer ``/health`` with 200 in time; the message ends with the
    tail of its log."""


def free_port() -> int:
    """A TCP port of the loopback interface that nobody listens on just now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((HOST, 0))
        return int(s.getsockname()[1])


def serve_command(port: int, data_dir: Path, workers: int = 2) -> list[str]:
    """The command line of ``isolab serve`` on loopback ``port`` with its study store in ``data_dir``
    (through the interpreter when the environment has no ``isolab`` script)."""
    isolab = (
        [str(ISOLAB)]
        if ISOLAB.exists()
        else [sys.executable, "-c", "from isolab.service.cli import app; app()"]
    )
    return [
        *isolab,
        "serve",
        "--host",
        HOST,
        "--port",
        str(port),
        "--workers",
        str(workers),
        "--data",
        str(data_dir),
    ]


def quick_scene(
    duration: str = "2 s", dt: str = "2 ms", fidelity: str = "lti", integrator: str = "exact"
) -> dict[str, Any]:
    """The article's scriber (one Y stage), simulated cheaply (LTI, exact discretisation)."""
    scene = copy.deepcopy(EXAMPLE_SCENE)
    scene["simulation"] = {"fidelity": fidelity, "integrator": integrator, "dt": dt, "duration": duration}
    return scene


@contextmanager
def thread_server(app: Any, start_timeout: float = 90.0) -> Iterator[str]:
    """Serve ``app`` (with its lifespan) under uvicorn in a thread of this process; yields its base URL
    and stops it afterwards."""
    port = free_port()
    server = uvicorn.Server(uvicorn.Config(app, host=HOST, port=port, log_level="warning"))
    thread = threading.Thread(target=server.run, name="uvicorn", daemon=True)
    thread.start()
    deadline = time.monotonic() + start_timeout
    while not server.started:
        if not thread.is_alive():
            raise ServiceDidNotStart("the server stopped while starting")
        if time.monotonic() > deadline:
            server.should_exit = True
            raise ServiceDidNotStart(f"the server did not start within {start_timeout} s")
        time.sleep(0.05)
    try:
        yield f"http://{HOST}:{port}"
    finally:
        server.should_exit = True
        thread.join(60)
        if thread.is_alive():
            raise RuntimeError("the server did not stop")


class ServiceProcess:
    """``isolab serve`` in a session (process group) of its own, so that the uvicorn process, the Dask
    scheduler and the worker processes can be stopped or killed together.

    Args:
        data_dir: the study store directory (``--data``).
        workers: Dask worker processes (``--workers``).
        env: environment variables for the service, over the caller's (whose
            :data:`SETTINGS_NOT_INHERITED` are dropped first).
        log: where the service's output goes (appended); default ``<data_dir>-serve.log`` beside it.

    ``start()`` (or ``with``) waits until ``/health`` answers 200; ``stop()`` (or leaving the ``with``)
    ends the whole group: SIGTERM, then SIGKILL.
    """

    def __init__(
        self,
        data_dir: Path,
        workers: int = 2,
        env: Mapping[str, str] | None = None,
        log: Path | None = None,
    ):
        self.data_dir = Path(data_dir)
        self.workers = workers
        inherited = {k: v for k, v in os.environ.items() if k not in SETTINGS_NOT_INHERITED}
        self.env = {**inherited, **(env or {})}
        self.log = (
            Path(log) if log is not None else self.data_dir.with_name(self.data_dir.name + "-serve.log")
        )
        self.port = 0
        self.proc: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> str:
        """The service's base URL."""
        return f"http://{HOST}:{self.port}"

    @property
    def pid(self) -> int:
        """The id of the service process (and of its process group); 0 before it starts."""
        return self.proc.pid if self.proc is not None else 0

    def start(self, timeout: float = 90.0) -> Self:
        """Start the service on a free port and wait until ``/health`` answers 200; stops it and raises
        :class:`ServiceDidNotStart` when it exits or does not become healthy within ``timeout`` s."""
        self.port = free_port()
        self.log.parent.mkdir(parents=True, exist_ok=True)
        with open(self.log, "ab") as log:
            self.proc = subprocess.Popen(
                serve_command(self.port, self.data_dir, self.workers),
                stdout=log,
                stderr=subprocess.STDOUT,
                env=self.env,
                start_new_session=True,
            )
        deadline = time.monotonic() + timeout
        while True:
            if self.proc.poll() is not None:
                raise ServiceDidNotStart(f"isolab serve exited with {self.proc.returncode}: {self.tail()}")
            try:
                if httpx.get(self.url + "/health", timeout=2.0).status_code == 200:
                    return self
            except httpx.HTTPError:
                pass
            if time.monotonic() > deadline:
                self.stop()
                raise ServiceDidNotStart(f"isolab serve did not become healthy in {timeout} s: {self.tail()}")
            time.sleep(0.1)

    def tail(self, n: int = 2000) -> str:
        """The last ``n`` characters of the service's log."""
        try:
            return self.log.read_text(errors="replace")[-n:]
        except OSError:
            return ""

    def running(self) -> bool:
        """The service process has not exited."""
        return self.proc is not None and self.proc.poll() is None

    def group_alive(self) -> bool:
        """Some process of the service's process group is still running."""
        if self.proc is None:
            return False
        try:
            os.killpg(self.proc.pid, 0)
        except ProcessLookupError:
            return False
        return True

    def kill(self) -> None:
        """SIGKILL the whole process group (server, scheduler, nannies, workers) and reap the server."""
        if self.proc is None:
            return
        try:
            os.killpg(self.proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        self.proc.wait(30)
        deadline = time.monotonic() + 30
        while self.group_alive():  # the worker processes die with their group
            if time.monotonic() > deadline:
                raise RuntimeError("processes of the killed service are still running")
            time.sleep(0.05)

    def stop(self, timeout: float = 60.0) -> None:
        """Stop gracefully (SIGTERM to the group, ``timeout`` s to end), else kill."""
        if self.proc is None:
            return
        if self.proc.poll() is None:
            try:
                os.killpg(self.proc.pid, signal.SIGTERM)
                self.proc.wait(timeout)
            except (ProcessLookupError, subprocess.TimeoutExpired):
                pass
        if self.proc.poll() is None or self.group_alive():
            self.kill()

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


def wait_finished(http: httpx.Client, study_id: str, timeout: float = 60.0) -> dict[str, Any]:
    """Poll a study until it is done, failed or cancelled; its last status (TimeoutError after
    ``timeout`` s)."""
    deadline = time.monotonic() + timeout
    while True:
        info = http.get(f"/studies/{study_id}").json()
        if info["status"] in FINISHED:
            return info
        if time.monotonic() > deadline:
            raise TimeoutError(f"study still {info['status']} after {timeout} s: {info}")
        time.sleep(0.1)
