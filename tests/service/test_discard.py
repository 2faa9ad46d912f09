"""An operator discards one labeler's labels in a run: each vote is withdrawn as an undo in that
labeler's name, the trainer hears every effective label withdrawn, the queries go back to the pool,
and the events still replay to the stored state."""

from __future__ import annotations

import threading
from collections import defaultdict
from collections.abc import Callable

import pytest

from backend.server import BackgroundServer
from backend.services.consensus import VoteEvent, replay
from collie.client import ApiError, CollieClient
from collie.schemas import LabelChangedEvent, WithdrawnEvent

from .conftest import TOKENS, make_run_spec, make_session

Labelers = Callable[[str], CollieClient]


@pytest.fixture(scope="module")
def database_url(both_databases: str) -> str:
    """This module runs on SQLite and on a real PostgreSQL server."""
    return both_databases


def label_all(client: CollieClient, run_id: int, values: list[int]) -> list[str]:
    done = []
    for value in values:
        claim = client.claim(run_id)
        assert claim is not None
        client.submit(run_id, claim.query.query_id, value)  # type: ignore[arg-type]
        done.append(claim.query.query_id)
    return done


def stream(trainer: CollieClient, run_id: int) -> list[tuple[str, str, int | None]]:
    kinds = LabelChangedEvent | WithdrawnEvent
    return [(e.kind, e.data.query_id, e.data.label) for e in trainer.events(run_id).events if isinstance(e, kinds)]


def replayed(trainer: CollieClient, run_id: int, r: int) -> dict[str, int]:
    """The effective labels the label events replay to (consensus.replay, every labeler a labeler)."""
    by_query: dict[str, list[VoteEvent]] = defaultdict(list)
    ids: dict[str, int] = {}
    for e in trainer.label_events(run_id):
        if e.kind in ("label", "undo"):
            by_query[e.query_id].append(VoteEvent(e.kind, ids.setdefault(e.labeler, len(ids)), e.value, "labeler"))
    labels = {q: replay(events, r)[1] for q, events in by_query.items()}
    return {q: label for q, label in labels.items() if label is not None}


def stored(trainer: CollieClient, run_id: int) -> dict[str, int]:
    """The effective labels the query rows hold (status labelled, a label)."""
    rows = trainer.queries(run_id)
    assert all((q.status == "labelled") == (q.label is not None) for q in rows), rows
    return {q.query_id: q.label for q in rows if q.label is not None}


def test_discarding_a_labelers_labels_withdraws_them_and_frees_their_queries(
    trainer: CollieClient, operator: CollieClient, new_labeler: Labelers
) -> None:
    run = trainer.create_run(make_run_spec())
    trainer.post_session(run.id, make_session(0, 4))
    careless, careful = new_labeler("careless"), new_labeler("careful")
    theirs = label_all(careless, run.id, [1, 0])
    kept = label_all(careful, run.id, [1])
    assert trainer.run(run.id).n_labels == 3
    gone = operator.discard_votes(run.id, careless.me().id)
    assert (gone.labeler, gone.queries, gone.withdrawn) == ("careless", theirs, theirs)
    undos = [e for e in trainer.label_events(run.id) if e.kind == "undo"]
    assert [(e.query_id, e.labeler) for e in undos] == [(q, "careless") for q in theirs]
    assert all(e.client_request_id.startswith(f"discard-by-{operator.me().id}-") for e in undos)  # who discarded
    assert stream(trainer, run.id)[-2:] == [("withdrawn", q, None) for q in theirs]  # the trainer is told
    state = trainer.run(run.id)
    assert state.n_labels == 1 and state.queue.labelled == 1 and state.queue.pending == 3
    assert {e.query_id: e.label for e in trainer.effective_labels(run.id)} == {kept[0]: 1}
    assert replayed(trainer, run.id, 1) == stored(trainer, run.id) == {kept[0]: 1}
    assert {i.query.query_id for i in trainer.labelled(run.id)} == set(kept)
    relabel = new_labeler("relabeller")
    assert label_all(relabel, run.id, [1, 1, 1])[:2] == theirs  # back in the pool, oldest first
    assert replayed(trainer, run.id, 1) == stored(trainer, run.id)
    again = operator.discard_votes(run.id, careless.me().id)  # nothing left of theirs
    assert (again.queries, again.withdrawn) == ([], [])


