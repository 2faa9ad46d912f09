"""The dashboard's labeling panel and labelled states: queue health, labels per minute, per-labeler
counts and median seconds per label, and agreement with the oracle — the task rule applied exactly
(collie.teacher.segment_label, no noise band) — where the run's task can judge.

A segment's frames never change once stored, so each is decoded once per process (SegmentCache):
a refresh reads only ids, labels and label events."""

from __future__ import annotations

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

from backend.models import LabelEvent, Principal, Query, QueryData
from backend.services import runs
from collie.dashboard_schemas import (
    LABEL_RATE_WINDOW_S,
    MAX_LABELLED_POINTS,
    MAX_LABELLED_SEGMENTS,
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
    return np.round(xy, 3).tolist()


def share(hits: int, judged: int) -> float | None:
    return hits / judged if judged else None


def labeler_stats(events: Sequence[Any], oracle: dict[int, int | None]) -> list[LabelerStats]:
    by_name: dict[str, list[Any]] = {}
    for e in events:
        by_name.setdefault(e.name, []).append(e)
    result = []
    for name, mine in sorted(by_name.items()):
        labels = [e for e in mine if e.kind == "label"]
        seconds = [e.seconds for e in labels if e.seconds is not None]
        judged = [e for e in labels if oracle.get(e.query_pk) is not None]
        result.append(
            LabelerStats(
                name=name,
                labels=len(labels),
                skips=sum(e.kind == "skip" for e in mine),
                median_s=statistics.median(seconds) if seconds else None,
                agreement=share(sum(e.value == oracle[e.query_pk] for e in judged), len(judged)),
            )
        )
    return result


def view(conn: Connection, run: Any, task: Task | None, cache: SegmentCache) -> LabelingView:
    """The labeling panel and the newest labelled segments (bounded) of `run` (a runs row)."""
    labelled = conn.execute(
        select(Query.id, Query.query_id, Query.session, Query.label)
        .where(Query.run_id == run.id, Query.status == "labelled", Query.label.is_not(None))
        .order_by(Query.label_event_id.desc())
    ).all()
    events = conn.execute(
        select(
            LabelEvent.query_pk,
            LabelEvent.kind,
            LabelEvent.value,
            LabelEvent.seconds,
            LabelEvent.created_at,
            Principal.name,
        )
        .join(Principal, Principal.id == LabelEvent.labeler_id)
        .where(LabelEvent.run_id == run.id)
    ).all()
    segments = cache.get_many(conn, [q.id for q in labelled] + [e.query_pk for e in events], task)
    oracle = {pk: s.oracle for pk, s in segments.items()}
    shown = labelled[:MAX_LABELLED_SEGMENTS]
    per_segment = max(2, MAX_LABELLED_POINTS // max(1, len(shown)))
    judged = [q for q in labelled if oracle.get(q.id) is not None]
    label_times = [e.created_at for e in events if e.kind == "label"]
    recent = sum(t >= time.time() - LABEL_RATE_WINDOW_S for t in label_times)
    stats = LabelingStats(
        queue=runs.get(conn, run.id).queue,
        n_labels=run.n_labels,
        n_total=run.n_total,
        labels_per_min=recent / (LABEL_RATE_WINDOW_S / 60.0),
        last_label_at=max(label_times) if label_times else None,
        labelers=labeler_stats(events, oracle),
        agreement=share(sum(q.label == oracle[q.id] for q in judged), len(judged)),
        judged=len(judged),
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
