"""Read-only views for the operators' dashboard: the runs list, a run's page in one read, and its
metric history thinned in SQL so that a run of 10 000 evaluations costs ~1000 decoded rows."""

from __future__ import annotations

import math

from sqlalchemy import Connection, func, or_, select

from backend.models import LabelEvent, Metrics, Rollouts, StreamEvent
from backend.services import label_stats, runs, telemetry
from backend.services.label_stats import SegmentCache
from collie.dashboard_schemas import LabelingView, MetricHistory, RunDashboard, RunSummary
from collie.schemas import RolloutsRead, RunRead
from collie.tasks import Task, task_for_run


def last_label_times(conn: Connection, run_ids: list[int]) -> dict[int, float]:
    rows = conn.execute(
        select(LabelEvent.run_id, func.max(LabelEvent.created_at))
        .where(LabelEvent.run_id.in_(run_ids), LabelEvent.kind == "label")
        .group_by(LabelEvent.run_id)
    )
    return {r[0]: r[1] for r in rows}


def latest_evaluations(conn: Connection, run_ids: list[int]) -> dict[int, int]:
    rows = conn.execute(
        select(Metrics.run_id, func.max(Metrics.epoch)).where(Metrics.run_id.in_(run_ids)).group_by(Metrics.run_id)
    )
    return {r[0]: r[1] for r in rows}


def summaries(conn: Connection, limit: int, only: frozenset[int] | None = None) -> list[RunSummary]:
    """The newest `limit` runs, without their configs (the list stays small). The epoch is the
    latest the trainer told: in a status change or an evaluation, whichever is further."""
    found = runs.list_runs(conn, None, limit, 0, only)
    ids = [r.id for r in found]
    last, evaluated = last_label_times(conn, ids), latest_evaluations(conn, ids)
    return [
        RunSummary(
            **r.model_dump(include=set(RunSummary.model_fields) - {"preset", "last_label_at", "epoch"}),
            epoch=max(r.epoch, evaluated.get(r.id, 0)),
            preset=str(r.config.get("preset")) if r.config.get("preset") is not None else None,
            last_label_at=last.get(r.id),
        )
        for r in found
    ]


def latest_event_id(conn: Connection) -> int:
    """A cheap fingerprint of "something happened on some run" (the stream table's newest row)."""
    return int(conn.execute(select(func.max(StreamEvent.id))).scalar() or 0)


def metric_history(conn: Connection, run_id: int, max_points: int) -> MetricHistory:
    """Every `stride`-th metric row by (epoch, id) and the newest: at most max_points (≥ 2) rows."""
    runs.row(conn, run_id)
    n = int(conn.execute(select(func.count()).where(Metrics.run_id == run_id)).scalar() or 0)
    stride = max(1, math.ceil((n - 1) / (max_points - 1))) if n > max_points else 1
    numbered = (
        select(Metrics.id, func.row_number().over(order_by=(Metrics.epoch, Metrics.id)).label("rn"))
        .where(Metrics.run_id == run_id)
        .subquery()
    )
    picked = select(numbered.c.id).where(or_((numbered.c.rn - 1) % stride == 0, numbered.c.rn == n))
    rows = conn.execute(
        select(Metrics.epoch, Metrics.values, Metrics.created_at)
        .where(Metrics.id.in_(picked))
        .order_by(Metrics.epoch, Metrics.id)
    ).all()
    names: dict[str, None] = {}
    for r in rows:
        names.update(dict.fromkeys(r.values))
    series = {name: [r.values.get(name) for r in rows] for name in names}
    return MetricHistory.model_construct(  # values were validated when posted: no second pass over them
        n_stored=n,
        stride=stride,
        epochs=[r.epoch for r in rows],
        created_at=[r.created_at for r in rows],
        series=series,
    )


def latest_rollouts(conn: Connection, run_id: int) -> RolloutsRead | None:
    """The newest evaluation's paths, without their simulator states (the map does not draw them)."""
    row = conn.execute(select(Rollouts).where(Rollouts.run_id == run_id).order_by(Rollouts.id.desc()).limit(1)).first()
    return None if row is None else telemetry.read_rollouts(row, states=False)


def task_of(run: RunRead) -> tuple[Task | None, str | None]:
    """The run's rule as stored with it, or why there is none (None, None: a run with only an
    instruction, which has no rule by design)."""
    try:
        return task_for_run(run), None
    except (ValueError, KeyError) as exc:
        return None, str(exc)


def run_page(conn: Connection, run_id: int, max_points: int, cache: SegmentCache, votes: bool = True) -> RunDashboard:
    """The whole run page from one read transaction (a consistent snapshot up to last_event_id);
    `votes`: with the disagreements, which name who voted what (not for a labeler: `without_votes`)."""
    row = runs.row(conn, run_id)
    run = runs.get(conn, run_id)
    task, task_error = task_of(run)
    view = label_stats.view(conn, row, task, cache)
    if not votes:
        view = without_votes(view)
    return RunDashboard(
        run=run,
        task=task.to_dict() if task is not None else None,
        task_error=task_error,
        rollouts=latest_rollouts(conn, run_id),
        metrics=metric_history(conn, run_id, max_points),
        last_event_id=run.last_event_id,
        **view.model_dump(),
    )


def labeling_view(conn: Connection, run_id: int, cache: SegmentCache, votes: bool = True) -> LabelingView:
    row = runs.row(conn, run_id)
    view = label_stats.view(conn, row, task_of(runs.get(conn, run_id))[0], cache)
    return view if votes else without_votes(view)


def without_votes(view: LabelingView) -> LabelingView:
    """A labeler's copy: no disagreements, whose labels name who voted what on queries that may still
    come to them (with redundancy r, a vote seen before one's own defeats the r independent votes)."""
    return view.model_copy(update={"labeling": view.labeling.model_copy(update={"disagreements": []})})
