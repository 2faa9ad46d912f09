"""The effective-label rule with redundancy r (pure; replayable from the label events).

Each labeler has at most one current label (vote) per query: their latest `label` event, unless an
`undo` withdrew it. An undo by a labeler who has a vote withdraws that vote; an undo by an operator
without a vote of their own withdraws every vote of the query. A query counts once, at a label
event, r distinct labelers have a vote, r being the run's redundancy when that event was recorded;
a query that counts stays counted (a later change of r does not touch it) until an undo withdraws
its effective label. When r is lowered, the queries whose votes reach it count at once: the r is
written on their latest label or undo event (a plain undo carries none), so the replay counts
them there too. Its effective label is the majority of the votes, a tie going to the safer
label: bad (0) over neutral (1) over good (2) — the lowest value among the tied. With r = 1 this
is the latest label, as before redundancy existed.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable
from typing import NamedTuple


class VoteEvent(NamedTuple):
    """What the rule reads of a label event: kind, who, the value, their role, and the r in effect
    (a label's: None for one stored before it was recorded, then the run's r is used; an undo's:
    None, or the lowered r that made its query count after it)."""

    kind: str
    labeler: int
    value: int | None
    role: str
    redundancy: int | None = None


def consensus(values: Iterable[int]) -> int | None:
    """Majority of `values`; ties → the safer (lower) label; None for no values."""
    counts = Counter(values)
    if not counts:
        return None
    top = max(counts.values())
    return min(v for v, n in counts.items() if n == top)


def effective(votes: Iterable[int], redundancy: int, counted: bool = False) -> int | None:
    """The effective label of a query with these votes: None until `redundancy` of them exist,
    unless the query already counts (`counted`)."""
    values = list(votes)
    return consensus(values) if counted or len(values) >= max(1, redundancy) else None


def replay(events: Iterable[VoteEvent], redundancy: int = 1) -> tuple[dict[int, int], int | None]:
    """The votes (labeler id → value) and the effective label after a query's events in order;
    `redundancy`: r for events that do not carry their own."""
    votes: dict[int, int] = {}
    label: int | None = None
    for kind, labeler, value, role, r in events:
        if kind == "label" and value is not None:
            votes[labeler] = value
            label = effective(votes.values(), redundancy if r is None else r, counted=label is not None)
        elif kind == "undo":
            if labeler in votes:
                del votes[labeler]
            elif role == "operator":
                votes.clear()
            label = None  # an undo withdraws the effective label; the query counts again at r votes
            if r is not None and votes:  # a lowered r made it count after this undo
                label = effective(votes.values(), r)
    return votes, label
