"""Gold segments: segments whose answer the task rule knows, mixed into a labeler's queue at the
run's gold_rate to measure the labeler's accuracy. They never reach the trainer.

Where they come from: the run's own queries of earlier feedback sessions (session below the oldest
one with work pending), whose label the run's task rule gives (collie.teacher.segment_label on the
segment's states, as the dashboard's oracle agreement judges), and which this labeler has neither
labelled nor been served as gold. Each serving is a copy of the segment (a Query row with gold_of
= the original, gold_answer = the rule's label, a fresh opaque query id, leased to that labeler
alone), so a gold segment looks like any other to the labeler, and its labels are events on the
copy: the original's votes, effective label and stream are untouched. A run's first session has
no gold (there is nothing earlier to re-serve); a run whose task cannot judge has none at all.

Pacing is deterministic: a labeler who needs a new segment while real work is pending is served
gold when gold served < gold_rate × (gold served + real labels + 1).
"""

from __future__ import annotations

import secrets
import time

from sqlalchemy import Connection, bindparam, func, insert, select

from backend.models import LabelVote, Query, QueryData, Run
from backend.services import runs
from backend.services.auth import Caller
from backend.services.dashboard import task_of
from backend.services.label_stats import decode

CANDIDATES = 50  # earlier segments decoded at most per serving (the oldest first)


# Built once: every claim asks whether gold is due, and most runs have none (gold_rate 0).
_GOLD_RATE = select(Run.gold_rate).where(Run.id == bindparam("run"))
_MINE = (Query.run_id == bindparam("run")) & Query.gold_of.is_not(None) & (Query.lease_owner_id == bindparam("me"))
_SERVED = select(func.count()).where(_MINE)
_REAL = (
    select(func.count())
    .select_from(LabelVote)
    .join(Query, Query.id == LabelVote.query_pk)
    .where(Query.run_id == bindparam("run"), Query.gold_of.is_(None), LabelVote.labeler_id == bindparam("me"))
)
_VOTED = select(LabelVote.query_pk).where(LabelVote.labeler_id == bindparam("me"))
_CURRENT = select(func.min(Query.session)).where(
    Query.run_id == bindparam("run"), Query.status == "pending", Query.gold_of.is_(None), Query.id.not_in(_VOTED)
)


def due(conn: Connection, run_id: int, me: int, rate: float) -> bool:
    params = {"run": run_id, "me": me}
    served = conn.execute(_SERVED, params).scalar_one()
    real = conn.execute(_REAL, params).scalar_one()
    return served < rate * (served + real + 1)


def serve_if_due(conn: Connection, run_id: int, caller: Caller, expires: float, tab: str | None = None) -> int | None:
    """The primary key of a gold copy newly leased to `caller` (for their `tab`) until `expires`, or None (gold off,
    not due, no real work pending, or no earlier segment the rule can judge)."""
    rate = conn.execute(_GOLD_RATE, {"run": run_id}).scalar()
    if rate is None or rate <= 0 or not due(conn, run_id, caller.id, rate):
        return None
    current = conn.execute(_CURRENT, {"run": run_id, "me": caller.id}).scalar()
    if current is None:
        return None
    task = task_of(runs.get(conn, run_id))[0]  # the rule as stored with the run (or none)
    if task is None:
        return None
    candidates = conn.execute(
        select(Query, QueryData.frames, QueryData.extra)
        .join(QueryData, QueryData.query_pk == Query.id)
        .where(
            Query.run_id == bindparam("run"),
            Query.gold_of.is_(None),
            Query.session < current,
            Query.id.not_in(_VOTED),
            Query.id.not_in(select(Query.gold_of).where(_MINE)),
        )
        .order_by(Query.id)
        .limit(CANDIDATES),
        {"run": run_id, "me": caller.id},
    )
    for c in candidates:
        answer = decode(c.frames, task).oracle
        if answer is None:
            continue
        pk = conn.execute(
            insert(Query)
            .values(
                run_id=run_id,
                query_id=f"r{secrets.token_hex(6)}",
                session=current,
                epoch=c.epoch,
                start=c.start,
                score=c.score,
                status="leased",
                lease_owner_id=caller.id,
                lease_tab=tab,
                lease_expires_at=expires,
                created_at=time.time(),
                gold_of=c.id,
                gold_answer=answer,
            )
            .returning(Query.id)
        ).scalar_one()
        conn.execute(insert(QueryData).values(query_pk=pk, frames=c.frames, extra=c.extra))
        return pk
    return None
