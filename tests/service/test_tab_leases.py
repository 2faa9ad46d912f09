"""Per-tab leases: a claim made for a browser tab is that tab's; a label that names its tab is
taken only from the tab holding the lease, else a typed 409 (NotHeld) says why. Revisions and
clients without a tab keep the labeler-wide rules."""

from __future__ import annotations

import time
from collections.abc import Callable
from datetime import UTC, datetime

import pytest

from collie.client import CollieClient, Conflict, NotHolding
from collie.schemas import MAX_HOLD, MAX_TABS, RunCreate, RunRead

from .conftest import make_run_spec, make_session

TAB_A, TAB_B = "tab-aaaaaaaa", "tab-bbbbbbbb"


@pytest.fixture(scope="module")
def database_url(both_databases: str) -> str:
    """This module runs on SQLite and on a real PostgreSQL server."""
    return both_databases


def refused(call: Callable[[], object]) -> str:
    """The typed reason of a NotHolding refusal."""
    with pytest.raises(NotHolding) as err:
        call()
    assert err.value.status == 409 and err.value.refusal.detail == err.value.detail
    return err.value.refusal.reason


def fresh_run(trainer: CollieClient, n: int, redundancy: int = 1) -> RunRead:
    spec = make_run_spec(n_total=n)
    created = trainer.create_run(RunCreate(**{**spec.model_dump(), "redundancy": redundancy}))
    trainer.post_session(created.id, make_session(0, n))
    return created


def test_each_tab_holds_its_own_queries(new_labeler: Callable[[str], CollieClient], trainer: CollieClient) -> None:
    run = fresh_run(trainer, 6)
    who = new_labeler("two-tabs")
    a = who.claim(run.id, tab=TAB_A)
    b = who.claim(run.id, tab=TAB_B)
    assert a is not None and b is not None and a.query.query_id != b.query.query_id
    assert a.held == [a.query.query_id] and b.held == [b.query.query_id]
    again = who.claim(run.id, tab=TAB_A)  # a reload of tab A (its id survives) gets its claim back
    assert again is not None and again.query.query_id == a.query.query_id
    second = who.claim(run.id, tab=TAB_A, hold=MAX_HOLD)  # A preloads its next
    assert second is not None and second.held == [a.query.query_id, second.query.query_id]
    assert who.claim(run.id).held == sorted([*second.held, b.query.query_id])  # type: ignore[union-attr]  # tab-less: all
    # B may not label A's segment; A may
    assert refused(lambda: who.submit(run.id, a.query.query_id, 1, tab=TAB_B)) == "other_tab"
    assert refused(lambda: who.submit(run.id, a.query.query_id, "skip", tab=TAB_B)) == "other_tab"
    ack = who.submit(run.id, a.query.query_id, 1, tab=TAB_A)
    assert ack.query_status == "labelled" and ack.event.revises_event_id is None


@pytest.mark.parametrize("redundancy", [1, 2])
def test_a_tab_never_labels_what_was_labelled_elsewhere(
    new_labeler: Callable[[str], CollieClient], trainer: CollieClient, redundancy: int
) -> None:
    run = fresh_run(trainer, 3, redundancy)
    who = new_labeler(f"stale-{redundancy}")
    claim = who.claim(run.id, tab=TAB_A)
    assert claim is not None
    query_id = claim.query.query_id
    who.submit(run.id, query_id, 1)  # another UI or client of the same labeler, without a tab
    assert refused(lambda: who.submit(run.id, query_id, 2, tab=TAB_A)) == "labelled_by_you"
    events = [e for e in trainer.label_events(run.id) if e.query_id == query_id]
    assert [(e.value, e.revises_event_id) for e in events] == [(1, None)]
    revision = who.submit(run.id, query_id, 2)  # from "my labels": a revision needs no lease
    assert revision.event.revises_event_id == events[0].id


