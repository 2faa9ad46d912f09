"""One query for an operator's review in 3D: its segment with the simulator states, who labelled
it what (each labeler's current label), the label it counts as, and the oracle's verdict (the
task rule applied exactly, as the dashboard's labeling panel judges it)."""

from __future__ import annotations

import time

from sqlalchemy import Connection, select

from backend.models import LabelVote, Principal
from backend.services import dashboard, label_stats, queries, runs
from collie.dashboard_schemas import QueryReview


def review(conn: Connection, run_id: int, query_id: str) -> QueryReview:
    row = queries.get_row(conn, run_id, query_id)  # NotFound naming the query (or the run)
    task, _ = dashboard.task_of(runs.get(conn, run_id))
    votes = conn.execute(
        select(Principal.name, LabelVote.value)
        .join(Principal, Principal.id == LabelVote.labeler_id)
        .where(LabelVote.query_pk == row.id)
        .order_by(Principal.name)
    ).all()
    return QueryReview(
        query=queries.full(row, time.time()),
        labels={v.name: v.value for v in votes},
        effective=row.label,
        oracle=label_stats.decode(row.frames, task).oracle,
        has_rule=task is not None,
    )
