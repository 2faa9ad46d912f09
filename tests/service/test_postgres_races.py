"""Writes that interleave on PostgreSQL (SQLite serialises its writers, so there they cannot):
retiring queries while a label for one of them commits, lowering the redundancy while a label
is in flight, and two feedback sessions posted at once into a run's budget. Each test holds one
side's transaction open at the moment that matters (a transaction of its own, or a hook pausing a
second service process on the same database), so the interleaving happens every time."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import pytest
from sqlalchemy import create_engine, event, text
from sqlalchemy.exc import DBAPIError

from backend.errors import database_fault
from backend.main import create_app
from backend.server import BackgroundServer
from backend.services.errors import DatabaseBusy
from collie.client import ApiError, CollieClient
from collie.schemas import Retired, RunRead, SessionPosted

from .conftest import TOKENS, make_run_spec, make_session, new_database_url, settings_for

# the database's sessions waiting for a lock now
LOCK_WAITS = "SELECT count(*) FROM pg_stat_activity WHERE wait_event_type = 'Lock' AND datname = current_database()"


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
            while not watcher.execute(text(LOCK_WAITS)).scalar():  # retire blocks on the row
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


@contextmanager
def paused_after(
    database_url: str, statement: str
) -> Iterator[tuple[BackgroundServer, threading.Event, threading.Event]]:
    """A second service process on the database whose first statement starting with `statement`
    pauses once executed, its transaction open, until `go`: yields (server, paused, go)."""
    server = BackgroundServer(create_app(settings_for(database_url)))
    paused, go = threading.Event(), threading.Event()

    def hook(conn: Any, cursor: Any, sql: str, *args: Any) -> None:
        if sql.lstrip().upper().startswith(statement) and not paused.is_set():
            paused.set()
            assert go.wait(60), "never let go"

    with server:
        event.listen(server.app.state.db.engine, "after_cursor_execute", hook)
        try:
            yield server, paused, go
        finally:
            go.set()


def wait(condition: Callable[[], bool], what: str) -> None:
    deadline = time.monotonic() + 30
    while not condition():
        assert time.monotonic() < deadline, what
        time.sleep(0.05)


@contextmanager
def lock_waits(database_url: str) -> Iterator[Callable[[], int]]:
    """How many of the database's sessions wait for a lock now."""
    engine = create_engine(database_url)

    def count() -> int:
        with engine.connect() as conn:
            return int(conn.execute(text(LOCK_WAITS)).scalar_one())

    try:
        yield count
    finally:
        engine.dispose()


def one_vote_of_three(
    live: BackgroundServer, trainer: CollieClient, operator: CollieClient
) -> tuple[RunRead, CollieClient, str]:
    """A run under r = 3 whose one query has ann's vote and is claimed by bob: (run, bob, query)."""
    run = trainer.create_run(make_run_spec().model_copy(update={"redundancy": 3}))
    trainer.post_session(run.id, make_session(0, 1))
    ann, bob = (CollieClient(live.url, operator.create_labeler(f"{name}-{run.id}").token) for name in ("ann", "bob"))
    ann.submit(run.id, ann.claim(run.id).query.query_id, 0)
    return run, bob, bob.claim(run.id).query.query_id


def test_redundancy_lowered_while_a_vote_is_in_flight_counts_the_vote(
    live: BackgroundServer, database_url: str, trainer: CollieClient, operator: CollieClient
) -> None:
    """r 3 → 2 while the second vote's transaction is open: the change waits for it, then counts it."""
    run, bob, query_id = one_vote_of_three(live, trainer, operator)
    with (
        lock_waits(database_url) as waiting,
        paused_after(database_url, "INSERT INTO LABEL_VOTES") as (elsewhere, paused, go),
        CollieClient(elsewhere.url, bob.token) as bob_elsewhere,
    ):
        voting = threading.Thread(target=lambda: bob_elsewhere.submit(run.id, query_id, 0))
        voting.start()
        assert paused.wait(30), "bob's vote never reached the database"
        lowering = threading.Thread(target=lambda: operator.set_quality(run.id, redundancy=2))
        lowering.start()
        wait(lambda: waiting() > 0 or not lowering.is_alive(), "the change neither waited nor ended")
        go.set()
        voting.join(30)
        lowering.join(30)
    assert trainer.query(run.id, query_id).status == "labelled"  # two votes, r = 2: it counts


def test_a_vote_that_waited_for_a_redundancy_change_is_counted_under_the_new_one(
    live: BackgroundServer, database_url: str, trainer: CollieClient, operator: CollieClient
) -> None:
    """r 3 → 2 committed while the second vote waits for the query's row (the change holds it, see
    hold_unlabelled): the vote is given under r = 2, read after the wait, not the r of before it."""
    run, bob, query_id = one_vote_of_three(live, trainer, operator)
    with (
        lock_waits(database_url) as waiting,
        paused_after(database_url, "UPDATE RUNS SET REDUNDANCY") as (elsewhere, paused, go),
        CollieClient(elsewhere.url, TOKENS["operator"]) as operator_elsewhere,
    ):
        lowering = threading.Thread(target=lambda: operator_elsewhere.set_quality(run.id, redundancy=2))
        lowering.start()
        assert paused.wait(30), "the change never reached the database"
        voting = threading.Thread(target=lambda: bob.submit(run.id, query_id, 0))
        voting.start()
        wait(lambda: waiting() > 0 or not voting.is_alive(), "the vote neither waited nor ended")
        go.set()
        lowering.join(30)
        voting.join(30)
    assert trainer.query(run.id, query_id).status == "labelled"


