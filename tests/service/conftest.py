"""Fixtures of the service tests: the app with its lifespan (its own Dask cluster) on a fresh store."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest
from fastapi.testclient import TestClient

from isolab.service.api.app import create_app
from isolab.service.settings import Settings


@contextmanager
def live_app(tmp_path_factory: pytest.TempPathFactory, **settings: Any) -> Iterator[TestClient]:
    """The app, its lifespan running, on a fresh data directory with ``settings`` (``Settings`` fields)."""
    with TestClient(create_app(Settings(data_dir=tmp_path_factory.mktemp("data"), **settings))) as client:
        yield client


@pytest.fixture(scope="module")
def http(tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    """The app with one worker, one per test module (a module that needs other settings defines its own
    ``http`` with :func:`live_app`)."""
    with live_app(tmp_path_factory, workers=1) as client:
        yield client
