"""Fixtures of the service tests: the app with its lifespan on a fresh store, joined to the test process's
shared cluster (tests/shared_cluster.py)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest
from fastapi.testclient import TestClient

from isolab.service.api.app import create_app
from isolab.service.settings import Settings
from tests.shared_cluster import shared_scheduler


@contextmanager
def live_app(tmp_path_factory: pytest.TempPathFactory, workers: int, **settings: Any) -> Iterator[TestClient]:
    """The app, its lifespan running, on a fresh data directory with ``settings`` (``Settings`` fields),
    joined to the shared cluster of ``workers`` worker processes."""
    settings["scheduler_address"] = shared_scheduler(workers)
    with TestClient(create_app(Settings(data_dir=tmp_path_factory.mktemp("data"), **settings))) as client:
        yield client


@pytest.fixture(scope="module")
def http(tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    """The app with one worker, one per test module (a module that needs other settings defines its own
    ``http`` with :func:`live_app`)."""
    with live_app(tmp_path_factory, workers=1) as client:
        yield client
