"""Lease gaps: a released query is nobody's (its former holder cannot label it), and an undo that
hands a query back keeps its labeler within MAX_HOLD."""

from __future__ import annotations

import time
from collections.abc import Callable

import pytest
from sqlalchemy import update

from backend.models import Principal
from backend.server import BackgroundServer
from backend.services import leases
from backend.services.auth import Caller
from collie.client import ApiError, CollieClient
from collie.schemas import MAX_HOLD, RunRead

from .conftest import make_run_spec, make_session


@pytest.fixture(scope="module")
def database_url(both_databases: str) -> str:
    """This module runs on SQLite and on a real PostgreSQL server."""
    return both_databases


def held_by(client: CollieClient, run_id: int, name: str) -> list[str]:
    return [q.query_id for q in client.queries(run_id, status="leased") if q.lease_owner == name]


def test_a_released_query_cannot_be_labelled_by_its_former_holder(
    new_labeler: Callable[[str], CollieClient], run: RunRead
) -> None:

    holder = new_labeler("releaser")
    claim = holder.claim(run.id)
    assert claim is not None
    assert holder.release(run.id, claim.query.query_id).status == "pending"
    with pytest.raises(ApiError) as err:
        holder.submit(run.id, claim.query.query_id, 2)
    assert err.value.status == 409 and "not claimed by you" in err.value.detail
    assert holder.query(run.id, claim.query.query_id).status == "pending"


def test_undo_keeps_the_labeler_within_max_hold(
    trainer: CollieClient, new_labeler: Callable[[str], CollieClient]
) -> None:
    created = trainer.create_run(make_run_spec())
    trainer.post_session(created.id, make_session(0, 6))
    who = new_labeler("undoer")
    name = who.me().name
    done = []
    for _ in range(2):
        claim = who.claim(created.id)
        assert claim is not None
        who.submit(created.id, claim.query.query_id, 1)
        done.append(claim.query.query_id)
    for hold in range(1, MAX_HOLD + 1):  # one on screen, one preloaded
        assert who.claim(created.id, hold=hold) is not None
    assert len(held_by(trainer, created.id, name)) == MAX_HOLD
    for query_id in done:
        assert who.undo(created.id, query_id).query_status == "leased"
        held = held_by(trainer, created.id, name)
        assert query_id in held and len(held) <= MAX_HOLD, held
    run = trainer.run(created.id)
    assert run.queue.leased <= MAX_HOLD and run.n_labels == 0


def test_revoking_a_labeler_hands_their_claims_back_at_once(
    trainer: CollieClient, operator: CollieClient, new_labeler: Callable[[str], CollieClient]
) -> None:
    created = trainer.create_run(make_run_spec())
    trainer.post_session(created.id, make_session(0, 4))
    gone = new_labeler("revoked-holder")
    me = gone.me()
    claims = [gone.claim(created.id, hold=hold) for hold in range(1, MAX_HOLD + 1)]
    held = [c.query.query_id for c in claims if c is not None]
    assert len(held) == MAX_HOLD and held_by(trainer, created.id, me.name) == held
    operator.revoke(me.id)
    assert held_by(trainer, created.id, me.name) == []  # not after the lease: now
    assert {trainer.query(created.id, q).status for q in held} == {"pending"}
    assert trainer.run(created.id).queue.leased == 0
    taker = new_labeler("next-in-line")
    first = taker.claim(created.id)
    assert first is not None and first.query.query_id == held[0]  # the oldest, as before the claim
    taker.submit(created.id, held[0], 1)
    with pytest.raises(ApiError) as err:
        gone.submit(created.id, held[1], 1)
    assert err.value.status == 401


def test_a_revoked_caller_past_the_token_check_takes_and_renews_nothing(
    live: BackgroundServer, trainer: CollieClient, new_labeler: Callable[[str], CollieClient]
) -> None:
    """Another service process (or a request already past its token check) may still let a revoked
    token in for a moment: the lease statements themselves refuse it."""
    created = trainer.create_run(make_run_spec())
    trainer.post_session(created.id, make_session(0, 3))
    late = new_labeler("late-revoked")
    me = late.me()
    held = late.claim(created.id)
    assert held is not None
    db = live.app.state.db
    with db.write() as conn:  # revoked elsewhere: revoked_at is set, this process's release not run
        conn.execute(update(Principal).where(Principal.id == me.id).values(revoked_at=time.time()))
    expires = trainer.query(created.id, held.query.query_id).lease_expires_at
    caller = Caller(me.id, me.name, "labeler")
    with db.write() as conn:
        assert leases.claim(conn, created.id, caller, lease_s=600.0, hold=2) is None  # nothing new
    assert trainer.query(created.id, held.query.query_id).lease_expires_at == expires  # not renewed
    assert trainer.run(created.id).queue.leased == 1


def test_a_run_that_ends_hands_every_claim_back_at_once(
    trainer: CollieClient, operator: CollieClient, new_labeler: Callable[[str], CollieClient]
) -> None:
    """The queue said "leased: on a labeler's screen now" of a finished run's segments until each
    lease ran out, though no screen could label them any more. A run being stopped still takes the
    labels on screen (the trainer has not finished): its leases stand until it ends."""
    created = trainer.create_run(make_run_spec())
    trainer.post_session(created.id, make_session(0, 4))
    holder = new_labeler("holder-at-the-end")
    held = [c.query.query_id for c in (holder.claim(created.id, hold=h) for h in (1, 2)) if c is not None]
    assert len(held) == MAX_HOLD
    operator.stop(created.id)
    assert trainer.run(created.id).queue.leased == MAX_HOLD  # stopping: a label on screen still lands
    holder.submit(created.id, held[0], 1)
    trainer.set_status(created.id, "finished")
    assert trainer.run(created.id).queue.model_dump(include={"pending", "leased", "labelled"}) == {
        "pending": 3,
        "leased": 0,
        "labelled": 1,
    }
    assert trainer.query(created.id, held[1]).lease_owner is None
