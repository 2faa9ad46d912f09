"""Label events and the effective label.

Events are append-only: `label` (0 bad, 1 neutral, 2 good), `skip` (not a label: the lease is
released and the query returns to the pool) and `undo`. Each labeler's current label of a query is
kept as a vote (models.LabelVote); the effective label follows services/consensus.py: once the
run's redundancy r of distinct labelers voted, the majority, ties to the safer label. Until then a
labelled query goes back to the pool for the next labeler (never one who voted on it: leases.py)
and nothing reaches the stream: the trainer hears a query once it counts, then only changes of its
effective label. Who may write:
- label: the holder of the live lease; a labeler with a vote on the query (a revision); or the
  last lease holder after the lease ran out, as long as nobody else has claimed the query since.
  A submission that names its tab is a first label from that tab: only the tab the lease is for
  may give it (live or late), never as a revision; otherwise a typed 409 (NotHeld) says why;
- undo: a labeler withdraws their own vote (the query comes back to them under a fresh lease, to
  relabel at once, within MAX_HOLD: their last preloaded query goes back to the pool); an operator
  without a vote withdraws every vote (the query returns to the pool);
- discard: an operator withdraws every vote of one labeler in a run (a careless or malicious
  labeler), each as an `undo` in that labeler's name, so the events replay to the same state;
- every submission is idempotent by (labeler, client_request_id): a repeat returns the first answer.
Gold copies (services/gold.py) take labels the same way with r = 1, but never touch the stream.
"""

from __future__ import annotations

import json
import secrets
import time
from typing import Any

from sqlalchemy import Connection, and_, bindparam, delete, exists, insert, select, update

from backend.models import LabelEvent, LabelVote, Principal, Query, QueryData, Run
from backend.services import consensus, events, leases, runs
from backend.services.auth import Caller
from backend.services.errors import Conflict, Invalid, NotFound, TabNotHolding
from collie.schemas import (
    FINISHED,
    EffectiveLabel,
    LabelAck,
    LabelChanged,
    LabelEventRead,
    LabelSubmit,
    LabelWithdrawn,
    MyLabel,
    NotHeldReason,
    UndoRequest,
    VotesDiscarded,
)
from collie.task_schemas import TaskDefinition
from collie.tasks import task_for_run
from collie.tasks.classes import GOOD

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
# Built once: submitting a label is the service's hottest write. The lookup also brings the
# caller's own vote on the query and whether their client_request_id was seen (one read, not three).
_REQUEST_SEEN = (
    select(LabelEvent.id)
    .where(LabelEvent.labeler_id == bindparam("me"), LabelEvent.client_request_id == bindparam("request_id"))
    .scalar_subquery()
)
# what _record, _announce and the pool updates read of a query row (a label's lookup, a discard's list)
_QUERY_STATE = (
    Query.id,
    Query.query_id,
    Query.session,
    Query.status,
    Query.label,
    Query.label_event_id,
    Query.lease_owner_id,
    Query.lease_expires_at,
    Query.lease_tab,
    Query.gold_of,
)
_LOOKUP = (
    select(
        *_QUERY_STATE,
        Run.status.label("run_status"),
        Run.control.label("run_control"),
        Run.task,
        Run.task_definition,
        Run.instruction,
        LabelVote.event_id.label("my_vote_event_id"),
        _REQUEST_SEEN.label("seen_event_id"),
    )
    .join(Run, Run.id == Query.run_id)
    .outerjoin(LabelVote, and_(LabelVote.query_pk == Query.id, LabelVote.labeler_id == bindparam("me")))
    .where(Query.run_id == bindparam("run"), Query.query_id == bindparam("query_id"))
    # PostgreSQL: the row is locked as it is read, so a label, an undo and a discard of one query
    # each decide on what the one before wrote (SQLite's writers are serialised already)
    .with_for_update(of=Query)
)
_SEEN = (
    select(LabelEvent.id, LabelEvent.run_id, LabelEvent.kind, LabelEvent.value, Query.query_id)
    .join(Query, Query.id == LabelEvent.query_pk)
    .where(LabelEvent.labeler_id == bindparam("me"), LabelEvent.client_request_id == bindparam("request_id"))
)
_INSERT_EVENT = insert(LabelEvent).returning(LabelEvent.id, LabelEvent.redundancy)
# a label given under the run's r as it is now: read in the INSERT, after the lookup locked the
# query (on PostgreSQL a lookup that waited for the lock, see hold_unlabelled, still joins the
# run row from before the wait, when an operator may have changed r), at no extra statement
_INSERT_RUN_LABEL = _INSERT_EVENT.values(
    redundancy=select(Run.redundancy).where(Run.id == bindparam("r_run")).scalar_subquery()
)
_MY_VOTE = select(LabelVote.event_id, LabelVote.value).where(
    LabelVote.query_pk == bindparam("pk"), LabelVote.labeler_id == bindparam("me")
)
_VOTES = select(LabelVote.value, LabelVote.event_id).where(LabelVote.query_pk == bindparam("pk"))
_DROP_MY_VOTE = delete(LabelVote).where(LabelVote.query_pk == bindparam("pk"), LabelVote.labeler_id == bindparam("me"))
_DROP_VOTES = delete(LabelVote).where(LabelVote.query_pk == bindparam("pk"))
_INSERT_VOTE = insert(LabelVote)
_REVISE_VOTE = (
    update(LabelVote)
    .where(LabelVote.query_pk == bindparam("pk"), LabelVote.labeler_id == bindparam("me"))
    .values(value=bindparam("value"), event_id=bindparam("event_id"))
)
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
    revises: int | None,
) -> tuple[LabelEventRead, int | None]:
    """The label event, and the r a label is given under (None for a skip or an undo): the run's
    now, 1 for a gold copy."""
    event = {
        "run_id": run_id,
        "query_pk": q.id,
        "labeler_id": caller.id,
        "kind": kind,
        "value": value,
        "seconds": seconds,
        "client_request_id": request_id,
        "revises_event_id": revises,
        "created_at": now,
    }
    if kind == "label" and q.gold_of is None:
        event_id, redundancy = conn.execute(_INSERT_RUN_LABEL, {**event, "r_run": run_id}).one()
    else:  # a skip or an undo (no r), or a gold copy's label (r = 1)
        r = 1 if kind == "label" else None
        event_id, redundancy = conn.execute(_INSERT_EVENT, {**event, "redundancy": r}).one()
    read = LabelEventRead(
        id=event_id,
        run_id=run_id,
        query_id=q.query_id,
        session=q.session,
        labeler=caller.name,
        kind=kind,
        value=value,
        seconds=seconds,
        client_request_id=request_id,
        revises_event_id=revises,
        created_at=now,
    )
    return read, redundancy


