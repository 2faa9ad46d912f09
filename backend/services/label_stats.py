"""The dashboard's labeling panel and labelled states: queue health, labels per minute, per-labeler
counts (current labels: revisions replace, undos withdraw) and median seconds per label, agreement
with the oracle — the task rule applied exactly (collie.teacher.segment_label, no noise band) —
where the run's task can judge, inter-labeler agreement (Krippendorff's α, services/agreement.py)
on queries with two labels or more, gold accuracy, and the queries where labelers or the oracle
disagree.

A segment's frames never change once stored, so each is decoded once per process (SegmentCache):
a refresh reads only ids, labels and label events."""

from __future__ import annotations

import itertools
import json
import statistics
import threading
import time
from collections import OrderedDict
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from sqlalchemy import Connection, select

from backend.models import LabelEvent, LabelVote, Principal, Query, QueryData
from backend.services import agreement, runs
from collie.dashboard_schemas import (
    LABEL_RATE_WINDOW_S,
    MAX_DISAGREEMENTS,
    MAX_LABELLED_POINTS,
    MAX_LABELLED_SEGMENTS,
    Disagreement,
    LabelerStats,
    LabelingStats,
    LabelingView,
    LabelledSegment,
)
from collie.tasks import Task
from collie.teacher import segment_label


@dataclass(frozen=True)
class SegmentInfo:
    xy: np.ndarray  # (H, 2)
    oracle: int | None  # the task rule's label; None where it cannot judge


class SegmentCache:
    """Decoded segments by query primary key (one cache per app, i.e. per database), LRU-bounded."""

    def __init__(self, max_items: int = 50_000) -> None:
        self.max_items = max_items
        self._items: OrderedDict[int, SegmentInfo] = OrderedDict()
        self._lock = threading.Lock()

    def get_many(self, conn: Connection, pks: Iterable[int], task: Task | None) -> dict[int, SegmentInfo]:
        wanted = set(pks)
        with self._lock:
            found = {pk: self._items[pk] for pk in wanted if pk in self._items}
        missing = sorted(wanted - found.keys())
        for start in range(0, len(missing), 500):
            chunk = missing[start : start + 500]
            rows = conn.execute(select(QueryData.query_pk, QueryData.frames).where(QueryData.query_pk.in_(chunk)))
            for pk, frames in rows:
                found[pk] = decode(frames, task)
        with self._lock:
            for pk in missing:
                if pk in found:
                    self._items[pk] = found[pk]
            for pk in wanted & self._items.keys():
                self._items.move_to_end(pk)
            while len(self._items) > self.max_items:
                self._items.popitem(last=False)
        return found


def decode(frames: str, task: Task | None) -> SegmentInfo:
    data = json.loads(frames)
    xy = np.asarray(data["xy"], dtype=np.float64).reshape(-1, 2)
    pitch = data.get("pitch")
    pitch_arr = None if pitch is None else np.array([np.nan if p is None else p for p in pitch], np.float64)
    oracle = None
    if task is not None and len(xy):
        try:
            oracle = segment_label(task.classify(xy, pitch_arr))
        except (ValueError, NotImplementedError):  # e.g. a pitch rule on a segment without pitch
            oracle = None
    return SegmentInfo(xy, oracle)


def thinned(xy: np.ndarray, at_most: int) -> list[list[float]]:
    if len(xy) > at_most:
        xy = xy[np.linspace(0, len(xy) - 1, at_most).round().astype(int)]
    # Rounding scales by 1000 first: past ~1e305 that overflows to inf (JSON null); a value past 1e15
    # has no thousandths to round in any case.
    return np.where(np.abs(xy) < 1e15, np.round(np.clip(xy, -1e15, 1e15), 3), xy).tolist()


def share(hits: int, judged: int) -> float | None:
    return hits / judged if judged else None


@dataclass(frozen=True)
class Vote:
    """A labeler's current label of a query (models.LabelVote), with what the panel needs of both."""

    query_pk: int
    query_id: str
    session: int
    name: str
    value: int
    seconds: float | None
    effective: int | None  # the query's effective label (None until it counts)
    gold_answer: int | None  # a gold copy's answer (None for the run's own queries)


def labeler_stats(events: Sequence[Any], votes: list[Vote], oracle: dict[int, int | None]) -> list[LabelerStats]:
    """Per labeler: their current labels (revisions replace, undos withdraw), skips, pace, agreement
    with the oracle, their α against the other labelers, and their gold accuracy."""
    real = [v for v in votes if v.gold_answer is None]
    units = units_of(real)
    ids = {e.name: e.labeler_id for e in events}  # every vote has its label event
    names = sorted(ids)
    result = []
    for name in names:
        mine = [v for v in real if v.name == name]
        gold = [v for v in votes if v.name == name and v.gold_answer is not None]
        seconds = [v.seconds for v in mine if v.seconds is not None]
        judged = [v for v in mine if oracle.get(v.query_pk) is not None]
        result.append(
            LabelerStats(
                id=ids[name],
                name=name,
                labels=len(mine),
                skips=sum(e.kind == "skip" and e.name == name and not e.gold for e in events),
                median_s=statistics.median(seconds) if seconds else None,
                agreement=share(sum(v.value == oracle[v.query_pk] for v in judged), len(judged)),
                alpha=agreement.coder_alpha(list(units.values()), name),
                shared=sum(1 for u in units.values() if name in u and len(u) >= 2),
                gold_answered=len(gold),
                gold_accuracy=share(sum(v.value == v.gold_answer for v in gold), len(gold)),
            )
        )
    return result


