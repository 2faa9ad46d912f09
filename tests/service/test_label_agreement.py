"""Agreement between labelers, the one agreement a run without a rule still has: over segments two
or more distinct labelers hold a label on now (their current votes: a revision replaced, an undo
removed — tests/service/test_quality.py covers that bookkeeping), the share of agreeing pairs."""

from __future__ import annotations

from backend.services.label_stats import Vote, between_labelers


def vote(pk: int, name: str, value: int, gold_answer: int | None = None) -> Vote:
    return Vote(
        query_pk=pk, query_id=f"q{pk}", session=0, name=name, value=value, seconds=None, effective=None,
        gold_answer=gold_answer,
    )  # fmt: skip


def test_pairs_on_shared_segments_only_and_gold_left_out() -> None:
    votes = [
        vote(1, "ann", 0),
        vote(1, "bob", 0),  # (ann, bob) agree
        vote(1, "cy", 2),  # three labelers on segment 1: (ann, cy) and (bob, cy) do not
        vote(2, "ann", 1),  # one labeler: not shared
        vote(4, "ann", 2),
        vote(4, "bob", 2),  # agree
        vote(5, "ann", 0, gold_answer=0),
        vote(5, "bob", 2, gold_answer=0),  # gold copies measure a labeler, not agreement
    ]
    agreement, shared = between_labelers(votes)
    assert shared == 2 and agreement == 2 / 4


def test_no_shared_segment_means_no_agreement_figure() -> None:
    assert between_labelers([vote(1, "ann", 0), vote(2, "bob", 0)]) == (None, 0)
    assert between_labelers([]) == (None, 0)
