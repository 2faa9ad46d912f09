"""One query's review for an operator (GET /api/dashboard/runs/{id}/queries/{qid}/review, what the
labeling UI's review mode replays): its segment with the simulator states, the labels by labeler,
the label it counts as and the oracle's; a clear 404 for an unknown query; operators only."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from collie.client import ApiError, CollieClient
from collie.schemas import RunRead

from .conftest import DIMS, TOKENS, make_run_spec, make_session


@pytest.fixture(scope="module")
def database_url(both_databases: str) -> str:
    """This module runs on SQLite and on a real PostgreSQL server."""
    return both_databases


@pytest.fixture(scope="module")
def disputed(trainer: CollieClient, new_labeler: Callable[[str], CollieClient]) -> RunRead:
    """A north run with redundancy 2: rev-a and rev-b label 0-0 neutral and bad; 0-1 is unlabelled."""
    run = trainer.create_run(make_run_spec(task="north").model_copy(update={"redundancy": 2}))
    post = make_session(0, 2)
    for q in post.queries:  # x = 0.5 at y = 1: north of y = |x|, neutral by the rule
        q.xy = [[0.5, 1.0 + 0.01 * i] for i in range(DIMS.horizon)]
    trainer.post_session(run.id, post)
    for name, value in (("rev-a", 1), ("rev-b", 0)):
        labeler = new_labeler(name)
        assert labeler.claim(run.id).query.query_id == "0-0"  # type: ignore[union-attr]
        labeler.submit(run.id, "0-0", value)  # type: ignore[arg-type]
    return run


def test_the_review_has_the_states_and_the_labels_by_labeler(operator: CollieClient, disputed: RunRead) -> None:
    review = operator.query_review(disputed.id, "0-0")
    assert review.query.query_id == "0-0" and len(review.query.qpos) == DIMS.horizon
    assert review.labels == {"rev-a": 1, "rev-b": 0}
    assert (review.effective, review.oracle, review.has_rule) == (0, 1, True)  # a tie: the safer label counts
    fresh = operator.query_review(disputed.id, "0-1")
    assert (fresh.labels, fresh.effective, fresh.oracle) == ({}, None, 1)


def test_an_unknown_query_or_run_is_a_404_naming_it(operator: CollieClient, disputed: RunRead) -> None:
    with pytest.raises(ApiError) as missing:
        operator.query_review(disputed.id, "no-such-query")
    assert missing.value.status == 404 and "no-such-query" in str(missing.value.detail)
    with pytest.raises(ApiError) as no_run:
        operator.query_review(987654, "0-0")
    assert no_run.value.status == 404 and "987654" in str(no_run.value.detail)


@pytest.mark.parametrize("role", ["labeler", "trainer"])
def test_only_an_operator_may_review(live: object, disputed: RunRead, role: str) -> None:
    with CollieClient(live.url, TOKENS[role]) as other, pytest.raises(ApiError) as refused:  # type: ignore[attr-defined]
        other.query_review(disputed.id, "0-0")
    assert refused.value.status == 403
