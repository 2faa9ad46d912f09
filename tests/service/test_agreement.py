"""The pure rules of labeler quality control: Krippendorff's α (nominal) on published worked
examples, and the effective-label rule with redundancy (majority, ties to the safer label)."""

from __future__ import annotations

import pytest

from backend.services.agreement import alpha, coder_alpha, coincidences
from backend.services.consensus import VoteEvent, consensus, effective, replay

_ = None
# Krippendorff (2011), "Computing Krippendorff's Alpha-Reliability", section C: 4 observers,
# 12 units, nominal values 1–5 with missing data; the paper gives α = 0.743.
PAPER = {
    "A": [1, 2, 3, 3, 2, 1, 4, 1, 2, _, _, _],
    "B": [1, 2, 3, 3, 2, 2, 4, 1, 2, 5, _, 3],
    "C": [_, 3, 3, 3, 2, 3, 4, 2, 2, 5, 1, _],
    "D": [1, 2, 3, 3, 2, 4, 4, 1, 2, 5, 1, _],
}


def units(table: dict[str, list[int | None]]) -> list[dict[str, int]]:
    n = len(next(iter(table.values())))
    return [{c: row[u] for c, row in table.items() if row[u] is not None} for u in range(n)]  # type: ignore[misc]


def test_alpha_of_the_papers_worked_example() -> None:
    data = units(PAPER)
    o = coincidences(data, [1, 2, 3, 4, 5])
    assert o.sum() == pytest.approx(40)  # n: the pairable values (unit 12 has a single one)
    # by hand: o_11 = 3·2/2 (unit 1) + 3·2/3 (unit 8) + 2·1/1 (unit 11); o_33 = 2 · 4·3/3 (units 3, 4)
    assert o[0, 0] == pytest.approx(7) and o[2, 2] == pytest.approx(8)
    assert round(alpha(data), 3) == 0.743  # type: ignore[arg-type]


def test_alpha_of_two_observers_binary() -> None:
    # Krippendorff (2011), section A: two observers, 10 units, binary: α = 0.095
    a = [0, 1, 0, 0, 0, 0, 0, 0, 1, 0]
    b = [1, 1, 1, 0, 0, 1, 0, 0, 0, 0]
    assert round(alpha(units({"A": a, "B": b})), 3) == 0.095  # type: ignore[arg-type,dict-item]


def test_alpha_edges_and_per_coder_alpha() -> None:
    assert alpha([{"A": 1, "B": 1}, {"A": 1}]) is None  # no variation: undefined, not 1
    assert alpha([{"A": 1}, {"B": 2}]) is None  # nothing pairable
    assert alpha([{"A": 0, "B": 0}, {"A": 2, "B": 2}]) == 1.0
    # hand-computed: units {A:0,B:0}, {A:2,B:2}, {A:0,B:2,C:2}; o_00=2, o_22=2+1, o_02=o_20=1
    data = [{"A": 0, "B": 0}, {"A": 2, "B": 2}, {"A": 0, "B": 2, "C": 2}]
    # n = 7, n_0 = 3, n_2 = 4: α = 1 − 6 · 2 / (2 · 3 · 4) = 0.5
    assert alpha(data) == pytest.approx(0.5)
    # C's only pairs are (C, A) 0 ≠ 2 and (C, B) 2 = 2, each weighted 1/2: D_o(C) = 1/2; D_e = 24/42
    assert coder_alpha(data, "C") == pytest.approx(1 - 0.5 / (24 / 42))
    assert coder_alpha(data, "Z") is None
    paper = units(PAPER)
    assert coder_alpha(paper, "C") < min(coder_alpha(paper, c) for c in "ABD")  # type: ignore[operator]


def test_consensus_majority_and_safer_ties() -> None:
    assert consensus([2, 2, 0]) == 2
    assert consensus([2, 0]) == 0  # a tie: bad over good
    assert consensus([1, 2]) == 1  # neutral over good
    assert consensus([0, 1, 1, 0, 2]) == 0  # bad over neutral
    assert consensus([]) is None
    assert effective([2], 2) is None and effective([2, 1], 2) == 1 and effective([2], 1) == 2


def test_replay_of_votes() -> None:
    events = [
        VoteEvent("label", 1, 2, "labeler"),
        VoteEvent("label", 2, 0, "labeler"),
        VoteEvent("label", 1, 1, "labeler"),  # a revision replaces the vote
        VoteEvent("undo", 2, None, "labeler"),  # withdraws 2's own vote
    ]
    assert replay(events) == ({1: 1}, None)  # an undo withdraws the effective label
    assert replay([*events, VoteEvent("undo", 9, None, "operator")]) == ({}, None)  # every vote
    assert replay([*events, VoteEvent("undo", 9, None, "labeler")]) == ({1: 1}, None)
    assert replay([*events, VoteEvent("label", 1, 2, "labeler")]) == ({1: 2}, 2)  # counts again


def test_replay_keeps_the_redundancy_each_label_was_given_under() -> None:
    """A query that counted under r = 1 stays counted after r rises; one short of r = 2 counts
    when r falls only at its next label; events without their r use the run's."""
    counted = [VoteEvent("label", 1, 2, "labeler", 1), VoteEvent("label", 1, 0, "labeler", 2)]
    assert replay(counted[:1]) == ({1: 2}, 2) and replay(counted) == ({1: 0}, 0)  # revised, still counts
    waiting = [VoteEvent("label", 1, 2, "labeler", 2)]
    assert replay(waiting, redundancy=1) == ({1: 2}, None)
    assert replay([*waiting, VoteEvent("label", 2, 0, "labeler", 1)]) == ({1: 2, 2: 0}, 0)
    assert replay([VoteEvent("label", 1, 2, "labeler")], redundancy=2) == ({1: 2}, None)
    undone = [VoteEvent("label", 1, 1, "labeler", 3), VoteEvent("label", 2, 0, "labeler", 3)]
    assert replay([*undone, VoteEvent("undo", 2, None, "labeler")]) == ({1: 1}, None)  # a plain undo
    assert replay([*undone, VoteEvent("undo", 2, None, "labeler", 1)]) == ({1: 1}, 1)  # then r lowered to 1
