"""Label events and the effective-label rule.

Events are append-only: `label` (0 bad, 1 neutral, 2 good), `skip` (not a label: the lease is
released and the query returns to the pool) and `undo`. The effective label of a query is the value
of its latest `label` event, unless an `undo` came after it (then it has none). Who may write:
- label: the holder of the live lease; the query's last labeler again (a revision); or the last
  lease holder after the lease ran out, as long as nobody else has claimed the query since;
- undo: the labeler of the effective label (the query comes back to them under a fresh lease, to
  relabel at once, within MAX_HOLD: their last preloaded query goes back to the pool) or an
  operator (the query returns to the pool);
- every submission is idempotent by (labeler, client_request_id): a repeat returns the first answer.
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from typing import Any

from sqlalchemy import Connection, bindparam, insert, select, update

from backend.models import LabelEvent, Principal, Query, Run
from backend.services import events, leases, runs
from backend.services.auth import Caller
from backend.services.errors import Conflict, NotFound
from collie.schemas import FINISHED, EffectiveLabel, LabelAck, LabelEventRead, LabelSubmit, UndoRequest


def effective_label(history: Iterable[tuple[str, int | None]]) -> int | None:
    """The rule, on a query's (kind, value) events in order."""
    current: int | None = None
    for kind, value in history:
        if kind == "label":
            current = value
        elif kind == "undo":
            current = None
    return current


_EVENT_COLUMNS = (
    LabelEvent.id,
    LabelEvent.run_id,
    Query.query_id,
    Query.session,
    Principal.name.label("labeler"),
    LabelEvent.labeler_id,
    LabelEvent.kind,
    LabelEvent.value,
    LabelEvent.seconds,
    LabelEvent.client_request_id,
    LabelEvent.revises_event_id,
    LabelEvent.created_at,
)
# Built once: submitting a label is the service's hottest write.
_LOOKUP = (
    select(
        Query.id,
        Query.query_id,
        Query.session,
        Query.status,
        Query.label,
        Query.label_event_id,
        Query.lease_owner_id,
        Query.lease_expires_at,
        LabelEvent.labeler_id.label("labelled_by"),
        Run.status.label("run_status"),
    )
    .join(Run, Run.id == Query.run_id)
    .outerjoin(LabelEvent, LabelEvent.id == Query.label_event_id)
    .where(Query.run_id == bindparam("run"), Query.query_id == bindparam("query_id"))
)
_SEEN = (
    select(LabelEvent.id, LabelEvent.run_id, LabelEvent.kind, LabelEvent.value, Query.query_id)
    .join(Query, Query.id == LabelEvent.query_pk)
    .where(LabelEvent.labeler_id == bindparam("me"), LabelEvent.client_request_id == bindparam("request_id"))
)
_INSERT_EVENT = insert(LabelEvent).returning(LabelEvent.id)
_SET_QUERY = update(Query).where(Query.id == bindparam("pk"))  # SET from the parameters given


def _event_select() -> Any:
    return (
        select(*_EVENT_COLUMNS)
        .join(Query, Query.id == LabelEvent.query_pk)
        .join(Principal, Principal.id == LabelEvent.labeler_id)
    )


def _event_read(row: Any) -> LabelEventRead:
    return LabelEventRead.model_validate(row, from_attributes=True)


def _repeat(
    conn: Connection, run_id: int, caller: Caller, request_id: str, key: tuple[str, str, int | None]
) -> LabelAck | None:
    """The answer to a repeated client_request_id (its first event, the query as it is now), or
    None for a new request; `key` is (query_id, kind, value) of this request."""
    seen = conn.execute(_SEEN, {"me": caller.id, "request_id": request_id}).first()
    if seen is None:
        return None
    if (seen.run_id, seen.query_id, seen.kind, seen.value) != (run_id, *key):
        raise Conflict(f"client_request_id '{request_id}' was already used for another submission")
    row = conn.execute(_event_select().add_columns(Query.label, Query.status).where(LabelEvent.id == seen.id)).one()
    return LabelAck(event=_event_read(row), label=row.label, query_status=row.status, duplicate=True)


def _query(conn: Connection, run_id: int, query_id: str) -> Any:
    found = conn.execute(_LOOKUP, {"run": run_id, "query_id": query_id}).first()
    if found is None:
        runs.row(conn, run_id)
        raise NotFound(f"no query '{query_id}' in run {run_id}")
    if found.run_status in FINISHED:
        raise Conflict(f"run {run_id} is {found.run_status}")
    return found


def _record(
    conn: Connection,
    run_id: int,
    q: Any,
    caller: Caller,
    kind: str,
    value: int | None,
    seconds: float | None,
    request_id: str,
    now: float,
) -> LabelEventRead:
    event = {
        "run_id": run_id,
        "query_pk": q.id,
        "labeler_id": caller.id,
        "kind": kind,
        "value": value,
        "seconds": seconds,
        "client_request_id": request_id,
        "revises_event_id": q.label_event_id,
        "created_at": now,
    }
    event_id = conn.execute(_INSERT_EVENT, event).scalar_one()
    return LabelEventRead(
        id=event_id,
        run_id=run_id,
        query_id=q.query_id,
        session=q.session,
        labeler=caller.name,
        kind=kind,  # type: ignore[arg-type]
        value=value,  # type: ignore[arg-type]
        seconds=seconds,
        client_request_id=request_id,
        revises_event_id=q.label_event_id,
        created_at=now,  # type: ignore[arg-type]
    )