def test_why_a_tab_may_not_label(new_labeler: Callable[[str], CollieClient], trainer: CollieClient) -> None:
    run = fresh_run(trainer, 4)
    ann, bob = new_labeler("why-ann"), new_labeler("why-bob")
    mine = ann.claim(run.id, tab=TAB_A)
    theirs = bob.claim(run.id, tab=TAB_A)  # tab ids are per labeler: the same id is no clash
    assert mine is not None and theirs is not None
    assert refused(lambda: ann.submit(run.id, theirs.query.query_id, 0, tab=TAB_A)) == "other_labeler"
    bob.submit(run.id, theirs.query.query_id, 0, tab=TAB_A)
    assert refused(lambda: ann.submit(run.id, theirs.query.query_id, 0, tab=TAB_A)) == "labelled"
    ann.release(run.id, mine.query.query_id)
    assert refused(lambda: ann.submit(run.id, mine.query.query_id, 0, tab=TAB_A)) == "not_claimed"
    trainer.retire(run.id, [mine.query.query_id])
    assert refused(lambda: ann.submit(run.id, mine.query.query_id, 0, tab=TAB_A)) == "retired"
    tabless = ann.claim(run.id)  # a claim without a tab is no tab's: a tab may not label it
    assert tabless is not None
    assert refused(lambda: ann.submit(run.id, tabless.query.query_id, 0, tab=TAB_A)) == "other_tab"
    assert ann.submit(run.id, tabless.query.query_id, 0).query_status == "labelled"


def test_a_late_label_comes_only_from_the_tab_that_held_it(
    new_labeler: Callable[[str], CollieClient], trainer: CollieClient
) -> None:
    run = fresh_run(trainer, 2)
    who = new_labeler("late")
    claim = who.claim(run.id, lease_s=0.2, tab=TAB_A)
    assert claim is not None
    time.sleep(0.4)  # the lease ran out; nobody took the query since
    assert refused(lambda: who.submit(run.id, claim.query.query_id, 1, tab=TAB_B)) == "other_tab"
    assert who.submit(run.id, claim.query.query_id, 1, tab=TAB_A).query_status == "labelled"


def test_undo_hands_the_query_back_to_the_tab_that_undid_it(
    new_labeler: Callable[[str], CollieClient], trainer: CollieClient
) -> None:
    run = fresh_run(trainer, 5)
    who = new_labeler("undo-tab")
    claim = who.claim(run.id, tab=TAB_A)
    assert claim is not None
    query_id = claim.query.query_id
    who.submit(run.id, query_id, 1, tab=TAB_A)
    for hold in range(1, MAX_HOLD + 1):
        assert who.claim(run.id, tab=TAB_A, hold=hold) is not None
    assert who.undo(run.id, query_id, tab=TAB_A).query_status == "leased"
    held = who.claim(run.id, tab=TAB_A)
    assert held is not None and query_id in held.held and len(held.held) <= MAX_HOLD
    assert refused(lambda: who.submit(run.id, query_id, 2, tab=TAB_B)) == "other_tab"
    ack = who.submit(run.id, query_id, 2, tab=TAB_A)  # labelled afresh (the undone vote is gone)
    assert ack.query_status == "labelled" and ack.event.revises_event_id is None


def test_a_labeler_holds_at_most_max_tabs_tabs_worth(
    new_labeler: Callable[[str], CollieClient], trainer: CollieClient
) -> None:
    run = fresh_run(trainer, MAX_HOLD * MAX_TABS + 3)
    who = new_labeler("many-tabs")
    tabs = [f"tab-many-{i:04d}" for i in range(MAX_TABS + 1)]
    for tab in tabs[:MAX_TABS]:
        for hold in range(1, MAX_HOLD + 1):
            assert who.claim(run.id, tab=tab, hold=hold) is not None
    with pytest.raises(Conflict, match=f"your other tabs hold {MAX_HOLD * MAX_TABS} segments"):
        who.claim(run.id, tab=tabs[-1])  # one tab too many: told so, not "nothing to label"
    assert trainer.run(run.id).queue.leased == MAX_HOLD * MAX_TABS
    first = tabs[0]
    held = who.claim(run.id, tab=first)
    assert held is not None
    who.submit(run.id, held.query.query_id, 1, tab=first)  # a tab labels: room for the fifth again
    assert who.claim(run.id, tab=tabs[-1]) is not None


