"""Retiring queries while a label for one of them commits, on PostgreSQL (SQLite serialises its
writers, so there the two cannot interleave): the label wins, as if it had come first."""

from __future__ import annotations

import threading
import time

import pytest
from sqlalchemy import create_engine, text

from backend.server import BackgroundServer
from collie.client import CollieClient
from collie.schemas import Retired

from .conftest import make_run_spec, make_session, new_database_url


@pytest.fixture(scope="module")
def database_url(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> str:
    return new_database_url("postgresql", request, tmp_path_factory)


def test_a_label_committed_while_retire_waits_for_its_row_is_kept(
    live: BackgroundServer, database_url: str, trainer: CollieClient
) -> None:
    run = trainer.create_run(make_run_spec())
    trainer.post_session(run.id, make_session(0, 2))
    labelled, open_ = "0-0", "0-1"
    engine = create_engine(database_url)
    answer: list[Retired] = []
    try:
        with engine.connect() as submit, engine.connect() as watcher:
            # a label's transaction, not committed yet: it holds the row retire will wait for
            mark = "UPDATE queries SET status = 'labelled', label = 0 WHERE run_id = :run AND query_id = :q"
            submit.execute(text(mark), {"run": run.id, "q": labelled})
            retiring = threading.Thread(target=lambda: answer.append(trainer.retire(run.id, [labelled, open_])))
            retiring.start()
            deadline = time.monotonic() + 30
            waiting = "SELECT count(*) FROM pg_stat_activity WHERE wait_event_type = 'Lock'"
            while not watcher.execute(text(waiting)).scalar():  # retire blocks on the row
                assert time.monotonic() < deadline and retiring.is_alive(), "retire never waited for the row"
                time.sleep(0.05)
                watcher.rollback()  # a fresh snapshot each look
            submit.commit()
            retiring.join(30)
    finally:
        engine.dispose()
    assert answer == [Retired(retired=[open_], not_retired=[labelled])]
    kept = trainer.query(run.id, labelled)
    assert (kept.status, kept.label) == ("labelled", 0)
