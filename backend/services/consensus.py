"""The effective-label rule with redundancy r (pure; replayable from the label events).

Each labeler has at most one current label (vote) per query: their latest `label` event, unless an
`undo` withdrew it. An undo by a labeler who has a vote withdraws that vote; an undo by an operator
without a vote of their own withdraws every vote of the query. A query counts once r distinct
labelers have a vote; its effective label is then the majority of the votes, a tie going to the
safer label: bad (0) over neutral (1) over good (2) — the lowest value among the tied. With r = 1
this is the latest label, as before redundancy existed.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable


def consensus(values: Iterable[int]) -> int | None:
    """Majority of `values`; ties → the safer (lower) label; None for no values."""
    counts = Counter(values)
    if not counts:
        return None
    top = max(counts.values())
    return min(v for v, n in counts.items() if n == top)


def effective(votes: Iterable[int], redundancy: int) -> int | None:
    """The effective label of a query with these votes, or None until `redundancy` of them exist."""
    values = list(votes)
    return consensus(values) if len(values) >= max(1, redundancy) else None


def replay(events: Iterable[tuple[str, int, int | None, str]]) -> dict[int, int]:
    """The votes (labeler id → value) after a query's (kind, labeler id, value, labeler role)
    events in order."""
    votes: dict[int, int] = {}
    for kind, labeler, value, role in events:
        if kind == "label" and value is not None:
            votes[labeler] = value
        elif kind == "undo":
            if labeler in votes:
                del votes[labeler]
            elif role == "operator":
                votes.clear()
    return votes
