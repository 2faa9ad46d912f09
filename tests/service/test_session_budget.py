"""A run's budget (n_total): the service refuses a new feedback session whose new queries would take
the run's stored queries past it, counting as the trainer does (every query asked once, retired ones
too, gold copies not); a re-posted session is answered as before, even at the budget."""

from __future__ import annotations

import threading
from collections.abc import Callable

import pytest

from collie.client import ApiError, CollieClient, Conflict
from collie.schemas import SessionPosted

from .conftest import make_run_spec, make_session


@pytest.fixture(scope="module")
def database_url(both_databases: str) -> str:
    """This module runs on SQLite and on a real PostgreSQL server."""
    return both_databases


def refusal(run_id: int, n_total: int, stored: int, adding: int) -> str:
    stored_part = f"run {run_id}'s budget is {n_total} queries and {stored} are stored"
    return f"{stored_part}: a new session of {adding} more would pass it"


def test_a_new_session_past_the_budget_is_refused_naming_the_budget_and_what_is_stored(
    trainer: CollieClient,
) -> None:
    run = trainer.create_run(make_run_spec(n_total=5))
    trainer.post_session(run.id, make_session(0, 4))
    before = trainer.run(run.id).queue
    with pytest.raises(Conflict) as err:
        trainer.post_session(run.id, make_session(1, 2))
    assert (err.value.status, err.value.detail) == (409, refusal(run.id, 5, 4, 2))
    assert trainer.run(run.id).queue == before
    posted = trainer.post_session(run.id, make_session(1, 1))  # the refused position was not kept
    assert not posted.reused and posted.created == ["1-0"]
    assert len(trainer.queries(run.id)) == 5


def test_a_re_post_at_the_budget_is_answered_and_stored_ids_do_not_count_twice(trainer: CollieClient) -> None:
    run = trainer.create_run(make_run_spec(n_total=4))
    trainer.post_session(run.id, make_session(0, 4))
    again = trainer.post_session(run.id, make_session(0, 6))  # a resumed trainer re-posts its position
    assert again.reused and again.query_ids == ["0-0", "0-1", "0-2", "0-3"]
    stored_only = make_session(1, 2)
    stored_only.queries = make_session(0, 2).queries  # ids 0-0 and 0-1: nothing new to store
    posted = trainer.post_session(run.id, stored_only)
    assert not posted.reused and posted.created == [] and posted.existing == ["0-0", "0-1"]
    one_new = make_session(2, 1)
    one_new.queries = [make_session(0, 3).queries[2], *one_new.queries]  # 0-2 is stored, 2-0 is new
    with pytest.raises(Conflict) as err:
        trainer.post_session(run.id, one_new)
    assert err.value.detail == refusal(run.id, 4, 4, 1)


def test_retired_queries_count_and_gold_copies_do_not(
    trainer: CollieClient, operator: CollieClient, new_labeler: Callable[[str], CollieClient]
) -> None:
    """Retired: the trainer asked them (its queries_asked counts them). A gold copy is a labeler's
    re-serving of an earlier segment, never asked by the trainer (services/gold.py)."""
    run = trainer.create_run(make_run_spec(task="north", n_total=4))
    trainer.post_session(run.id, make_session(0, 2))
    trainer.retire(run.id, ["0-1"])
    first = new_labeler(f"budget-first-{run.id}")
    first.submit(run.id, first.claim(run.id).query.query_id, 1)
    operator.set_quality(run.id, gold_rate=0.5)
    trainer.post_session(run.id, make_session(1, 1))
    gold = new_labeler(f"budget-gold-{run.id}").claim(run.id)  # a copy of 0-0: a row of the run's queries
    assert gold is not None and gold.query.query_id not in {"0-0", "0-1", "1-0"}
    trainer.post_session(run.id, make_session(2, 1))  # 4 of 4: the retired one counted, the gold copy not
    with pytest.raises(Conflict) as err:
        trainer.post_session(run.id, make_session(3, 1))
    assert err.value.detail == refusal(run.id, 4, 4, 1)


def test_sessions_posted_at_once_never_pass_the_budget_together(trainer: CollieClient) -> None:
    """Eight positions of 2 posted at the same moment into a budget of 10: five are stored, three refused."""
    run = trainer.create_run(make_run_spec(n_total=10))
    start = threading.Barrier(8)
    posted: list[SessionPosted] = []
    refused: list[ApiError] = []

    def post(session: int) -> None:
        body = make_session(session, 2)
        start.wait(30)
        try:
            posted.append(trainer.post_session(run.id, body))
        except ApiError as exc:
            refused.append(exc)

    threads = [threading.Thread(target=post, args=(s,)) for s in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert (len(posted), [e.status for e in refused]) == (5, [409] * 3)
    assert len(trainer.queries(run.id)) == 10
