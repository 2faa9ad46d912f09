"""The SQLite file deleted (`rm -r` of a stack's folder) or replaced while the service runs: every
answer says so in a 500 and the log says it every 10 s, not a traceback per request. Was: the
pooled connections went on acknowledging labels into the deleted file (lost when the service
stopped) while new ones made an empty database at the path and answered 500 "no such table"."""

from __future__ import annotations

import contextlib
import logging
import shutil
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from backend.main import create_app
from backend.server import BackgroundServer
from collie.client import CollieClient
from collie.schemas import RunRead

from .conftest import TOKENS, make_run_spec, settings_for


@contextlib.contextmanager
def service_with_a_run(tmp_path: Path) -> Iterator[tuple[BackgroundServer, Path, RunRead]]:
    """A service over tmp_path/stack/collie.db (a folder of its own, to delete) holding one run."""
    db = tmp_path / "stack" / "collie.db"
    db.parent.mkdir()
    with (
        BackgroundServer(create_app(settings_for(db))) as server,
        CollieClient(server.url, TOKENS["trainer"]) as trainer,
    ):
        yield server, db, trainer.create_run(make_run_spec())


@pytest.mark.parametrize("how", ["deleted", "replaced"])
def test_a_database_file_gone_under_the_service_is_said_and_nothing_more_is_acknowledged(
    tmp_path: Path, logged: list[logging.LogRecord], how: str
) -> None:
    with service_with_a_run(tmp_path) as (server, db, run):
        if how == "deleted":
            shutil.rmtree(db.parent)
        else:
            shutil.copy(db, tmp_path / "copy.db")
            (tmp_path / "copy.db").replace(db)  # another file at the path: a backup put back while it ran
        auth = {"Authorization": f"Bearer {TOKENS['operator']}"}
        for path in (f"/api/runs/{run.id}", "/api/runs", f"/api/runs/{run.id}/pause"):
            call = httpx.post if path.endswith("pause") else httpx.get
            answer = call(f"{server.url}{path}", headers=auth, timeout=30)
            assert answer.status_code == 500, answer.text
            assert answer.json()["detail"] == (
                f"the database file {db} was deleted or replaced while the service ran: stop the service, put "
                "the file back (from a backup) and start it again"
            )
    assert how == "replaced" or not db.exists()  # no empty database made at the path
    assert [r for r in logged if r.exc_info] == []  # no traceback
    lines = [r.getMessage() for r in logged if r.levelno >= logging.WARNING]
    assert lines == [
        f"database file is gone (1 answer(s) refused with 500): the database file {db} was deleted"
        " or replaced while the service ran: stop the service, put the file back (from a backup) and"
        " start it again"
    ]


def test_an_open_event_stream_ends_in_a_line_when_the_file_goes(
    tmp_path: Path, logged: list[logging.LogRecord], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Was: a traceback per open stream (a dashboard or labeling tab), the response already started."""
    from backend.routes import stream as stream_route

    monkeypatch.setattr(stream_route, "HEARTBEAT_S", 0.5)  # its check of the caller, every 15 s
    with service_with_a_run(tmp_path) as (server, db, run):
        auth = {"Authorization": f"Bearer {TOKENS['operator']}"}
        with httpx.stream("GET", f"{server.url}/api/runs/{run.id}/stream", headers=auth, timeout=60) as stream:
            lines = stream.iter_lines()
            next(line for line in lines if line.startswith("data:"))  # the run's first event: it streams
            shutil.rmtree(db.parent)
            rest = list(lines)  # ends at its next check of the caller (a heartbeat), not with an error
    assert not any(line.startswith("data:") for line in rest)
    assert [r for r in logged if r.exc_info] == []
    assert f"stream of run {run.id} ended: the database file {db} was deleted" in " ".join(
        r.getMessage() for r in logged
    )