def submit(conn: Connection, run_id: int, caller: Caller, body: LabelSubmit) -> LabelAck:
    kind, value = ("skip", None) if body.value == "skip" else ("label", int(body.value))
    repeat = _repeat(conn, run_id, caller, body.client_request_id, (body.query_id, kind, value))
    if repeat is not None:
        return repeat
    q = _query(conn, run_id, body.query_id)
    now = time.time()
    live = q.status == "leased" and q.lease_expires_at > now
    if live and q.lease_owner_id != caller.id:
        raise Conflict(f"query '{body.query_id}' is leased to someone else")
    if kind == "skip":
        if not live:
            raise Conflict(f"you hold no lease on query '{body.query_id}'")
        event = _record(conn, run_id, q, caller, kind, None, body.seconds, body.client_request_id, now)
        conn.execute(_SET_QUERY, {"pk": q.id, "status": "pending", "lease_owner_id": None, "lease_expires_at": None})
        return LabelAck(event=event, label=q.label, query_status="pending", duplicate=False)
    late = q.status in ("leased", "pending") and q.lease_owner_id == caller.id  # lease ran out, nobody took it
    revision = q.status == "labelled" and q.labelled_by == caller.id
    if not (live or late or revision):
        reason = {"labelled": "was labelled by someone else", "retired": "was withdrawn by the trainer"}.get(
            q.status, "is not claimed by you"
        )
        raise Conflict(f"query '{body.query_id}' {reason}; claim a query before labelling it")
    event = _record(conn, run_id, q, caller, kind, value, body.seconds, body.client_request_id, now)
    conn.execute(
        _SET_QUERY,
        {"pk": q.id, "status": "labelled", "label": value, "label_event_id": event.id, "lease_expires_at": None},
    )
    data = {
        "query_id": body.query_id,
        "session": q.session,
        "event_id": event.id,
        "labeler": caller.name,
        "label": value,
    }
    events.append(conn, run_id, "label", data, now, labels_delta=int(q.label is None))
    return LabelAck(event=event, label=value, query_status="labelled", duplicate=False)  # type: ignore[arg-type]


def undo(conn: Connection, run_id: int, caller: Caller, body: UndoRequest, lease_s: float) -> LabelAck:
    repeat = _repeat(conn, run_id, caller, body.client_request_id, (body.query_id, "undo", None))
    if repeat is not None:
        return repeat
    q = _query(conn, run_id, body.query_id)
    if q.status != "labelled":
        raise Conflict(f"query '{body.query_id}' has no label to undo")
    own = q.labelled_by == caller.id
    if not own and caller.role != "operator":
        raise Conflict(f"query '{body.query_id}' was labelled by someone else")
    now = time.time()
    event = _record(conn, run_id, q, caller, "undo", None, None, body.client_request_id, now)
    # Your own label comes back to you under a fresh lease, to relabel at once; an operator's undo
    # returns the query to the pool.
    status, owner, expires = ("leased", caller.id, now + lease_s) if own else ("pending", None, None)
    if own:  # it counts against MAX_HOLD like a claimed one: the preloaded query goes back to the pool
        leases.make_room(conn, run_id, caller, now)
    change = {
        "status": status,
        "lease_owner_id": owner,
        "lease_expires_at": expires,
        "label": None,
        "label_event_id": None,
    }
    conn.execute(_SET_QUERY, {"pk": q.id, **change})
    data = {
        "query_id": body.query_id,
        "session": q.session,
        "event_id": event.id,
        "labeler": caller.name,
        "label": None,
    }
    events.append(conn, run_id, "withdrawn", data, now, labels_delta=-1)
    return LabelAck(event=event, label=None, query_status=status, duplicate=False)  # type: ignore[arg-type]


def list_events(conn: Connection, run_id: int, after: int, limit: int) -> list[LabelEventRead]:
    runs.row(conn, run_id)
    rows = conn.execute(
        _event_select().where(LabelEvent.run_id == run_id, LabelEvent.id > after).order_by(LabelEvent.id).limit(limit)
    )
    return [_event_read(r) for r in rows]


def effective_labels(conn: Connection, run_id: int) -> list[EffectiveLabel]:
    """Recomputed from the append-only events with `effective_label` (not from the cached column)."""
    runs.row(conn, run_id)
    by_query: dict[str, list[Any]] = {}
    for row in conn.execute(_event_select().where(LabelEvent.run_id == run_id).order_by(LabelEvent.id)):
        by_query.setdefault(row.query_id, []).append(row)
    result = []
    for rows in by_query.values():
        value = effective_label((r.kind, r.value) for r in rows)
        if value is None:
            continue
        last = next(r for r in reversed(rows) if r.kind == "label")
        result.append(
            EffectiveLabel(
                query_id=last.query_id,
                session=last.session,
                label=value,
                event_id=last.id,
                labeler=last.labeler,
                seconds=last.seconds,
                labelled_at=last.created_at,
            )
        )
    return sorted(result, key=lambda e: e.event_id)
