"""Queries (segments): posted a feedback session at a time by the trainer, read by labelers and UIs.
A session is identified by its position in the trainer's schedule (`session`, unique per run): posting
a position already posted stores nothing and answers with the stored session's queries, so a resumed
trainer asks for nothing twice. Within a new session, query ids already stored are kept unchanged
and reported back."""

from __future__ import annotations

import time
from typing import Any

from sqlalchemy import Connection, Select, func, insert, select, update

from backend.models import FeedbackSession, Principal, Query, QueryData
from backend.services import events, runs
from backend.services.errors import Conflict, Invalid, NotFound
from collie.schemas import (
    FINISHED,
    EnvDims,
    LabelledPage,
    LabelledQuery,
    QueriesPosted,
    QueriesRetired,
    QueryFrames,
    QueryRead,
    QuerySummary,
    Retired,
    SessionPost,
    SessionPosted,
)

FRAME_FIELDS = frozenset(QueryFrames.model_fields)
SUMMARY_COLUMNS = (
    Query.id,
    Query.run_id,
    Query.query_id,
    Query.session,
    Query.epoch,
    Query.start,
    Query.score,
    Query.status,
    Query.label,
    Query.label_event_id,
    Query.lease_owner_id,
    Query.lease_expires_at,
    Query.created_at,
    Principal.name.label("lease_owner"),
)


def post_session(conn: Connection, run_id: int, body: SessionPost, max_queries: int) -> SessionPosted:
    runs.posting(conn, run_id)  # posts to one run one at a time: the budget's count stays true
    run = runs.row(conn, run_id)
    if run.status in FINISHED or run.control == "stop":  # a stopped run's queries could never be claimed
        raise Conflict(runs.ended(run_id, run.status, run.control))
    if len(body.queries) > max_queries:
        raise Invalid(f"{len(body.queries)} queries in one session, at most {max_queries}")
    dims = EnvDims.model_validate(run.dims)
    problems = [f"{q.query_id}: {e}" for q in body.queries for e in q.shape_errors(dims)]
    if problems:
        raise Invalid("segments do not match the run's env dims: " + "; ".join(problems[:5]))
    posted_before = conn.execute(
        select(FeedbackSession.epoch, FeedbackSession.query_ids).where(
            FeedbackSession.run_id == run_id, FeedbackSession.session == body.session
        )
    ).first()
    if posted_before is not None:
        stored_ids = posted_before.query_ids
        if stored_ids is None:  # posted before 0010: the queries this session created
            stored = conn.execute(
                select(Query.query_id).where(Query.run_id == run_id, Query.session == body.session).order_by(Query.id)
            ).scalars()
            stored_ids = list(stored)
        return SessionPosted(
            session=body.session,
            epoch=posted_before.epoch,
            created=[],
            existing=stored_ids,
            reused=True,
            query_ids=stored_ids,
        )
    now = time.time()
    ids = [q.query_id for q in body.queries]
    existing = set(
        conn.execute(select(Query.query_id).where(Query.run_id == run_id, Query.query_id.in_(ids))).scalars()
    )
    new = [q for q in body.queries if q.query_id not in existing]
    if run.n_total is not None:
        check_budget(conn, run_id, run.n_total, len(new))
    conn.execute(
        insert(FeedbackSession).values(
            run_id=run_id, session=body.session, epoch=body.epoch, created_at=now, query_ids=ids
        )
    )
    rows = [
        {
            "run_id": run_id,
            "query_id": q.query_id,
            "session": body.session,
            "epoch": body.epoch,
            "start": q.start,
            "score": q.score,
            "status": "pending",
            "created_at": now,
        }
        for q in new
    ]
    if rows:
        pks = conn.execute(insert(Query).returning(Query.id, sort_by_parameter_order=True), rows).scalars().all()
        data = [
            {"query_pk": pk, "frames": q.model_dump_json(include=set(FRAME_FIELDS)), "extra": q.extra}
            for pk, q in zip(pks, new, strict=True)
        ]
        conn.execute(insert(QueryData), data)
        created = [str(r["query_id"]) for r in rows]
        events.append(conn, run_id, QueriesPosted(session=body.session, epoch=body.epoch, query_ids=created), now)
    return SessionPosted(
        session=body.session,
        epoch=body.epoch,
        created=[str(r["query_id"]) for r in rows],
        existing=[i for i in ids if i in existing],
        query_ids=ids,
    )


