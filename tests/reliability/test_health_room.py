"""``/health`` counts the room of the store: a store whose free space is below its next write (about one
chunk of the running study) is degraded, though a 64 kB file still fits."""

from __future__ import annotations

import os
import shutil
from collections import namedtuple
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from isolab.service.api.app import create_app
from isolab.service.api.routes import health
from isolab.service.settings import Settings

MB = 1024 * 1024
Usage = namedtuple("Usage", "total used free")


def with_free(monkeypatch: pytest.MonkeyPatch, free: int) -> None:
    real = shutil.disk_usage
    monkeypatch.setattr(
        health.shutil, "disk_usage", lambda p: Usage(real(p).total, real(p).total - free, free)
    )


def saved_chunk(root: Path, size: int) -> None:
    chunks = root / "studies" / f"{'a' * 32}.chunks"
    chunks.mkdir(parents=True)
    (chunks / "0.npz").write_bytes(b"\0" * size)


def test_free_space_below_the_next_chunk_is_not_writable(tmp_path: Path, monkeypatch) -> None:
    saved_chunk(tmp_path, int(1.5 * MB))
    with_free(monkeypatch, int(0.55 * MB))
    store = health.probe_store(tmp_path)
    assert store.writable is False
    assert store.next_write_bytes == int(1.5 * MB) and store.free_bytes == int(0.55 * MB)
    assert "0.55 MB free" in store.error and "1.50 MB" in store.error


def test_room_for_the_next_chunk_is_writable(tmp_path: Path, monkeypatch) -> None:
    saved_chunk(tmp_path, int(1.5 * MB))
    with_free(monkeypatch, 4 * MB)
    assert health.probe_store(tmp_path).writable is True


def test_without_a_saved_chunk_a_typical_chunk_is_the_estimate(tmp_path: Path, monkeypatch) -> None:
    with_free(monkeypatch, health.TYPICAL_CHUNK_BYTES - 1)
    assert health.probe_store(tmp_path).writable is False
    with_free(monkeypatch, health.TYPICAL_CHUNK_BYTES + 1)
    assert health.probe_store(tmp_path).writable is True


def test_a_study_assembled_while_health_looks_is_passed_over(tmp_path: Path, monkeypatch) -> None:
    """A study finishing removes its chunk folder between /health listing the folders and reading one:
    the estimate goes on without it (it was a 500 of /health)."""
    saved_chunk(tmp_path, int(1.5 * MB))
    going = tmp_path / "studies" / f"{'b' * 32}.chunks"
    going.mkdir()
    (going / "0.npz").write_bytes(b"\0" * (3 * MB))
    real = os.scandir

    def scandir_as_the_study_finishes(path):
        if not isinstance(path, int) and Path(path) == going:
            shutil.rmtree(going)
        return real(path)

    monkeypatch.setattr(os, "scandir", scandir_as_the_study_finishes)
    assert health.next_write_bytes(tmp_path) == int(1.5 * MB)


def test_health_answers_degraded_with_the_reason(tmp_path: Path, monkeypatch) -> None:
    saved_chunk(tmp_path, int(1.5 * MB))
    with_free(monkeypatch, int(0.55 * MB))
    answer = TestClient(create_app(Settings(data_dir=tmp_path))).get("/health")  # no lifespan, no cluster
    assert answer.status_code == 503
    body = answer.json()
    assert body["status"] == "degraded"
    assert body["store"]["writable"] is False and "next write" in body["store"]["error"]