def _announce(
    conn: Connection, run_id: int, q: Any, caller: Caller, kind: str, event_id: int, label: int | None, now: float
) -> None:
    """Tell the stream (the trainer) that the query's effective label changed; gold stays off it."""
    if q.gold_of is not None:
        return
    kind_of = LabelChanged if kind == "label" else LabelWithdrawn
    data = kind_of(query_id=q.query_id, session=q.session, event_id=event_id, labeler=caller.name, label=label)
    delta = int(label is not None) - int(q.label is not None)
    events.append(conn, run_id, data, now, labels_delta=delta)


def _not_held(conn: Connection, q: Any, caller: Caller, tab: str, live: bool) -> TabNotHolding:
    """Why `tab` of `caller` may not label `q` (it does not hold the lease)."""
    reason: NotHeldReason
    if live and q.lease_owner_id != caller.id:
        reason, detail = "other_labeler", "is leased to someone else"
    elif q.lease_owner_id == caller.id and q.status in ("leased", "pending") and q.lease_tab != tab:
        reason, detail = "other_tab", "is held by another tab of yours"
    elif q.my_vote_event_id is not None:
        reason, detail = "labelled_by_you", "was labelled by you already (in another tab or client)"
    elif q.status == "labelled":
        reason, detail = "labelled", "was labelled by someone else"
    elif q.status == "retired":
        reason, detail = "retired", "was withdrawn by the trainer"
    else:
        reason, detail = "not_claimed", "is not claimed by this tab (released, or its claim ran out)"
    return TabNotHolding(q.query_id, reason, f"query '{q.query_id}' {detail}")


