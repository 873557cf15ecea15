"""Where the commands and the client find the service: ``--url``, else ``ISOLAB_URL``, else
http://127.0.0.1:8000; and what they say when nothing listens there (one line, no traceback).

A port nobody listens on stands for a service that is not running: bound, never listened on, so the
kernel refuses a connection to it at once (and no other process can take it while the test runs).
"""

from __future__ import annotations

import shutil
import socket
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest
from typer.testing import CliRunner

from isolab.service.cli import app
from isolab.service.client import DEFAULT_URL, Client, ClientError

ROOT = Path(__file__).resolve().parents[2]
STUDY = ROOT / "studies" / "examples" / "isolator-comparison.yaml"


@pytest.fixture
def nowhere() -> Iterator[str]:
    """The address of a port bound on loopback that nobody listens on."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        yield f"http://127.0.0.1:{s.getsockname()[1]}"


def hint(url: str) -> str:
    return f"is `isolab serve` running at {url}? set ISOLAB_URL or --url"


def test_the_client_names_the_address_and_what_to_set(nowhere: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("ISOLAB_URL", raising=False)
    assert Client().base_url == DEFAULT_URL
    monkeypatch.setenv("ISOLAB_URL", nowhere + "/")
    with Client(timeout=5) as api:
        assert api.base_url == nowhere  # the environment's address, without its trailing slash
        with pytest.raises(ClientError) as err:
            api.status("0" * 32)
    assert err.value.status_code is None
    message = str(err.value)
    assert message == f"cannot reach the isolab service at {nowhere} (connection refused): {hint(nowhere)}"
    assert "\n" not in message
    with Client("http://127.0.0.1:8000") as api:  # an address given wins over the environment
        assert api.base_url == "http://127.0.0.1:8000"


def test_a_download_from_nowhere_says_the_same_and_leaves_no_file(nowhere: str, tmp_path: Path) -> None:
    with Client(nowhere, timeout=5) as api, pytest.raises(ClientError, match=r"is `isolab serve` running"):
        api.download("0" * 32, tmp_path / "out.nc")
    assert list(tmp_path.iterdir()) == []


def test_an_address_without_its_scheme_is_named(monkeypatch: pytest.MonkeyPatch) -> None:
    with Client("localhost:8000", timeout=5) as api, pytest.raises(ClientError) as err:
        api.list()
    assert str(err.value).startswith("'localhost:8000' is not an http:// or https:// address: set ISOLAB_URL")


@pytest.mark.parametrize(
    "args",
    [
        ["status"],
        ["status", "0" * 32],
        ["submit", str(STUDY)],
        ["fetch", "0" * 32, "-o", "{tmp}/x.nc"],
        ["sensitivity", "0" * 32, "--output", "settling_time"],
    ],
    ids=["status", "status-id", "submit", "fetch", "sensitivity"],
)
@pytest.mark.parametrize("how", ["--url", "ISOLAB_URL"])
def test_every_command_that_calls_the_service_says_where_it_looked(
    args: list[str], how: str, nowhere: str, tmp_path: Path
) -> None:
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    env = {"ISOLAB_URL": nowhere} if how == "ISOLAB_URL" else {"ISOLAB_URL": "http://127.0.0.1:9"}
    extra = ["--url", nowhere] if how == "--url" else []  # --url wins over the environment
    result = CliRunner().invoke(app, [*args, *extra], env=env)
    assert result.exit_code != 0
    assert result.exception is None or isinstance(result.exception, SystemExit)
    assert result.stdout == ""
    lines = result.stderr.strip().splitlines()
    assert lines == [
        f"error: cannot reach the isolab service at {nowhere} (connection refused): {hint(nowhere)}"
    ]
    assert "Traceback" not in result.output
    assert list(tmp_path.iterdir()) == []


@pytest.mark.skipif(shutil.which("make") is None, reason="GNU make is not installed")
@pytest.mark.parametrize(
    ("host", "port", "url"),
    [("127.0.0.1", "8000", "http://127.0.0.1:8000"), ("0.0.0.0", "8080", "http://127.0.0.1:8080")],
)
def test_make_serve_prints_the_address_to_export(host: str, port: str, url: str) -> None:
    """``make -n`` lists the recipe without running it (nor installing anything)."""
    result = subprocess.run(
        ["make", "-n", "--no-print-directory", "serve", f"HOST={host}", f"PORT={port}"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 0, result.stderr
    assert f"export ISOLAB_URL={url}" in result.stdout
    assert f"isolab serve --host {host} --port {port}" in result.stdout
