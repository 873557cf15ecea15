"""Service foundation: CLI entry point, settings from the environment, app lifespan and /health."""

from __future__ import annotations

import dataclasses
import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest
from distributed import LocalCluster
from fastapi.testclient import TestClient
from typer.testing import CliRunner

from isolab.service.api.app import create_app, free_dashboard_address
from isolab.service.cli import app as cli_app
from isolab.service.settings import ENV_VARS, Settings, SettingsError, load_settings

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture
def clean_env(monkeypatch: pytest.MonkeyPatch) -> pytest.MonkeyPatch:
    for variable in ENV_VARS.values():
        monkeypatch.delenv(variable, raising=False)
    return monkeypatch


# --- CLI -------------------------------------------------------------------------------------------


def test_cli_help_lists_serve() -> None:
    result = CliRunner().invoke(cli_app, ["--help"])
    assert result.exit_code == 0
    assert "serve" in result.output


def test_installed_console_script_runs() -> None:
    script = Path(sys.executable).parent / "isolab"
    assert script.is_file(), "the isolab console script is not installed (pip install -e '.[test]')"
    result = subprocess.run([str(script), "--help"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert "serve" in result.stdout


def test_serve_refuses_a_bad_environment_before_starting(clean_env: pytest.MonkeyPatch) -> None:
    clean_env.setenv("ISOLAB_WORKERS", "two")
    result = CliRunner().invoke(cli_app, ["serve", "--port", "8999"])
    assert result.exit_code == 2
    assert "ISOLAB_WORKERS" in result.output
    assert "'two'" in result.output


# --- settings --------------------------------------------------------------------------------------


def test_defaults_without_environment(clean_env: pytest.MonkeyPatch) -> None:
    settings = load_settings()
    assert settings.data_dir == Path("./data")
    assert settings.scheduler_address is None
    assert settings.workers == 2
    assert settings.api_token is None
    assert settings.max_cases == 1_000_000
    assert settings.max_body_bytes == 10 * 1024 * 1024
    assert settings.cors_origins == ()


def test_environment_is_parsed(clean_env: pytest.MonkeyPatch, tmp_path: Path) -> None:
    clean_env.setenv("ISOLAB_DATA_DIR", str(tmp_path / "store"))
    clean_env.setenv("DASK_SCHEDULER_ADDRESS", " tcp://scheduler:8786 ")
    clean_env.setenv("ISOLAB_WORKERS", "3")
    clean_env.setenv("ISOLAB_API_TOKEN", "s3cret")
    clean_env.setenv("ISOLAB_MAX_CASES", "5000")
    clean_env.setenv("ISOLAB_MAX_BODY_BYTES", "2048")
    clean_env.setenv("ISOLAB_CORS_ORIGINS", "https://a.example, http://localhost:3000,")
    settings = load_settings()
    assert settings == Settings(
        data_dir=tmp_path / "store",
        scheduler_address="tcp://scheduler:8786",
        workers=3,
        api_token="s3cret",
        max_cases=5000,
        max_body_bytes=2048,
        cors_origins=("https://a.example", "http://localhost:3000"),
    )


def test_empty_variables_count_as_unset(clean_env: pytest.MonkeyPatch) -> None:
    clean_env.setenv("DASK_SCHEDULER_ADDRESS", "")
    clean_env.setenv("ISOLAB_API_TOKEN", "  ")
    clean_env.setenv("ISOLAB_WORKERS", "")
    settings = load_settings()
    assert settings.scheduler_address is None
    assert settings.api_token is None
    assert settings.workers == 2


def test_overrides_win_over_environment(clean_env: pytest.MonkeyPatch) -> None:
    clean_env.setenv("ISOLAB_WORKERS", "3")
    assert load_settings(workers=1).workers == 1
    with pytest.raises(TypeError, match="wokers"):
        load_settings(wokers=1)


@pytest.mark.parametrize(
    ("variable", "value"),
    [
        ("ISOLAB_WORKERS", "0"),
        ("ISOLAB_WORKERS", "-1"),
        ("ISOLAB_WORKERS", "two"),
        ("ISOLAB_MAX_CASES", "0"),
        ("ISOLAB_MAX_BODY_BYTES", "1.5"),
        ("ISOLAB_CORS_ORIGINS", "example.com"),
    ],
)
def test_bad_environment_value_names_the_variable(
    clean_env: pytest.MonkeyPatch, variable: str, value: str
) -> None:
    clean_env.setenv(variable, value)
    with pytest.raises(SettingsError, match=variable) as excinfo:
        load_settings()
    assert value in str(excinfo.value)


def test_bad_override_names_the_variable(clean_env: pytest.MonkeyPatch) -> None:
    with pytest.raises(SettingsError, match="ISOLAB_WORKERS"):
        load_settings(workers=0)


def test_settings_are_frozen() -> None:
    with pytest.raises(dataclasses.FrozenInstanceError):
        Settings().workers = 4  # type: ignore[misc]


# --- app and /health -------------------------------------------------------------------------------


def test_dashboard_address_falls_back_to_none_when_port_is_taken() -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as holder:
        holder.bind(("127.0.0.1", 0))
        holder.listen()
        port = holder.getsockname()[1]
        assert free_dashboard_address(port) is None
    assert free_dashboard_address(port) == f"127.0.0.1:{port}"


def test_health_with_a_local_cluster_of_two_worker_processes(tmp_path: Path) -> None:
    data_dir = tmp_path / "nested" / "store"
    app = create_app(Settings(data_dir=data_dir, workers=2))
    with TestClient(app) as http:
        client = app.state.dask
        cluster = app.state.dask_cluster
        assert data_dir.is_dir(), "the lifespan creates the data directory"

        response = http.get("/health")
        assert response.status_code == 200
        body = response.json()
        assert body["status"] == "ok"
        assert body["service"]["version"] == app.version
        store = {k: body["store"][k] for k in ("path", "writable", "error")}
        assert store == {"path": str(data_dir.resolve()), "writable": True, "error": None}
        assert body["store"]["free_bytes"] > body["store"]["next_write_bytes"] > 0
        assert body["dask"]["scheduler"] == cluster.scheduler_address
        assert body["dask"]["n_workers"] == 2
        workers = body["dask"]["workers"]
        assert sorted(w["address"] for w in workers) == sorted(cluster.scheduler_info["workers"])
        assert all(w["nthreads"] == 1 and w["memory_limit"] > 0 for w in workers)

        # Two separate worker processes, neither of them the API process.
        pids = client.run(os.getpid)
        assert len(set(pids.values())) == 2
        assert os.getpid() not in pids.values()

        # A store that disappears makes the service degraded while Dask stays healthy.
        for leftover in data_dir.iterdir():  # the app's lock file and the store's reserve
            leftover.unlink()
        data_dir.rmdir()
        response = http.get("/health")
        assert response.status_code == 503
        body = response.json()
        assert body["status"] == "degraded"
        assert body["store"]["writable"] is False
        assert "FileNotFoundError" in body["store"]["error"]
        assert body["dask"]["n_workers"] == 2

    assert app.state.dask is None
    assert client.status == "closed"
    assert cluster.status.name == "closed"


def test_health_is_degraded_when_the_external_scheduler_has_no_workers(tmp_path: Path) -> None:
    with LocalCluster(n_workers=0, processes=False, dashboard_address=None) as external:
        app = create_app(Settings(data_dir=tmp_path, scheduler_address=external.scheduler_address))
        with TestClient(app) as http:
            assert app.state.dask_cluster is None
            response = http.get("/health")
            assert response.status_code == 503
            body = response.json()
            assert body["status"] == "degraded"
            assert body["store"]["writable"] is True
            assert body["dask"] == {
                "scheduler": external.scheduler_address,
                "workers": [],
                "n_workers": 0,
                "error": None,
            }
        # Closing the app leaves a scheduler it did not start running.
        assert external.status.name == "running"


def test_cors_is_closed_by_default_and_opens_to_configured_origins(tmp_path: Path) -> None:
    preflight = {"Origin": "https://a.example", "Access-Control-Request-Method": "GET"}

    closed = TestClient(create_app(Settings(data_dir=tmp_path)))
    response = closed.options("/health", headers=preflight)
    assert "access-control-allow-origin" not in response.headers

    opened = TestClient(create_app(Settings(data_dir=tmp_path, cors_origins=("https://a.example",))))
    response = opened.options("/health", headers=preflight)
    assert response.status_code == 200
    assert response.headers["access-control-allow-origin"] == "https://a.example"
    other = opened.options("/health", headers={**preflight, "Origin": "https://evil.example"})
    assert other.headers.get("access-control-allow-origin") != "https://evil.example"


def test_health_without_lifespan_reports_no_dask_client(tmp_path: Path) -> None:
    response = TestClient(create_app(Settings(data_dir=tmp_path))).get("/health")
    assert response.status_code == 503
    assert response.json()["dask"]["error"] == "no Dask client"