def _lookup_or_repeat(
    conn: Connection, run_id: int, caller: Caller, query_id: str, request_id: str, key: tuple[str, str, int | None]
) -> Any:
    """The query row (with the caller's vote), or the LabelAck of a repeated request: one read for a
    new request; the repeat is looked at as before when the request id was seen or the query not found."""
    found = conn.execute(_LOOKUP, {"run": run_id, "query_id": query_id, "me": caller.id, "request_id": request_id})
    q = found.first()
    if q is None or q.seen_event_id is not None:
        repeat = _repeat(conn, run_id, caller, request_id, key)
        if repeat is not None:
            return repeat
    if q is None:
        runs.row(conn, run_id)
        raise NotFound(f"no query '{query_id}' in run {run_id}")
    if q.run_status in FINISHED:
        raise Conflict(runs.ended(run_id, q.run_status, q.run_control))
    return q


def _takes_good(conn: Connection, run_id: int, q: Any) -> bool:
    """Whether the run's rule calls any state good; a run without a rule (an instruction) takes
    every class. A run stored before rules travelled is judged by its built-in task's name, as the
    labeling UI judges it (collie.tasks.task_for_run); one of no known task takes every class."""
    if q.task_definition is not None:
        return TaskDefinition.model_validate(q.task_definition).can_be_good
    if q.instruction is not None:
        return True
    try:
        task = task_for_run(runs.get(conn, run_id))
    except ValueError:
        return True
    return task is None or task.can_be_good


def _check_good(conn: Connection, run_id: int, q: Any) -> None:
    """A good label on a run whose rule never calls a state good is refused (as the labeling UI
    refuses the key)."""
    if not _takes_good(conn, run_id, q):
        raise Invalid(
            f"run {run_id}'s task '{q.task}' never calls a state good: label the segment 0 (bad) or 1 (neutral)"
        )


def submit(conn: Connection, run_id: int, caller: Caller, body: LabelSubmit) -> LabelAck:
    kind, value = ("skip", None) if body.value == "skip" else ("label", int(body.value))
    q = _lookup_or_repeat(conn, run_id, caller, body.query_id, body.client_request_id, (body.query_id, kind, value))
    if isinstance(q, LabelAck):
        return q
    if value == GOOD:
        _check_good(conn, run_id, q)
    now = time.time()
    live = q.status == "leased" and q.lease_expires_at > now
    holder = live and q.lease_owner_id == caller.id
    if body.tab is not None and q.lease_tab != body.tab and q.lease_owner_id == caller.id:
        holder = False  # the lease is another tab's (or a tab-less claim's) of this labeler
    if body.tab is not None and not holder:
        late = not live and q.status in ("leased", "pending") and q.lease_owner_id == caller.id
        if kind == "skip" or not (late and q.lease_tab == body.tab):
            raise _not_held(conn, q, caller, body.tab, live)
    if kind == "skip":
        if not holder:
            raise Conflict(
                f"query '{body.query_id}' is leased to someone else"
                if live
                else f"you hold no lease on query '{body.query_id}'"
            )
        event, _ = _record(conn, run_id, q, caller, kind, None, body.seconds, body.client_request_id, now, None)
        if q.gold_of is not None:  # a skipped gold copy is not served again (it stays its labeler's)
            conn.execute(_SET_QUERY, {"pk": q.id, "status": "retired", "lease_expires_at": None})
            return LabelAck(event=event, label=None, query_status="retired", duplicate=False)
        conn.execute(_SET_QUERY, {"pk": q.id, "status": "pending", "lease_owner_id": None, "lease_expires_at": None})
        return LabelAck(event=event, label=q.label, query_status="pending", duplicate=False)
    mine = q.my_vote_event_id  # the caller's current vote (its event), from the lookup
    late = not live and q.status in ("leased", "pending") and q.lease_owner_id == caller.id  # nobody took it since
    late = late and body.tab in (None, q.lease_tab)
    revision = mine is not None and q.status != "retired" and body.tab is None  # a tab's label is never one
    if not (holder or late or revision):
        if live:
            raise Conflict(f"query '{body.query_id}' is leased to someone else")
        reason = {"labelled": "was labelled by someone else", "retired": "was withdrawn by the trainer"}.get(
            q.status, "is not claimed by you"
        )
        raise Conflict(f"query '{body.query_id}' {reason}; claim a query before labelling it")
    revises = mine
    event, r = _record(conn, run_id, q, caller, kind, value, body.seconds, body.client_request_id, now, revises)
    if mine is None:
        conn.execute(_INSERT_VOTE, {"query_pk": q.id, "labeler_id": caller.id, "value": value, "event_id": event.id})
    else:  # a revision replaces the caller's vote in place
        conn.execute(_REVISE_VOTE, {"pk": q.id, "me": caller.id, "value": value, "event_id": event.id})
    votes = conn.execute(_VOTES, {"pk": q.id}).scalars().all()
    label = consensus.effective(votes, int(r or 1), counted=q.status == "labelled")  # a label's r is never None
    if label is not None:
        change = {"status": "labelled", "label": label, "label_event_id": event.id, "lease_expires_at": None}
        status = "labelled"
        if label != q.label:  # the stream carries changes of the effective label only
            _announce(conn, run_id, q, caller, "label", event.id, label, now)
    elif holder or late:  # more labels needed: back to the pool, for labelers who have not voted
        change = {"status": "pending", "lease_owner_id": None, "lease_expires_at": None}
        status = "pending"
    else:  # a revision while another labeler holds the query: their lease stands
        change, status = {}, q.status
    if change:
        conn.execute(_SET_QUERY, {"pk": q.id, **change})
    return LabelAck(event=event, label=label, query_status=status, duplicate=False)


