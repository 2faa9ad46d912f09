"""Fixtures for the dashboard tests: a real service on an ephemeral port over a SQLite file, and
Debian's /usr/bin/chromium driven by Playwright from pip (never `playwright install`)."""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from pathlib import Path

import pytest
from service.conftest import TOKENS, settings_for

from backend.main import create_app
from backend.server import BackgroundServer
from collie.client import CollieClient

CHROMIUM = "/usr/bin/chromium"
ARTIFACTS = Path(__file__).resolve().parents[2] / "test-artifacts" / "web"


@pytest.fixture(scope="session")
def artifacts() -> Path:
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    return ARTIFACTS


@pytest.fixture(scope="module")
def live(tmp_path_factory: pytest.TempPathFactory) -> Iterator[BackgroundServer]:
    db = tmp_path_factory.mktemp("dashboard") / "collie.db"
    with BackgroundServer(create_app(settings_for(db))) as server:
        yield server


@pytest.fixture(scope="module")
def trainer(live: BackgroundServer) -> Iterator[CollieClient]:
    with CollieClient(live.url, TOKENS["trainer"]) as client:
        yield client


@pytest.fixture(scope="module")
def labeler(live: BackgroundServer) -> Iterator[CollieClient]:
    with CollieClient(live.url, TOKENS["labeler"]) as client:
        yield client


@pytest.fixture(scope="module")
def browser() -> Iterator[object]:
    sync_api = pytest.importorskip("playwright.sync_api", reason="pip install playwright")
    if shutil.which(CHROMIUM) is None:
        pytest.skip(f"{CHROMIUM} missing: apt-get install -y chromium")
    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=["--enable-unsafe-swiftshader"])
        yield b
        b.close()