def test_a_label_can_claim_the_tabs_next_preload(
    new_labeler: Callable[[str], CollieClient], trainer: CollieClient
) -> None:
    run = fresh_run(trainer, 5)
    who = new_labeler("label-and-preload")
    shown = who.claim(run.id, tab=TAB_A)
    ahead = who.claim(run.id, tab=TAB_A, hold=MAX_HOLD)
    other = who.claim(run.id, tab=TAB_B)
    assert shown is not None and ahead is not None and other is not None
    ack = who.submit(run.id, shown.query.query_id, 1, tab=TAB_A, next=True, hold=MAX_HOLD)
    assert ack.next is not None  # the tab shows `ahead` next; the label's answer brings the one after
    assert ack.next.query.query_id not in (shown.query.query_id, ahead.query.query_id, other.query.query_id)
    assert ack.next.held == [ahead.query.query_id, ack.next.query.query_id]


def test_a_label_and_an_undo_lease_for_as_long_as_the_client_asks(
    new_labeler: Callable[[str], CollieClient], trainer: CollieClient
) -> None:
    """The labeling UI leases for 60 s and renews every 20 s; the segment claimed with a label's answer
    (and one an undo hands back) was leased for the service's default (120 s), so a UI that died just
    after a label kept it from others twice as long as its docs say."""
    run = fresh_run(trainer, 4)
    who = new_labeler("short-leases")

    def expires_in(query_id: str) -> float:
        (query,) = [q for q in trainer.queries(run.id) if q.query_id == query_id]
        assert query.lease_expires_at is not None
        return (query.lease_expires_at - datetime.now(UTC)).total_seconds()

    first = who.claim(run.id, lease_s=30, tab=TAB_A)
    assert first is not None
    ack = who.submit(run.id, first.query.query_id, 1, tab=TAB_A, next=True, hold=MAX_HOLD, lease_s=30)
    assert ack.next is not None
    for held in ack.next.held:
        assert 20 < expires_in(held) <= 30, held
    assert who.undo(run.id, first.query.query_id, tab=TAB_A, lease_s=30).query_status == "leased"
    assert 20 < expires_in(first.query.query_id) <= 30
    ack = who.submit(run.id, first.query.query_id, 2, tab=TAB_A, next=True)  # no lease_s: the service's
    assert ack.next is not None and expires_in(ack.next.query.query_id) > 100


def test_a_closed_tabs_lease_runs_out_while_the_labelers_other_tab_goes_on(
    new_labeler: Callable[[str], CollieClient], trainer: CollieClient
) -> None:
    """A tab's claim renews that tab's leases only. It used to renew every lease the labeler held,
    so a segment left in a tab that closed without handing it back (its UI died, the service was
    down then) stayed leased for as long as the labeler labelled elsewhere: nobody else could take
    it, and a run that waits for its session's labels waited on it. An API client's claim (no tab)
    is the labeler's as a whole and still renews everything they hold."""
    run = fresh_run(trainer, 4)
    who = new_labeler("closed-tab")
    left = who.claim(run.id, tab=TAB_A, lease_s=1.0)
    assert left is not None
    deadline = time.monotonic() + 2.0
    while time.monotonic() < deadline:  # the other tab renews every so often
        assert who.claim(run.id, tab=TAB_B, lease_s=60.0) is not None
        time.sleep(0.2)
    with new_labeler("someone-else") as other:
        taken = [other.claim(run.id, hold=h) for h in (1, 2)]
    assert left.query.query_id in {c.query.query_id for c in taken if c is not None}
    assert who.claim(run.id, lease_s=60.0) is not None  # no tab: renews the labeler's B lease
    (b_query,) = [q for q in trainer.queries(run.id) if q.status == "leased" and q.lease_owner == "closed-tab"]
    assert b_query.lease_expires_at is not None
    assert (b_query.lease_expires_at - datetime.now(UTC)).total_seconds() > 30