def test_a_deadlock_between_service_processes_is_a_busy_database_the_client_may_retry(
    live: BackgroundServer, database_url: str
) -> None:
    """PostgreSQL rolls one of two transactions back when each waits for the other's row: the
    service answers that one 503 (busy, nothing written), not an outage or a 500."""
    engine = create_engine(database_url)
    failed: list[DBAPIError] = []
    both = threading.Barrier(2)

    def take(first: int, second: int) -> None:
        try:
            with engine.begin() as conn:
                conn.execute(text("SELECT id FROM principals WHERE id = :id FOR UPDATE"), {"id": first})
                both.wait(10)
                conn.execute(text("SELECT id FROM principals WHERE id = :id FOR UPDATE"), {"id": second})
        except DBAPIError as exc:
            failed.append(exc)

    try:
        with engine.connect() as conn:
            ids = list(conn.execute(text("SELECT id FROM principals ORDER BY id LIMIT 2")).scalars())
        threads = [threading.Thread(target=take, args=order) for order in (ids, ids[::-1])]
        for t in threads:
            t.start()
        for t in threads:
            t.join(30)
        assert not any(t.is_alive() for t in threads), "a transaction still waits"
    finally:
        engine.dispose()
    assert len(failed) == 1, failed
    assert isinstance(database_fault(failed[0], "postgresql"), DatabaseBusy)


def test_two_sessions_posted_at_once_never_pass_the_budget_together(
    live: BackgroundServer, database_url: str, trainer: CollieClient
) -> None:
    """A post whose transaction is open (its queries inserted, not committed) holds the run's posting
    lock: a second post waits for it, then counts its queries and is refused. Without the lock it counted
    only what was committed, and the two together stored 6 queries of a budget of 4."""
    run = trainer.create_run(make_run_spec(n_total=4))
    trainer.post_session(run.id, make_session(0, 2))
    answers: dict[int, SessionPosted | ApiError] = {}

    def post(client: CollieClient, session: int) -> None:
        try:
            answers[session] = client.post_session(run.id, make_session(session, 2))
        except ApiError as exc:
            answers[session] = exc

    with (
        lock_waits(database_url) as waiting,
        paused_after(database_url, "INSERT INTO QUERIES") as (elsewhere, paused, go),
        CollieClient(elsewhere.url, TOKENS["trainer"]) as trainer_elsewhere,
    ):
        first = threading.Thread(target=post, args=(trainer_elsewhere, 1))
        first.start()
        assert paused.wait(30), "the first post never reached the database"
        second = threading.Thread(target=post, args=(trainer, 2))
        second.start()
        wait(lambda: waiting() > 0 or not second.is_alive(), "the second post neither waited nor ended")
        go.set()
        first.join(30)
        second.join(30)
    stored, refused = answers[1], answers[2]
    assert isinstance(stored, SessionPosted) and stored.created == ["1-0", "1-1"]
    assert isinstance(refused, ApiError) and refused.status == 409
    assert "budget is 4 queries and 4 are stored" in str(refused.detail)
    assert len(trainer.queries(run.id)) == 4


def test_a_label_is_not_held_up_by_a_session_being_posted_to_its_run(
    live: BackgroundServer, database_url: str, trainer: CollieClient, operator: CollieClient
) -> None:
    """Posts take turns on a lock of their own: a label given while a post's transaction is open
    (up to 128 MiB of frames) is stored at once. A lock on the run's row would hold it (the label
    updates that row for its event) until the post committed."""
    run = trainer.create_run(make_run_spec(n_total=4))
    trainer.post_session(run.id, make_session(0, 2))
    ann = CollieClient(live.url, operator.create_labeler(f"ann-posting-{run.id}").token)
    claimed = ann.claim(run.id).query.query_id
    labelled = threading.Event()
    with (
        paused_after(database_url, "INSERT INTO QUERIES") as (elsewhere, paused, go),
        CollieClient(elsewhere.url, TOKENS["trainer"]) as trainer_elsewhere,
    ):
        posting = threading.Thread(target=trainer_elsewhere.post_session, args=(run.id, make_session(1, 2)))
        posting.start()
        assert paused.wait(30), "the post never reached the database"
        labelling = threading.Thread(target=lambda: (ann.submit(run.id, claimed, 0), labelled.set()))
        labelling.start()
        labelling.join(20)
        assert labelled.is_set(), "the label waited for the post"
        go.set()
        posting.join(30)
    assert len(trainer.queries(run.id)) == 4
