"""SQLite durability and write transactions: every commit is fsynced (synchronous=FULL, so an
acknowledged label survives a power cut), and write transactions take the lock up front (BEGIN
IMMEDIATE), so concurrent read-then-write transactions wait for each other instead of failing
with SQLITE_BUSY."""

from __future__ import annotations

import threading
from pathlib import Path

from sqlalchemy import text

from backend.db import Database
from backend.main import create_app

from .conftest import settings_for


def test_the_service_commits_with_synchronous_full(tmp_path: Path) -> None:
    app = create_app(settings_for(tmp_path / "d.db"))
    with app.state.db.write() as conn:
        assert conn.exec_driver_sql("PRAGMA synchronous").scalar() == 2  # FULL
    app.state.db.dispose()


def test_concurrent_read_then_write_never_fails(tmp_path: Path) -> None:
    # What is tested is the locking (BEGIN IMMEDIATE), not the fsync: without it (NORMAL, so a WAL
    # commit does not fsync) a slow disk on a loaded machine cannot starve a thread past the 5 s
    # busy timeout into "database is locked".
    db = Database(f"sqlite:///{tmp_path / 'c.db'}", synchronous="NORMAL")
    with db.write() as conn:
        conn.execute(text("CREATE TABLE counter (n INTEGER)"))
        conn.execute(text("INSERT INTO counter VALUES (0)"))
    errors: list[BaseException] = []

    def work() -> None:
        try:
            for _ in range(25):
                with db.write() as conn:  # read, then write what was read: a deferred BEGIN would deadlock
                    n = conn.execute(text("SELECT n FROM counter")).scalar_one()
                    conn.execute(text("UPDATE counter SET n = :n"), {"n": n + 1})
        except BaseException as exc:
            errors.append(exc)

    threads = [threading.Thread(target=work) for _ in range(8)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    with db.read() as conn:
        assert conn.execute(text("SELECT n FROM counter")).scalar_one() == 8 * 25
    assert errors == []
    db.dispose()
