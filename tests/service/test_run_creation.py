"""POST /runs with a client_request_id is idempotent: a trainer that lost the answer (a dropped link,
a restarted service, its own death) sends it again and gets the run the first made, not a second
run beside an orphan that would show "training" on the dashboard for good. On SQLite and PostgreSQL."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import httpx
import pytest
from sqlalchemy import text
from stalling_proxy import stalling_relay

from backend.db import Database
from backend.main import create_app
from backend.migrate import upgrade
from backend.server import BackgroundServer
from collie.client import CollieClient, Conflict, new_request_id
from collie.schemas import RunCreate, RunRead
from trainer.feedback.http import HttpFeedback

from .conftest import TOKENS, both_databases, database_at, make_run_spec, settings_for

database_url = both_databases


def keyed(key: str, **change: object) -> RunCreate:
    return make_run_spec().model_copy(update={"client_request_id": key, **change})


def test_a_repeated_creation_answers_the_first_run_and_another_spec_under_its_id_is_refused(
    live: BackgroundServer, trainer: CollieClient
) -> None:
    key = new_request_id()
    post = lambda spec: httpx.post(  # noqa: E731
        f"{live.url}/api/runs",
        content=spec.model_dump_json(),
        headers={"Authorization": f"Bearer {TOKENS['trainer']}", "Content-Type": "application/json"},
    )
    first, again = post(keyed(key)), post(keyed(key))
    assert (first.status_code, again.status_code) == (201, 200)
    made = RunRead.model_validate_json(first.content)
    assert RunRead.model_validate_json(again.content).id == made.id
    with pytest.raises(
        Conflict, match=rf"client_request_id '{key}' was already used for another run \(run {made.id}\)"
    ):
        trainer.create_run(keyed(key, config={"preset": "cpu"}))
    # without an id, or with a fresh one, each post is a run of its own
    ids = {trainer.create_run(make_run_spec()).id, trainer.create_run(make_run_spec()).id}
    ids.add(trainer.create_run(keyed(new_request_id())).id)
    assert len(ids) == 3 and made.id not in ids


def test_a_creation_whose_answer_was_lost_is_sent_again_and_makes_one_run(
    live: BackgroundServer, trainer: CollieClient
) -> None:
    before = {r.id for r in trainer.runs()}
    made: list[HttpFeedback] = []
    with stalling_relay(live.url, lose_answer_to=b"POST /api/runs ") as relay:
        creating = threading.Thread(
            target=lambda: made.append(HttpFeedback.create(relay.url, TOKENS["trainer"], keyed(new_request_id())))
        )
        creating.start()
        deadline = time.monotonic() + 30
        while not {r.id for r in trainer.runs()} - before:  # the service made it; its answer is held
            assert time.monotonic() < deadline, "the run was never made"
            time.sleep(0.05)
        assert relay.holding
        relay.drop_held()  # the link drops: the trainer got no answer
        creating.join(30)
    new = {r.id for r in trainer.runs()} - before
    assert len(new) == 1 and len(made) == 1 and made[0].run_id in new
    made[0].close()


def test_a_0011_database_holding_runs_and_their_rows_upgrades(tmp_path: Path) -> None:
    """Migration 0012 on a database whose run has rows pointing at it (was: a table rebuild of
    `runs`, refused by SQLite's foreign keys: serve and export both failed on such a database)."""
    path = tmp_path / "old.db"
    metrics = text("""INSERT INTO metrics (run_id, epoch, "values", created_at) VALUES (1, 0, '{}', 0)""")
    database_at(path, "0011", "north", lambda conn: conn.execute(metrics))
    db = Database(f"sqlite:///{path}")
    upgrade(db.engine)
    db.dispose()
    with BackgroundServer(create_app(settings_for(path))) as server, CollieClient(server.url, TOKENS["trainer"]) as c:
        assert c.run(1).task == "north"
        key = new_request_id()
        assert c.create_run(keyed(key)).id == c.create_run(keyed(key)).id == 2


def test_a_repeat_with_another_rule_is_another_run_and_racing_repeats_make_one(
    live: BackgroundServer, trainer: CollieClient
) -> None:
    """A task file edited between the lost answer and the repeat: the run made holds the old rule
    (was: answered as the same run, judged by another rule). Repeats sent at once (a retry racing
    the first's insert) all answer one run, on PostgreSQL too (was: 409 "conflicting write")."""
    key = new_request_id()
    trainer.create_run(keyed(key, task="instruction", instruction="stay west"))
    with pytest.raises(Conflict, match="was already used for another run"):
        trainer.create_run(keyed(key, task="instruction", instruction="stay east"))
    before = {r.id for r in trainer.runs(limit=1000)}
    key, answers = new_request_id(), []

    def create() -> None:
        with CollieClient(live.url, TOKENS["trainer"]) as client:
            answers.append(client.create_run(keyed(key)).id)

    racing = [threading.Thread(target=create) for _ in range(6)]
    for thread in racing:
        thread.start()
    for thread in racing:
        thread.join(30)
    assert len(answers) == 6 and len(set(answers)) == 1
    assert {r.id for r in trainer.runs(limit=1000)} - before == set(answers)