def undo(conn: Connection, run_id: int, caller: Caller, body: UndoRequest, lease_s: float) -> LabelAck:
    q = _lookup_or_repeat(conn, run_id, caller, body.query_id, body.client_request_id, (body.query_id, "undo", None))
    if isinstance(q, LabelAck):
        return q
    now = time.time()
    mine = conn.execute(_MY_VOTE, {"pk": q.id, "me": caller.id}).first()
    votes = conn.execute(_VOTES, {"pk": q.id}).all()
    if q.status == "retired" or not votes:
        raise Conflict(f"query '{body.query_id}' has no label to undo")
    live_other = q.status == "leased" and q.lease_expires_at > now and q.lease_owner_id != caller.id
    owner: int | None
    expires: float | None
    tab: str | None
    if mine is not None:
        if live_other:
            raise Conflict(
                f"query '{body.query_id}' is held by another labeler now; label it again instead (a revision)"
            )
        revises = mine.event_id
        conn.execute(_DROP_MY_VOTE, {"pk": q.id, "me": caller.id})
        # your own label comes back to you under a fresh lease, to relabel at once; it counts against
        # MAX_HOLD like a claimed one: the preloaded query goes back to the pool
        status, owner, expires, tab = "leased", caller.id, now + lease_s, body.tab  # to the tab that undid it
        leases.make_room(conn, run_id, caller, now, body.tab)
    elif caller.role == "operator":
        revises = q.label_event_id if q.label_event_id is not None else max(v.event_id for v in votes)
        conn.execute(_DROP_VOTES, {"pk": q.id})
        if q.gold_of is not None:  # a gold copy is its labeler's alone: done, as a skipped or released one
            status, owner, expires, tab = "retired", q.lease_owner_id, None, q.lease_tab
        else:  # the query returns to the pool (a lease another labeler holds now stands)
            status = "leased" if live_other else "pending"
            owner = q.lease_owner_id if live_other else None
            expires = q.lease_expires_at if live_other else None
            tab = q.lease_tab if live_other else None
    else:
        raise Conflict(f"query '{body.query_id}' was labelled by someone else")
    event, _ = _record(conn, run_id, q, caller, "undo", None, None, body.client_request_id, now, revises)
    change = {
        "status": status,
        "lease_owner_id": owner,
        "lease_expires_at": expires,
        "lease_tab": tab,
        "label": None,
        "label_event_id": None,
    }
    conn.execute(_SET_QUERY, {"pk": q.id, **change})
    if q.label is not None:
        _announce(conn, run_id, q, caller, "withdrawn", event.id, None, now)
    return LabelAck(event=event, label=None, query_status=status, duplicate=False)


