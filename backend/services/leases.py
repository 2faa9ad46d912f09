"""Claiming under a lease. Taking a query is one conditional UPDATE … RETURNING (the row must still
be pending), so two labelers never hold the same query, on SQLite or PostgreSQL alike. Expired
leases go back to the pool at the next claim in their run (keeping their last holder, who may
still hand in a late label while nobody else has the query). Queries a labeler skipped come to
them last. Statements are built once: this is the hottest path of the service."""

from __future__ import annotations

import json
import time
from datetime import UTC, datetime
from typing import Any

from sqlalchemy import Connection, Update, bindparam, exists, select, update
from sqlalchemy.orm import aliased

from backend.models import LabelEvent, Query, QueryData, Run
from backend.services.auth import Caller
from backend.services.errors import Conflict, NotFound
from collie.schemas import FINISHED

_RETURNED = (
    Query.id,
    Query.run_id,
    Query.query_id,
    Query.session,
    Query.epoch,
    Query.start,
    Query.score,
    Query.created_at,
)
_DATA = select(QueryData.frames, QueryData.extra).where(QueryData.query_pk == bindparam("pk"))
_RUN_OPEN = exists().where(Run.id == bindparam("run"), Run.status.not_in(tuple(FINISHED)), Run.control != "stop")
_SWEEP = (
    update(Query)
    .where(Query.run_id == bindparam("run"), Query.status == "leased", Query.lease_expires_at <= bindparam("now"))
    .values(status="pending")
)


def _held() -> Update:
    """Renew and return the caller's live lease in this run (a labeler works one query at a time)."""
    mine = aliased(Query)
    held = (
        select(mine.id)
        .where(mine.run_id == bindparam("run"), mine.status == "leased", mine.lease_owner_id == bindparam("me"))
        .limit(1)
        .scalar_subquery()
    )
    return (
        update(Query)
        .where(Query.id == held, _RUN_OPEN)
        .values(lease_expires_at=bindparam("expires"))
        .returning(*_RETURNED)
    )


def _take(avoid_skipped: bool) -> Update:
    """Lease the oldest pending query (by session, then posting order) to the caller."""
    pool = aliased(Query)
    oldest = select(pool.id).where(pool.run_id == bindparam("run"), pool.status == "pending")
    if avoid_skipped:
        skipped = exists().where(
            LabelEvent.query_pk == pool.id, LabelEvent.labeler_id == bindparam("me"), LabelEvent.kind == "skip"
        )
        oldest = oldest.where(~skipped)
    oldest_id = oldest.order_by(pool.session, pool.id).limit(1).scalar_subquery()
    return (
        update(Query)
        .where(Query.id == oldest_id, Query.status == "pending", _RUN_OPEN)
        .values(status="leased", lease_owner_id=bindparam("me"), lease_expires_at=bindparam("expires"))
        .returning(*_RETURNED)
    )


_HELD = _held()
_TAKE = (_take(avoid_skipped=True), _take(avoid_skipped=False))


def claim(conn: Connection, run_id: int, caller: Caller, lease_s: float) -> bytes | None:
    """The caller's query as ClaimRead JSON, or None when nothing is claimable right now."""
    now = time.time()
    params = {"run": run_id, "me": caller.id, "now": now, "expires": now + lease_s}
    conn.execute(_SWEEP, params)
    row = conn.execute(_HELD, params).first()
    # PostgreSQL: a concurrent claim may win our candidate (the re-checked WHERE then fails); try again.
    attempts = 1 if conn.dialect.name == "sqlite" else 4
    for take in [*_TAKE] * attempts:
        if row is not None:
            break
        row = conn.execute(take, params).first()
    if row is not None:
        data = conn.execute(_DATA, {"pk": row.id}).one()
        return claim_json(row, data, caller.name, now + lease_s)
    state = conn.execute(select(Run.status, Run.control).where(Run.id == run_id)).first()
    if state is None:
        raise NotFound(f"no run {run_id}")
    if state.status in FINISHED or state.control == "stop":
        raise Conflict(f"run {run_id} takes no more labels ({state.status}, control {state.control})")
    return None


def iso(t: float) -> str:
    return datetime.fromtimestamp(t, UTC).isoformat().replace("+00:00", "Z")


def claim_json(row: Any, data: Any, owner: str, expires: float) -> bytes:
    """ClaimRead as JSON. The stored frames are JSON already (QueryFrames): they are spliced in
    rather than parsed and re-serialised (about 1,600 floats per Ant segment)."""
    head = {
        "run_id": row.run_id,
        "query_id": row.query_id,
        "session": row.session,
        "epoch": row.epoch,
        "start": row.start,
        "score": row.score,
        "status": "leased",
        "label": None,
        "lease_owner": owner,
        "lease_expires_at": iso(expires),
        "created_at": iso(row.created_at),
        "extra": data.extra,
    }
    query = json.dumps(head)[:-1] + "," + data.frames[1:]
    return f'{{"query":{query},"lease_expires_at":"{iso(expires)}"}}'.encode()
