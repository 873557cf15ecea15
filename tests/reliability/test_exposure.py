"""What the service shows beyond its API: the Dask dashboard (off by default, on the loopback interface
alone when the setting asks for it) and the headers a browser reads on every page."""

from __future__ import annotations

import socket
import warnings
from pathlib import Path

import httpx
import pytest
from distributed import Client
from fastapi.testclient import TestClient

from isolab.service.api.app import create_app, free_dashboard_address, start_dask, stop_dask
from isolab.service.settings import Settings, SettingsError, load_settings
from isolab.studies.run.fanout import local_cluster
from isolab.studies.run.runner import make_client


def http_addresses(cluster) -> list[tuple[str, int]]:
    """Where the LocalCluster's scheduler serves HTTP: (host, port) of every listening socket."""
    sockets = cluster.scheduler.http_server._sockets.values()
    return sorted({s.getsockname()[:2] for s in sockets})


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def test_the_dashboard_setting_is_off_unless_a_port_is_given(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("ISOLAB_DASHBOARD_PORT", raising=False)
    assert load_settings().dashboard_port is None
    monkeypatch.setenv("ISOLAB_DASHBOARD_PORT", "8787")
    assert load_settings().dashboard_port == 8787
    for bad in ("0", "70000", "yes"):
        monkeypatch.setenv("ISOLAB_DASHBOARD_PORT", bad)
        with pytest.raises(SettingsError, match="ISOLAB_DASHBOARD_PORT"):
            load_settings()


def test_a_dashboard_port_in_use_gives_no_dashboard_and_the_address_is_loopback() -> None:
    assert free_dashboard_address(None) is None
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as holder:
        holder.bind(("127.0.0.1", 0))
        holder.listen()
        port = holder.getsockname()[1]
        assert free_dashboard_address(port) is None
    assert free_dashboard_address(port) == f"127.0.0.1:{port}"


def _worker_setting(key: str) -> object:
    import dask

    return dask.config.get(key)


@pytest.mark.slow
def test_by_default_the_scheduler_serves_no_dashboard_and_only_on_loopback(tmp_path: Path) -> None:
    # 8787 held by another program on every interface: Dask used to warn it was in use and take another
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as holder:
        holder.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            holder.bind(("", 8787))
            holder.listen()
        except OSError:
            pass  # something already holds it: the same situation
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # "Port 8787 is already in use" would fail here
            client, cluster = start_dask(Settings(data_dir=tmp_path, workers=1))
        try:
            addresses = http_addresses(cluster)
            assert addresses and all(host == "127.0.0.1" for host, _ in addresses), addresses
            assert all(port != 8787 for _, port in addresses)
            host, port = addresses[0]
            base = f"http://{host}:{port}"
            assert httpx.get(f"{base}/health", timeout=10).status_code == 200
            # no page of the dashboard or of the scheduler's own information (task keys hold study ids)
            for page in ("/status", "/info/main/workers.html", "/json/identity.json", "/metrics"):
                assert httpx.get(f"{base}{page}", timeout=10).status_code == 404, page
            # no dashboard, no profiler: the workers sample no stacks, and their housekeeping is slowed
            assert set(client.run(_worker_setting, "distributed.worker.profile.enabled").values()) == {False}
            assert set(client.run(_worker_setting, "distributed.admin.tick.interval").values()) == {"1s"}
        finally:
            stop_dask(client, cluster)


@pytest.mark.slow
def test_with_a_port_set_the_dashboard_listens_on_loopback_alone(tmp_path: Path) -> None:
    port = free_port()
    client, cluster = start_dask(Settings(data_dir=tmp_path, workers=1, dashboard_port=port))
    try:
        assert http_addresses(cluster) == [("127.0.0.1", port)]
        assert httpx.get(f"http://127.0.0.1:{port}/info/main/workers.html", timeout=10).status_code == 200
        # the dashboard shows the workers' profiles: they are sampled
        assert set(client.run(_worker_setting, "distributed.worker.profile.enabled").values()) == {True}
    finally:
        stop_dask(client, cluster)


def listening_hosts() -> set[str]:
    """The addresses every TCP socket of this process and its children listens on."""
    import os

    import psutil

    me = psutil.Process(os.getpid())
    return {
        c.laddr.ip
        for p in [me, *me.children(recursive=True)]
        for c in p.net_connections(kind="tcp")
        if c.status == psutil.CONN_LISTEN
    }


@pytest.mark.slow
def test_the_cluster_of_a_local_run_and_of_the_default_client_listens_on_loopback_alone() -> None:
    # `isolab run` and a notebook's default client start a LocalCluster of their own: its scheduler,
    # workers and HTTP server (no dashboard) listen on 127.0.0.1 alone, and it runs the slowed housekeeping
    with local_cluster(1) as cluster, Client(cluster) as client:
        assert listening_hosts() == {"127.0.0.1"}
        assert http_addresses(cluster)[0][0] == "127.0.0.1"
        assert set(client.run(_worker_setting, "distributed.worker.profile.enabled").values()) == {False}
    with make_client(workers=1) as client:
        assert listening_hosts() == {"127.0.0.1"}
        cluster = client.cluster
    assert cluster.status.name == "closed"  # the client's own cluster closes with it


# ------------------------------------------------------------------------------------------ headers
PAGES = ["/ui/", "/ui/new", "/ui/compare", f"/ui/studies/{'a' * 32}", f"/ui/studies/{'a' * 32}/cases/0"]


@pytest.fixture(scope="module")
def pages() -> TestClient:
    return TestClient(create_app(Settings(api_token="t0ken")))  # no lifespan: pages and assets only


@pytest.mark.parametrize("path", PAGES)
def test_every_page_sends_a_policy_that_runs_the_services_scripts_only(pages: TestClient, path: str) -> None:
    answer = pages.get(path)
    assert answer.status_code == 200
    policy = {
        part.split()[0]: part.split()[1:]
        for part in answer.headers["content-security-policy"].split(";")
        if part.strip()
    }
    assert policy["script-src"] == ["'self'"]  # no inline script, no handler attribute, no eval
    assert policy["object-src"] == ["'none'"]
    assert policy["base-uri"] == ["'none'"]
    assert policy["frame-ancestors"] == ["'none'"]
    assert answer.headers["x-content-type-options"] == "nosniff"
    assert answer.headers["referrer-policy"] == "no-referrer"
    # the pages hold no inline script or handler the policy would block
    html = answer.text
    assert "<script>" not in html and " onclick=" not in html and " onload=" not in html


@pytest.mark.parametrize("path", ["/docs", "/redoc"])
def test_the_api_reference_pages_send_a_policy_that_lets_their_own_set_up_run(
    pages: TestClient, path: str
) -> None:
    answer = pages.get(path)
    policy = answer.headers["content-security-policy"]
    scripts = next(p for p in policy.split(";") if p.strip().startswith("script-src")).split()[1:]
    assert "'unsafe-inline'" not in scripts and "'unsafe-eval'" not in scripts
    assert answer.headers["x-content-type-options"] == "nosniff"


@pytest.mark.parametrize(
    "path", ["/ui/assets/new.js", "/ui/assets/ui.css", "/ui/vendor/plotly.min.js", "/health", "/studies"]
)
def test_assets_and_api_answers_are_not_sniffed(pages: TestClient, path: str) -> None:
    answer = pages.get(path)
    assert answer.headers["x-content-type-options"] == "nosniff"
    assert answer.headers["referrer-policy"] == "no-referrer"
