"""A SQLite file with a damaged page (a disk fault, a copy taken mid-write): the service answers
what touches it with a 500 that says so, and one log line, not a traceback per request; `collie
export` says it in a line. Nothing mends it but a backup, so it is no 503 to retry."""

from __future__ import annotations

import logging
import sqlite3
import subprocess
import sys
from pathlib import Path

import httpx

from backend.main import create_app
from backend.server import BackgroundServer
from collie.client import CollieClient

from .conftest import TOKENS, make_run_spec, settings_for


def damage(db: Path, table: str) -> None:
    """Overwrite the root pages of `table` and its indexes with garbage (the service stopped, its
    log checkpointed)."""
    with sqlite3.connect(db) as conn:
        conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
        size = conn.execute("PRAGMA page_size").fetchone()[0]
        roots = [r for (r,) in conn.execute("SELECT rootpage FROM sqlite_master WHERE tbl_name = ?", (table,))]
    with open(db, "r+b") as f:
        for root in roots:
            f.seek((root - 1) * size)
            f.write(b"\x5a" * size)


def test_a_damaged_page_is_said_as_such_by_the_service_and_by_export(
    tmp_path: Path, logged: list[logging.LogRecord]
) -> None:
    db = tmp_path / "collie.db"
    with (
        BackgroundServer(create_app(settings_for(db))) as server,
        CollieClient(server.url, TOKENS["trainer"]) as trainer,
    ):
        run = trainer.create_run(make_run_spec())
    damage(db, "label_events")
    export = [sys.executable, "-m", "collie.cli", "export", "--db", str(db), "--run", str(run.id)]
    out = subprocess.run(export, capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and "Traceback" not in out.stderr, out.stderr
    said = f"collie export: error: {db} is damaged (database disk image is malformed): restore it from a backup\n"
    assert out.stderr == said
    with BackgroundServer(create_app(settings_for(db))) as server:
        auth = {"Authorization": f"Bearer {TOKENS['operator']}"}
        for _ in range(3):
            answer = httpx.get(f"{server.url}/api/runs/{run.id}/labels", headers=auth, timeout=30)
            assert answer.status_code == 500, answer.text
            assert answer.json()["detail"].startswith("the database file is damaged; its operator must stop")
        assert httpx.get(f"{server.url}/api/runs/{run.id}", headers=auth, timeout=30).status_code == 200
    assert [r for r in logged if r.exc_info] == []  # no traceback
    lines = [r.getMessage() for r in logged if r.levelno >= logging.WARNING]
    assert lines == ["database file is damaged (1 answer(s) refused with 500): database disk image is malformed"]
