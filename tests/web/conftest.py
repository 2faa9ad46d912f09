"""Fixtures for the dashboard tests: the service tests' live service (uvicorn on an ephemeral port
over a SQLite file) and its clients, and Debian's Chromium (tests/chromium.py)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from chromium import chromium
from playwright.sync_api import Browser
from service.conftest import database_url, labeler, live, operator, trainer  # noqa: F401 (the same live service)

ARTIFACTS = Path(__file__).resolve().parents[2] / "test-artifacts" / "web"


@pytest.fixture(scope="session")
def artifacts() -> Path:
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    return ARTIFACTS


@pytest.fixture(scope="module")
def browser() -> Iterator[Browser]:
    with chromium() as b:
        yield b
