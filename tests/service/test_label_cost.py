"""What one label costs the database: the SQL statements a label POST runs, counted on the service's
own engine behind a real server. A new statement on the service's hottest write shows up here (and
in `make bench-service` as CPU per label); lower a count here when you take one away."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest
from sqlalchemy import event

from backend.server import BackgroundServer
from collie.client import ApiError, CollieClient
from collie.labels import Label
from collie.schemas import LabelChangedEvent, RunRead

from .conftest import both_databases, make_run_spec, make_session

database_url = both_databases

# SQL per request, BEGIN/COMMIT and SQLite's PRAGMAs (the background checkpoint) left out.
LABEL = 7  # lookup (query, run, own vote, request id seen), event, vote, votes, stream id, stream event, query
CLAIM = 5  # sweep expired leases, renew held ones, gold rate, take the oldest pending, its frames
REPEAT = 3  # lookup, the first event by request id, that event with the query as it is now


@contextmanager
def counted(live: BackgroundServer) -> Iterator[list[str]]:
    statements: list[str] = []

    def count(_conn: Any, _cursor: Any, statement: str, *_: Any) -> None:
        word = statement.split(None, 1)[0].upper()
        if word not in ("BEGIN", "COMMIT", "PRAGMA", "ROLLBACK"):
            statements.append(" ".join(statement.split()))

    engine = live.app.state.db.engine
    event.listen(engine, "before_cursor_execute", count)
    try:
        yield statements
    finally:
        event.remove(engine, "before_cursor_execute", count)


@pytest.fixture
def fresh_run(trainer: CollieClient) -> RunRead:
    created = trainer.create_run(make_run_spec())
    trainer.post_session(created.id, make_session(0, 4))
    return created


def test_statements_per_label(live: BackgroundServer, labeler: CollieClient, fresh_run: RunRead) -> None:
    held = labeler.claim(fresh_run.id)  # also resolves the token: the token cache answers from here on
    assert held is not None
    with counted(live) as statements:
        ack = labeler.submit(fresh_run.id, held.query.query_id, Label.GOOD, client_request_id="cost-1", next=True)
    assert ack.label == 2 and ack.next is not None
    assert len(statements) == LABEL + CLAIM, "\n".join(statements)

    following = ack.next.query.query_id
    with counted(live) as statements:
        ack = labeler.submit(fresh_run.id, following, Label.BAD, client_request_id="cost-2")
    assert ack.label == 0 and ack.query_status == "labelled"
    assert len(statements) == LABEL, "\n".join(statements)


def test_statements_per_revision_and_repeat(live: BackgroundServer, labeler: CollieClient, fresh_run: RunRead) -> None:
    held = labeler.claim(fresh_run.id)
    assert held is not None
    query_id = held.query.query_id
    first = labeler.submit(fresh_run.id, query_id, Label.NEUTRAL, client_request_id="rev-1")
    with counted(live) as statements:
        revised = labeler.submit(fresh_run.id, query_id, Label.GOOD, client_request_id="rev-2")
    assert revised.label == 2 and revised.event.revises_event_id == first.event.id
    assert len(statements) == LABEL, "\n".join(statements)  # the vote is updated in place, not deleted and re-added

    with counted(live) as statements:
        repeat = labeler.submit(fresh_run.id, query_id, Label.GOOD, client_request_id="rev-2")
    assert repeat.duplicate and repeat.event.id == revised.event.id and repeat.label == 2
    assert len(statements) == REPEAT, "\n".join(statements)


def test_statements_per_event_page(live: BackgroundServer, labeler: CollieClient, fresh_run: RunRead) -> None:
    """The trainer's long poll reads the log once for a page that has events (no separate run
    lookup), and still answers 404 for an unknown run."""
    held = labeler.claim(fresh_run.id)
    assert held is not None
    after = labeler.run(fresh_run.id).last_event_id
    labeler.submit(fresh_run.id, held.query.query_id, Label.GOOD)
    with counted(live) as statements:
        page = labeler.events(fresh_run.id, after=after, wait_s=5.0)
    assert [(type(e), e.data.query_id) for e in page.events if isinstance(e, LabelChangedEvent)] == [
        (LabelChangedEvent, held.query.query_id)
    ]
    assert len(statements) == 1, "\n".join(statements)
    with pytest.raises(ApiError) as unknown:
        labeler.events(fresh_run.id + 1000, after=0, wait_s=1.0)
    assert unknown.value.status == 404
