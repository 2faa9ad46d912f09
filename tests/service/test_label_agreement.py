"""Agreement between labelers, the one agreement a run without a rule still has: over segments two
or more distinct labelers label now (latest label each, unless undone), agreeing labeler pairs."""

from __future__ import annotations

from types import SimpleNamespace

from backend.services.label_stats import between_labelers


def event(pk: int, name: str, kind: str, value: int | None = None) -> SimpleNamespace:
    return SimpleNamespace(query_pk=pk, name=name, kind=kind, value=value)


def test_pairs_on_shared_segments_with_revisions_undos_and_skips() -> None:
    events = [
        event(1, "ann", "label", 0),
        event(1, "bob", "label", 1),
        event(1, "bob", "label", 0),  # bob revises: agrees with ann now
        event(1, "cy", "label", 2),  # three labelers on segment 1: pairs (a,b) agree, (a,c), (b,c) do not
        event(2, "ann", "label", 1),
        event(2, "bob", "label", 1),
        event(2, "bob", "undo"),  # withdrawn: segment 2 has one labeler left, not shared
        event(3, "ann", "label", 1),
        event(3, "bob", "skip"),  # a skip is not a label
        event(4, "ann", "label", 2),
        event(4, "bob", "label", 2),  # agree
    ]
    agreement, shared = between_labelers(events)
    assert shared == 2 and agreement == 2 / 4


def test_no_shared_segment_means_no_agreement_figure() -> None:
    assert between_labelers([event(1, "ann", "label", 0), event(2, "bob", "label", 0)]) == (None, 0)
    assert between_labelers([]) == (None, 0)