_VOTED_BY = (
    select(*_QUERY_STATE, LabelVote.event_id.label("vote_event_id"))
    .join(LabelVote, LabelVote.query_pk == Query.id)
    .where(Query.run_id == bindparam("run"), LabelVote.labeler_id == bindparam("who"), Query.gold_of.is_(None))
    .order_by(Query.id)
    .with_for_update(of=Query)  # as _LOOKUP: two discards, or a discard and a label, never decide on one state
)


def discard_votes(conn: Connection, run_id: int, labeler_id: int, operator: Caller) -> VotesDiscarded:
    """Withdraw every vote of one labeler in a run (gold copies aside: they measure the labeler and
    never reach the trainer). Each is an `undo` event in the labeler's name (consensus.replay: the
    vote goes, the effective label with it); the query goes back to the pool to gather its r votes
    again (a lease someone holds on it now stands; a retired query stays retired), and the stream
    tells the trainer of every effective label withdrawn. Each event's client_request_id names the
    operator who discarded (`discard-by-<principal id>-…`), for the audit."""
    run = runs.row(conn, run_id)
    if run.status in FINISHED:
        raise Conflict(f"{runs.ended(run_id, run.status, run.control)}: its labels stay as they are")
    who = conn.execute(select(Principal.id, Principal.name, Principal.role).where(Principal.id == labeler_id)).first()
    if who is None:
        raise NotFound(f"no principal {labeler_id}")
    caller, now = Caller(who.id, who.name, who.role), time.time()
    queries, withdrawn = [], []
    for q in conn.execute(_VOTED_BY, {"run": run_id, "who": labeler_id}).all():
        conn.execute(_DROP_MY_VOTE, {"pk": q.id, "me": labeler_id})
        request_id = f"discard-by-{operator.id}-{secrets.token_hex(8)}"
        event, _ = _record(conn, run_id, q, caller, "undo", None, None, request_id, now, q.vote_event_id)
        held = q.status == "leased" and q.lease_expires_at is not None and q.lease_expires_at > now
        change: dict[str, Any] = {"label": None, "label_event_id": None}
        if q.status == "labelled" or (q.status == "leased" and not held):
            change |= {"status": "pending", "lease_owner_id": None, "lease_expires_at": None, "lease_tab": None}
        conn.execute(_SET_QUERY, {"pk": q.id, **change})
        if q.label is not None:
            _announce(conn, run_id, q, caller, "withdrawn", event.id, None, now)
            withdrawn.append(q.query_id)
        queries.append(q.query_id)
    return VotesDiscarded(run_id=run_id, labeler=who.name, queries=queries, withdrawn=withdrawn)


def hold_unlabelled(conn: Connection, run_id: int) -> None:
    """Before the run's redundancy changes (PostgreSQL; SQLite serialises its writers already):
    lock its unlabelled queries, in id order, so a label in flight commits first (count_reached
    then sees its vote) and one that comes after waits for the new r."""
    unlabelled = Query.run_id == run_id, Query.status.in_(("pending", "leased"))
    conn.execute(select(Query.id).where(*unlabelled).order_by(Query.id).with_for_update()).all()


def count_reached(conn: Connection, run_id: int, now: float) -> list[str]:
    """After the run's redundancy was lowered: the uncounted queries whose votes reach it count now
    (their labelers cannot vote on them again, so no later label would). The new r is written on
    each one's latest label or undo event, so the recomputed labels count it there too. Returns
    their ids."""
    r = runs.row(conn, run_id).redundancy
    waiting = conn.execute(
        select(Query.id, Query.query_id, Query.session)
        .where(Query.run_id == run_id, Query.status.in_(("pending", "leased")), Query.gold_of.is_(None))
        .where(exists().where(LabelVote.query_pk == Query.id))
    ).all()
    counted = []
    for q in waiting:
        votes = conn.execute(_VOTES, {"pk": q.id}).all()
        label = consensus.effective([v.value for v in votes], r)
        if label is None:
            continue
        latest = (
            select(LabelEvent.id)
            .where(LabelEvent.query_pk == q.id, LabelEvent.kind.in_(("label", "undo")))
            .order_by(LabelEvent.id.desc())
            .limit(1)
            .scalar_subquery()
        )
        conn.execute(update(LabelEvent).where(LabelEvent.id == latest).values(redundancy=r))
        last_vote = max(v.event_id for v in votes)
        voter = conn.execute(
            select(Principal.name)
            .join(LabelEvent, LabelEvent.labeler_id == Principal.id)
            .where(LabelEvent.id == last_vote)
        ).scalar_one()
        change = {"status": "labelled", "label": label, "label_event_id": last_vote, "lease_expires_at": None}
        conn.execute(_SET_QUERY, {"pk": q.id, **change})
        data = LabelChanged(query_id=q.query_id, session=q.session, event_id=last_vote, labeler=voter, label=label)
        events.append(conn, run_id, data, now, labels_delta=1)
        counted.append(q.query_id)
    return counted


