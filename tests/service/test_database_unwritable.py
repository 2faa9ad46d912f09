"""A SQLite database that cannot be written under a running service (its files made immutable, as
`chattr +i collie.db collie.db-wal` does; a full disk, which a file size limit stands in for):
writes answer 503 with Retry-After and one log line, never a 500 and a traceback; /api/health
says so; the trainer's final status, refused meanwhile, arrives once the database takes writes
again; and the background checkpoints survive the fault. A read-only PostgreSQL (a standby, or
default_transaction_read_only) is the same 503."""

from __future__ import annotations

import contextlib
import logging
import resource
import shutil
import signal
import subprocess
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import httpx
import psycopg
import pytest

from backend.main import create_app
from backend.server import BackgroundServer
from collie.client import Backoff, CollieClient
from trainer.feedback.http_reporter import HttpReporter
from trainer.telemetry import StatusReport

from .conftest import TOKENS, make_run_spec, settings_for
from .postgres import PostgresServer

AUTH = {"Authorization": f"Bearer {TOKENS['trainer']}"}


def chattr_refusal(folder: Path) -> str | None:
    """Why `chattr +i` cannot be used in `folder`, or None when it can."""
    if shutil.which("chattr") is None:
        return "no chattr on this machine"
    probe = folder / "chattr-probe"
    probe.touch()
    tried = subprocess.run(["chattr", "+i", probe], capture_output=True, text=True)
    if tried.returncode != 0:
        probe.unlink()
        said = tried.stderr.strip() or f"exit {tried.returncode}"
        return f"chattr +i refused ({said}): it needs root (CAP_LINUX_IMMUTABLE) and a filesystem with the flag"
    subprocess.run(["chattr", "-i", probe], check=True)
    probe.unlink()
    return None


@contextlib.contextmanager
def immutable(*files: Path) -> Iterator[None]:
    """`files` immutable: the kernel refuses writes even through descriptors already open. Never
    the -shm file: SQLite maps it into memory, and a store into an immutable mapping is a SIGBUS
    that kills the whole process."""
    subprocess.run(["chattr", "+i", *files], check=True)
    try:
        yield
    finally:
        subprocess.run(["chattr", "-i", *files], check=True)