def test_with_redundancy_two_the_other_vote_stays_and_the_query_counts_at_two_again(
    trainer: CollieClient, operator: CollieClient, new_labeler: Labelers
) -> None:
    run = trainer.create_run(make_run_spec().model_copy(update={"redundancy": 2}))
    trainer.post_session(run.id, make_session(0, 1))
    a, b, c = new_labeler("r2-discarded"), new_labeler("r2-stays"), new_labeler("r2-third")
    label_all(a, run.id, [0])
    label_all(b, run.id, [1])
    assert {e.query_id: e.label for e in trainer.effective_labels(run.id)} == {"0-0": 0}  # a tie: bad
    gone = operator.discard_votes(run.id, a.me().id)
    assert (gone.queries, gone.withdrawn) == (["0-0"], ["0-0"])
    assert trainer.effective_labels(run.id) == [] and trainer.query(run.id, "0-0").status == "pending"
    assert b.claim(run.id) is None  # b's vote stands: never served to b again
    label_all(c, run.id, [1])
    assert {e.query_id: e.label for e in trainer.effective_labels(run.id)} == {"0-0": 1}  # b and c agree
    assert stream(trainer, run.id)[-2:] == [("withdrawn", "0-0", None), ("label", "0-0", 1)]
    assert replayed(trainer, run.id, 2) == stored(trainer, run.id) == {"0-0": 1}


def test_discard_needs_an_operator_and_a_known_labeler(
    trainer: CollieClient, operator: CollieClient, new_labeler: Labelers
) -> None:
    run = trainer.create_run(make_run_spec())
    someone = new_labeler("not-an-operator")
    with pytest.raises(ApiError) as err:
        someone.discard_votes(run.id, someone.me().id)
    assert err.value.status == 403
    with pytest.raises(ApiError) as err:
        operator.discard_votes(run.id, 10**6)
    assert err.value.status == 404 and "no principal" in err.value.detail
    with pytest.raises(ApiError) as err:
        operator.discard_votes(10**6, someone.me().id)
    assert err.value.status == 404


def test_a_live_lease_stands_gold_copies_stay_and_a_finished_run_is_refused(
    trainer: CollieClient, operator: CollieClient, new_labeler: Labelers
) -> None:
    run = trainer.create_run(make_run_spec().model_copy(update={"redundancy": 2}))
    trainer.post_session(run.id, make_session(0, 2))
    leaving, holder = new_labeler("leaving-r2"), new_labeler("holder-r2")
    label_all(leaving, run.id, [1, 1])  # one vote of two on each: nothing counts yet
    held = holder.claim(run.id)
    assert held is not None  # 0-0, on holder's screen now
    gone = operator.discard_votes(run.id, leaving.me().id)
    assert (gone.queries, gone.withdrawn) == (["0-0", "0-1"], [])  # nothing had counted
    assert trainer.query(run.id, "0-0").status == "leased" and trainer.query(run.id, "0-0").lease_owner == "holder-r2"
    assert trainer.query(run.id, "0-1").status == "pending"
    holder.submit(run.id, "0-0", 0)  # the lease held through the discard
    assert stored(trainer, run.id) == {}  # one vote of two again
    trainer.set_status(run.id, "finished")
    with pytest.raises(ApiError) as err:
        operator.discard_votes(run.id, holder.me().id)
    assert err.value.status == 409 and "finished" in err.value.detail


def test_two_discards_at_once_withdraw_each_label_once(
    trainer: CollieClient, operator: CollieClient, new_labeler: Labelers, live: BackgroundServer
) -> None:
    """On PostgreSQL the query rows are locked as they are read: two operators discarding the two
    labelers of the same queries at once withdraw each effective label once, never twice."""
    run = trainer.create_run(make_run_spec(n_total=12).model_copy(update={"redundancy": 2}))
    trainer.post_session(run.id, make_session(0, 12))
    a, b = new_labeler("race-a"), new_labeler("race-b")
    label_all(a, run.id, [1] * 12)
    label_all(b, run.id, [1] * 12)
    assert trainer.run(run.id).n_labels == 12
    start = threading.Barrier(2)

    def discard(who: CollieClient, labeler_id: int) -> None:
        with CollieClient(live.url, TOKENS["operator"]) as own:
            start.wait()
            own.discard_votes(run.id, labeler_id)

    threads = [threading.Thread(target=discard, args=(c, c.me().id)) for c in (a, b)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    withdrawn = [e for e in trainer.events(run.id).events if isinstance(e, WithdrawnEvent)]
    assert len(withdrawn) == 12 and len({e.data.query_id for e in withdrawn}) == 12
    state = trainer.run(run.id)
    assert state.n_labels == 0 and state.queue.labelled == 0 and state.queue.pending == 12
    assert stored(trainer, run.id) == {}
