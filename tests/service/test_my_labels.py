"""A labeler's own labels (GET /runs/{id}/labels/mine, the labeling UI's "my labels" panel) and an
operator's run instructions (PUT /runs/{id}/instructions)."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from collie.client import ApiError, CollieClient
from collie.schemas import MAX_INSTRUCTIONS, RunRead


def test_my_labels_newest_first_with_revisions_and_undo(
    labeler: CollieClient, new_labeler: Callable[[str], CollieClient], run: RunRead
) -> None:
    for _ in range(3):
        claimed = labeler.claim(run.id)
        assert claimed is not None
        labeler.submit(run.id, claimed.query.query_id, 0)
    first, second, third = (e.query_id for e in labeler.label_events(run.id))
    labeler.submit(run.id, first, 1)  # a revision
    labeler.undo(run.id, second)
    mine = labeler.my_labels(run.id)
    assert [m.query_id for m in mine] == [first, third, second]  # by their newest label event
    by_id = {m.query_id: m for m in mine}
    assert (by_id[first].label, by_id[first].revisions, by_id[first].in_effect) == (1, 1, True)
    assert by_id[second].in_effect is False and by_id[third].in_effect is True
    assert len(by_id[third].xy) == len(labeler.query(run.id, third).xy)
    assert new_labeler("someone-else").my_labels(run.id) == []


def test_instructions_are_set_by_an_operator_and_read_by_everyone(
    operator: CollieClient, labeler: CollieClient, run: RunRead
) -> None:
    assert labeler.run(run.id).instructions == ""
    assert operator.set_instructions(run.id, "  Ignore the first second.  ").instructions == "Ignore the first second."
    assert labeler.run(run.id).instructions == "Ignore the first second."
    with pytest.raises(ApiError) as refused:
        labeler.set_instructions(run.id, "mine now")
    assert refused.value.status == 403
    too_long = operator._http.put(f"/runs/{run.id}/instructions", json={"text": "x" * (MAX_INSTRUCTIONS + 1)})
    assert too_long.status_code == 422