def list_events(
    conn: Connection, run_id: int, after: int, limit: int, labeler_id: int | None = None
) -> list[LabelEventRead]:
    """The run's label events in order (those of gold copies excepted: they are no query's labels);
    with `labeler_id`, that labeler's only."""
    runs.row(conn, run_id)
    query = _event_select().where(LabelEvent.run_id == run_id, LabelEvent.id > after, Query.gold_of.is_(None))
    if labeler_id is not None:
        query = query.where(LabelEvent.labeler_id == labeler_id)
    rows = conn.execute(query.order_by(LabelEvent.id).limit(limit))
    return [_event_read(r) for r in rows]


def effective_labels(conn: Connection, run_id: int) -> list[EffectiveLabel]:
    """Recomputed from the append-only events with services/consensus.py (not from the cached
    columns); the event given is the latest label of a labeler whose vote stands."""
    run = runs.row(conn, run_id)
    by_query: dict[str, list[Any]] = {}
    rows = conn.execute(
        _event_select()
        .add_columns(Principal.role, LabelEvent.redundancy)
        .where(LabelEvent.run_id == run_id, Query.gold_of.is_(None))
        .order_by(LabelEvent.id)
    )
    for row in rows:
        by_query.setdefault(row.query_id, []).append(row)
    result = []
    for history in by_query.values():
        events = (consensus.VoteEvent(r.kind, r.labeler_id, r.value, r.role, r.redundancy) for r in history)
        votes, value = consensus.replay(events, run.redundancy)
        if value is None:
            continue
        last = next(r for r in reversed(history) if r.kind == "label" and r.labeler_id in votes)
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


MINE_LIMIT = 200  # the newest queries listed in a labeler's "my labels"


def my_labels(conn: Connection, run_id: int, caller: Caller, limit: int = MINE_LIMIT) -> list[MyLabel]:
    """The queries `caller` labelled in the run, newest label first: their latest label of each,
    how often they revised it, whether it still stands as their vote, and the segment's x-y."""
    runs.row(conn, run_id)
    rows = conn.execute(
        select(LabelEvent.id, LabelEvent.kind, LabelEvent.value, LabelEvent.created_at, LabelEvent.query_pk,
               Query.query_id, Query.session, LabelVote.event_id.label("vote_event_id"))
        .join(Query, Query.id == LabelEvent.query_pk)
        .outerjoin(LabelVote, and_(LabelVote.query_pk == Query.id, LabelVote.labeler_id == caller.id))
        .where(LabelEvent.run_id == run_id, LabelEvent.labeler_id == caller.id, LabelEvent.kind == "label")
        .order_by(LabelEvent.id)
    ).all()  # fmt: skip
    latest: dict[int, Any] = {}
    count: dict[int, int] = {}
    for r in rows:
        latest[r.query_pk] = r
        count[r.query_pk] = count.get(r.query_pk, 0) + 1
    newest = sorted(latest.values(), key=lambda r: r.id, reverse=True)[:limit]
    frames = dict(
        conn.execute(
            select(QueryData.query_pk, QueryData.frames).where(QueryData.query_pk.in_([r.query_pk for r in newest]))
        ).all()
    )
    return [
        MyLabel(
            run_id=run_id,
            query_id=r.query_id,
            session=r.session,
            label=r.value,
            event_id=r.id,
            labelled_at=r.created_at,
            revisions=count[r.query_pk] - 1,
            in_effect=r.vote_event_id == r.id,  # their vote stands (not undone)
            xy=json.loads(frames[r.query_pk]).get("xy", []) if r.query_pk in frames else [],
        )
        for r in newest
    ]