@contextlib.contextmanager
def no_file_may_grow() -> Iterator[None]:
    """RLIMIT_FSIZE 0: every write into a file is refused (EFBIG, as a full disk refuses with
    ENOSPC), for root too and through descriptors already open. It holds for this whole process,
    the test's own file writes included, so the window is kept short. Python ignores SIGXFSZ, which
    would otherwise kill the process; it is ignored here in any case."""
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    handler = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (0, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
        signal.signal(signal.SIGXFSZ, handler)


def unwritable_by(how: str, db: Path) -> Callable[[], contextlib.AbstractContextManager[None]]:
    if how == "immutable":
        refusal = chattr_refusal(db.parent)
        if refusal is not None:
            pytest.skip(refusal)
        return lambda: immutable(db, db.with_name(db.name + "-wal"))
    return no_file_may_grow


def wait_for(found: Callable[[], bool], what: Callable[[], str], timeout_s: float = 30.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not found():
        assert time.monotonic() < deadline, what()
        time.sleep(0.05)


@pytest.mark.parametrize("how", ["immutable", "file size limit"])
def test_an_unwritable_database_is_503_and_the_final_status_arrives(
    how: str, tmp_path: Path, logged: list[logging.LogRecord], caplog: pytest.LogCaptureFixture
) -> None:
    db = tmp_path / "collie.db"
    unwritable = unwritable_by(how, db)
    caplog.set_level(logging.WARNING, logger="trainer.feedback.http_reporter")
    with (
        BackgroundServer(create_app(settings_for(db))) as server,
        httpx.Client(base_url=server.url, timeout=30) as http,
        CollieClient(server.url, TOKENS["trainer"]) as trainer,
    ):
        run = trainer.create_run(make_run_spec())
        trainer.set_status(run.id, "training", epoch=51)
        assert http.get("/api/health").status_code == 200
        # quick tries (the shared backoff, capped at 0.2 s) so the test sees the delivery soon
        reporter = HttpReporter(server.url, TOKENS["trainer"], run.id, backoff=Backoff(max_s=0.2))
        giving_up = HttpReporter(server.url, TOKENS["trainer"], run.id, final_retry_s=1.0)
        final = threading.Thread(target=reporter.status, args=(StatusReport("finished", 52),), daemon=True)
        with unwritable():
            write = http.put(f"/api/runs/{run.id}/status", json={"status": "training", "epoch": 52}, headers=AUTH)
            assert write.status_code == 503, write.text
            assert write.headers["retry-after"] and "cannot be written" in write.json()["detail"]
            health = http.get("/api/health")
            assert health.status_code == 503 and health.headers["retry-after"]
            assert "cannot be written" in health.json()["detail"]
            assert http.get(f"/api/runs/{run.id}", headers=AUTH).json()["epoch"] == 51  # reads go on

            started = time.monotonic()
            giving_up.status(StatusReport("failed", 52, error="diverged"))  # bounded: it gives up
            assert time.monotonic() - started < 15
            final.start()
            retrying = lambda: any("retrying for up to 60 s" in r.getMessage() for r in caplog.records)  # noqa: E731
            wait_for(retrying, lambda: f"no retry: {caplog.text}")
        final.join(30)
        assert not final.is_alive(), "the final status was not delivered once the database took writes"
        shown = trainer.run(run.id)
        assert (shown.status, shown.epoch) == ("finished", 52)
        assert reporter.shown == "finished" and giving_up.shown is None
        assert http.get("/api/health").status_code == 200
        reporter.close()
        giving_up.close()

    said = [r.getMessage() for r in caplog.records]
    assert any("final status (failed at epoch 52) not delivered in 1 s (503: " in line for line in said), said
    assert any("final status (finished at epoch 52) delivered" in line for line in said), said
    lines = [r.getMessage() for r in logged if r.levelno >= logging.WARNING]
    assert any(line.startswith("database cannot be written (") for line in lines), lines
    assert all("\n" not in line for line in lines)
    assert [r for r in logged if r.exc_info] == []  # no traceback


def test_checkpoints_survive_a_database_file_that_cannot_be_written(
    tmp_path: Path, logged: list[logging.LogRecord]
) -> None:
    """Only the database file refuses writes (the log takes them): writes go on, each background
    checkpoint fails, and the checkpoints start again once the file takes writes; one line each."""
    db = tmp_path / "collie.db"
    refusal = chattr_refusal(tmp_path)
    if refusal is not None:
        pytest.skip(refusal)
    said = lambda text: any(text in r.getMessage() for r in list(logged))  # noqa: E731
    lines = lambda: f"the service logged {[r.getMessage() for r in list(logged)]}"  # noqa: E731
    with (
        BackgroundServer(create_app(settings_for(db))) as server,
        CollieClient(server.url, TOKENS["trainer"]) as trainer,
    ):
        run = trainer.create_run(make_run_spec())
        with immutable(db):
            trainer.set_status(run.id, "training", epoch=1)  # in the log: a checkpoint has work to do
            wait_for(lambda: said("checkpoint failed"), lambda: f"no checkpoint failed; {lines()}")
            trainer.set_status(run.id, "training", epoch=2)
        wait_for(lambda: said("checkpoint: the database is written again"), lambda: f"no checkpoint since; {lines()}")
        assert trainer.run(run.id).epoch == 2
    assert [r for r in logged if r.exc_info] == []


def test_a_stop_while_the_database_file_cannot_be_written_keeps_every_write(
    tmp_path: Path, logged: list[logging.LogRecord]
) -> None:
    """The last checkpoint, at shutdown, fails as the background ones do: a line, not a traceback
    ("Application shutdown failed"), and the next start finds every write in the log."""
    db = tmp_path / "collie.db"
    refusal = chattr_refusal(tmp_path)
    if refusal is not None:
        pytest.skip(refusal)
    with contextlib.ExitStack() as serving:
        server = serving.enter_context(BackgroundServer(create_app(settings_for(db))))
        trainer = serving.enter_context(CollieClient(server.url, TOKENS["trainer"]))
        run = trainer.create_run(make_run_spec())
        with immutable(db):
            trainer.set_status(run.id, "training", epoch=3)  # in the log, for the last checkpoint to write
            serving.close()  # the service stops
        said = [r.getMessage() for r in logged]
        assert any(
            line.startswith("the last checkpoint failed; the write-ahead log keeps every write: ") for line in said
        )
    assert [r for r in logged if r.exc_info] == []
    with (
        BackgroundServer(create_app(settings_for(db))) as server,
        CollieClient(server.url, TOKENS["trainer"]) as trainer,
    ):
        assert trainer.run(run.id).epoch == 3


@contextlib.contextmanager
def read_only(postgres: PostgresServer, url: str) -> Iterator[None]:
    """PostgreSQL's transactions on the service's database read-only, as on a standby: set for the
    database, its open sessions ended so that the service's pool reconnects under the setting."""
    name = url.rsplit("/", 1)[1]

    def apply(sql: str) -> None:
        with psycopg.connect(postgres.dsn("postgres"), autocommit=True) as admin:
            admin.execute(sql)
            admin.execute("SELECT pg_terminate_backend(pid) FROM pg_stat_activity WHERE datname = %s", (name,))

    apply(f"ALTER DATABASE {name} SET default_transaction_read_only = on")
    try:
        yield
    finally:
        apply(f"ALTER DATABASE {name} RESET default_transaction_read_only")


def test_a_read_only_postgresql_is_503_and_health_says_so(
    postgres: PostgresServer, logged: list[logging.LogRecord]
) -> None:
    url = postgres.new_database()
    with (
        BackgroundServer(create_app(settings_for(url))) as server,
        httpx.Client(base_url=server.url, timeout=30) as http,
        CollieClient(server.url, TOKENS["trainer"]) as trainer,
    ):
        run = trainer.create_run(make_run_spec())
        with read_only(postgres, url):
            write = http.put(f"/api/runs/{run.id}/status", json={"status": "training", "epoch": 1}, headers=AUTH)
            assert write.status_code == 503, write.text
            assert write.headers["retry-after"] and "cannot be written" in write.json()["detail"]
            for _ in range(2):  # every time: the first answer's probe is no write that proves the next ok
                health = http.get("/api/health")
                assert health.status_code == 503 and "cannot be written" in health.json()["detail"]
            assert http.get(f"/api/runs/{run.id}", headers=AUTH).status_code == 200  # reads go on
        assert http.get("/api/health").status_code == 200
        assert trainer.set_status(run.id, "training", epoch=1).epoch == 1
    lines = [r.getMessage() for r in logged if r.levelno >= logging.WARNING]
    assert any(line.startswith("database cannot be written (") for line in lines), lines
    assert [r for r in logged if r.exc_info] == []


def test_a_write_that_changed_nothing_is_no_proof_the_database_takes_writes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """SQLite commits an empty write transaction on a full disk too: health must still look."""
    from sqlalchemy.exc import DBAPIError

    from backend import db as database
    from backend.db import Database

    monkeypatch.setattr(database, "WROTE_RECENTLY_S", 0.2)
    db = Database(f"sqlite:///{tmp_path / 'c.db'}")
    try:
        with db.write() as conn:
            conn.exec_driver_sql("CREATE TABLE t (x INTEGER)")
            conn.exec_driver_sql("INSERT INTO t VALUES (1)")
        time.sleep(0.3)  # that write is no longer recent
        with no_file_may_grow():
            with db.write() as conn:  # committed though no file may grow: it wrote nothing
                conn.exec_driver_sql("SELECT x FROM t").all()
            with pytest.raises(DBAPIError, match="disk I/O error"):  # the write check ran, and failed
                db.unwritable()
        with db.write() as conn:
            conn.exec_driver_sql("UPDATE t SET x = 2")
        assert db.unwritable() is None
    finally:
        db.dispose()