def check_budget(conn: Connection, run_id: int, n_total: int, adding: int) -> None:
    """Refuse new queries past the run's budget. It counts as the trainer's (trainer/loop.py
    queries_asked) does: every query asked, labelled or not, retired ones too, once per id; gold
    copies are no query of the run's (services/gold.py)."""
    stored = conn.execute(
        select(func.count()).select_from(Query).where(Query.run_id == run_id, Query.gold_of.is_(None))
    ).scalar_one()
    if adding and stored + adding > n_total:
        raise Conflict(
            f"run {run_id}'s budget is {n_total} queries and {stored} are stored: "
            f"a new session of {adding} more would pass it"
        )


def retire(conn: Connection, run_id: int, query_ids: list[str]) -> Retired:
    """Close unlabelled queries: nobody can claim or label them any more. Labelled ones stay."""
    runs.row(conn, run_id)
    wanted = set(query_ids)
    # one conditional UPDATE: on PostgreSQL a label committed while it waited for the row is seen
    # (the condition is checked again on the row it waited for), so the label is not overwritten
    done = sorted(
        conn.execute(
            update(Query)
            .where(Query.run_id == run_id, Query.query_id.in_(wanted), Query.status.in_(("pending", "leased")))
            .values(status="retired", lease_owner_id=None, lease_expires_at=None)
            .returning(Query.query_id)
        ).scalars()
    )
    if done:
        events.append(conn, run_id, QueriesRetired(query_ids=done), time.time())
    return Retired(retired=done, not_retired=sorted(wanted - set(done)))


def summary_select() -> Select:  # its many columns: any row shape
    return select(*SUMMARY_COLUMNS).outerjoin(Principal, Principal.id == Query.lease_owner_id)


def full_select() -> Select[Any]:
    """Summary columns with the frames (for `full`)."""
    return (
        summary_select().add_columns(QueryData.frames, QueryData.extra).join(QueryData, QueryData.query_pk == Query.id)
    )


def summary(row: Any, now: float) -> QuerySummary:
    live = row.status == "leased" and row.lease_expires_at is not None and row.lease_expires_at > now
    status = "pending" if row.status == "leased" and not live else row.status
    return QuerySummary(
        run_id=row.run_id,
        query_id=row.query_id,
        session=row.session,
        epoch=row.epoch,
        start=row.start,
        score=row.score,
        status=status,
        label=row.label,
        lease_owner=row.lease_owner if live else None,
        lease_expires_at=row.lease_expires_at if live else None,
        created_at=row.created_at,
    )


def full(row: Any, now: float) -> QueryRead:
    """Summary plus frames; `row` must carry the summary columns, `frames` and `extra`."""
    frames = QueryFrames.model_validate_json(row.frames)
    return QueryRead(**summary(row, now).model_dump(), **frames.model_dump(), extra=row.extra)


def get_row(conn: Connection, run_id: int, query_id: str) -> Any:
    found = conn.execute(full_select().where(Query.run_id == run_id, Query.query_id == query_id)).first()
    if found is None:
        runs.row(conn, run_id)  # a missing run is the clearer 404
        raise NotFound(f"no query '{query_id}' in run {run_id}")
    return found


def get(conn: Connection, run_id: int, query_id: str) -> QueryRead:
    return full(get_row(conn, run_id, query_id), time.time())


def list_queries(
    conn: Connection, run_id: int, session: int | None, status: str | None, limit: int, offset: int
) -> list[QuerySummary]:
    runs.row(conn, run_id)
    now = time.time()
    stmt = summary_select().where(Query.run_id == run_id, Query.gold_of.is_(None))  # gold copies: services/gold.py
    if session is not None:
        stmt = stmt.where(Query.session == session)
    if status == "pending":
        stmt = stmt.where((Query.status == "pending") | ((Query.status == "leased") & (Query.lease_expires_at <= now)))
    elif status == "leased":
        stmt = stmt.where(Query.status == "leased", Query.lease_expires_at > now)
    elif status is not None:
        stmt = stmt.where(Query.status == status)
    rows = conn.execute(stmt.order_by(Query.id).limit(limit).offset(offset))
    return [summary(r, now) for r in rows]


def labelled_page(conn: Connection, run_id: int, cursor: int, limit: int) -> LabelledPage:
    """Queries with an effective label, with frames, in a stable order; pass next_cursor to go on."""
    runs.row(conn, run_id)
    now = time.time()
    rows = conn.execute(
        full_select()
        .where(Query.run_id == run_id, Query.label.is_not(None), Query.gold_of.is_(None), Query.id > cursor)
        .order_by(Query.id)
        .limit(limit)
    ).all()
    items = [LabelledQuery(query=full(r, now), label=r.label, event_id=r.label_event_id) for r in rows]
    return LabelledPage(items=items, next_cursor=rows[-1].id if len(rows) == limit else None)
