"""Fixtures for the dashboard tests: the service tests' live service (uvicorn on an ephemeral port
over a SQLite file) and its clients, and Debian's Chromium (tests/chromium.py)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

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


@contextmanager
def operator_page(browser: Browser, url: str, *, clipboard: bool = False, wait_ms: int = 30_000) -> Iterator[Any]:
    """The dashboard at `url` in a fresh Chromium context (1400 × 1000), closed on exit."""
    # bypass_csp: Playwright evaluates its predicates as strings, which the dashboard's CSP refuses
    context = browser.new_context(bypass_csp=True, viewport={"width": 1400, "height": 1000})
    if clipboard:
        context.grant_permissions(["clipboard-read", "clipboard-write"], origin=url.split("/?")[0])
    page = context.new_page()
    page.set_default_timeout(wait_ms)
    page.goto(url)
    try:
        yield page
    finally:
        context.close()