def units_of(votes: list[Vote]) -> dict[int, dict[str, int]]:
    """Reliability data for Krippendorff's α: query → labeler → label."""
    units: dict[int, dict[str, int]] = {}
    for v in votes:
        units.setdefault(v.query_pk, {})[v.name] = v.value
    return units


def disagreements(votes: list[Vote], oracle: dict[int, int | None], segments: dict[int, SegmentInfo]) -> list[Any]:
    """The run's queries whose labelers disagree among themselves, or whose effective label (a lone
    label while it does not count yet) the oracle disagrees with; newest first."""
    by_query: dict[int, list[Vote]] = {}
    for v in votes:
        if v.gold_answer is None:
            by_query.setdefault(v.query_pk, []).append(v)
    found = []
    for pk in sorted(by_query, reverse=True):
        mine = by_query[pk]
        values = {v.value for v in mine}
        verdict = mine[0].effective if mine[0].effective is not None else (mine[0].value if len(mine) == 1 else None)
        rule = oracle.get(pk)
        if len(values) < 2 and (rule is None or verdict is None or verdict == rule):
            continue
        found.append(
            Disagreement(
                query_id=mine[0].query_id,
                session=mine[0].session,
                labels={v.name: v.value for v in mine},
                effective=mine[0].effective,
                oracle=rule,
                xy=thinned(segments[pk].xy, MAX_LABELLED_POINTS // MAX_DISAGREEMENTS) if pk in segments else [],
            )
        )
    return found


_VOTES = (
    select(
        LabelVote.query_pk,
        LabelVote.value,
        Query.query_id,
        Query.session,
        Query.label.label("effective"),
        Query.gold_answer,
        Principal.name,
        LabelEvent.seconds,
    )
    .join(Query, Query.id == LabelVote.query_pk)
    .join(Principal, Principal.id == LabelVote.labeler_id)
    .join(LabelEvent, LabelEvent.id == LabelVote.event_id)
)


def between_labelers(votes: list[Vote]) -> tuple[float | None, int]:
    """Agreement between labelers, which needs no rule: over the queries that two or more distinct
    labelers hold a label on now (each one's current vote; gold copies left out), the share of
    labeler pairs that gave the same label; and how many such queries there are."""
    per_query: dict[int, list[int]] = {}
    for v in votes:
        if v.gold_answer is None:
            per_query.setdefault(v.query_pk, []).append(v.value)
    same = pairs = 0
    shared = [values for values in per_query.values() if len(values) >= 2]
    for values in shared:
        for a, b in itertools.combinations(values, 2):
            same, pairs = same + (a == b), pairs + 1
    return share(same, pairs), len(shared)


def view(conn: Connection, run: Any, task: Task | None, cache: SegmentCache) -> LabelingView:
    """The labeling panel and the newest labelled segments (bounded) of `run` (a runs row)."""
    labelled = conn.execute(
        select(Query.id, Query.query_id, Query.session, Query.label)
        .where(Query.run_id == run.id, Query.status == "labelled", Query.label.is_not(None), Query.gold_of.is_(None))
        .order_by(Query.label_event_id.desc())
    ).all()
    events = conn.execute(
        select(
            LabelEvent.query_pk,
            LabelEvent.kind,
            LabelEvent.created_at,
            Principal.name,
            Principal.id.label("labeler_id"),
            Query.gold_of.is_not(None).label("gold"),
        )
        .join(Principal, Principal.id == LabelEvent.labeler_id)
        .join(Query, Query.id == LabelEvent.query_pk)
        .where(LabelEvent.run_id == run.id)
        .order_by(LabelEvent.id)
    ).all()
    votes = [Vote(**r._mapping) for r in conn.execute(_VOTES.where(Query.run_id == run.id))]
    real_pks = {v.query_pk for v in votes if v.gold_answer is None}
    segments = cache.get_many(conn, [q.id for q in labelled] + sorted(real_pks), task)
    oracle = {pk: s.oracle for pk, s in segments.items()}
    shown = labelled[:MAX_LABELLED_SEGMENTS]
    per_segment = max(2, MAX_LABELLED_POINTS // max(1, len(shown)))
    judged = [q for q in labelled if oracle.get(q.id) is not None]
    label_times = [e.created_at for e in events if e.kind == "label" and not e.gold]
    recent = sum(t >= time.time() - LABEL_RATE_WINDOW_S for t in label_times)
    units = list(units_of([v for v in votes if v.gold_answer is None]).values())
    disagreeing = disagreements(votes, oracle, segments)
    pairwise, shared = between_labelers(votes)
    stats = LabelingStats(
        queue=runs.get(conn, run.id).queue,
        n_labels=run.n_labels,
        n_total=run.n_total,
        labels_per_min=recent / (LABEL_RATE_WINDOW_S / 60.0),
        last_label_at=max(label_times) if label_times else None,
        labelers=labeler_stats(events, votes, oracle),
        agreement=share(sum(q.label == oracle[q.id] for q in judged), len(judged)),
        judged=len(judged),
        redundancy=run.redundancy,
        gold_rate=run.gold_rate,
        alpha=agreement.alpha(units),
        alpha_queries=sum(len(u) >= 2 for u in units),
        n_disagreements=len(disagreeing),
        disagreements=disagreeing[:MAX_DISAGREEMENTS],
        between_labelers=pairwise,
        shared_queries=shared,
    )
    return LabelingView(
        labeling=stats,
        n_labelled=len(labelled),
        labelled=[
            LabelledSegment(
                query_id=q.query_id,
                session=q.session,
                label=q.label,
                oracle=oracle.get(q.id),
                xy=thinned(segments[q.id].xy, per_segment) if q.id in segments else [],
            )
            for q in shown
        ],
    )
