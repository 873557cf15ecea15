"""Fixtures of the browser tests."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from ui_driver import browser


@pytest.fixture(scope="module")
def chromium() -> Iterator:
    """One headless Chromium for a test module (a launch takes ~1 s of CPU); each test opens a context of
    its own."""
    with browser() as b:
        yield b
