"""Claiming under a lease. Taking a query is one conditional UPDATE … RETURNING (the row must still
be pending), so two labelers never hold the same query, on SQLite or PostgreSQL alike. Expired
leases go back to the pool at the next claim in their run (keeping their last holder, who may
still hand in a late label while nobody else has the query); a released query keeps no holder.
Queries a labeler skipped come to them last; a query they voted on never comes to them again
(redundancy: r distinct labelers), and gold copies (services/gold.py) are never in the pool: a due
one is served to its labeler instead. A claim renews every lease the labeler holds in the run, or
with a tab, every lease that tab holds.

A claim may name the browser tab it is for: the lease records it, and a label that names a tab
is taken only from the tab holding the lease (services/labels.py), so a stale tab never labels a
segment another tab of the same labeler shows. Each tab holds up to MAX_HOLD queries (the one on
screen and the next, preloaded) and sees only its own; a labeler's tabs hold at most
MAX_HOLD × MAX_TABS, and a tab beyond that which holds none is refused with why. A tab's claim
renews its own leases only: a closed tab's run out (after its UI's release, or lease_s) however long
the labeler's other tabs go on. A claim without a tab is the labeler's as a whole (an API client):
it sees and renews every query they hold and may hold MAX_HOLD. Statements are built once: this is
the hottest path of the service."""

from __future__ import annotations

import json
import time
from datetime import UTC, datetime
from typing import Any

from sqlalchemy import Connection, Update, bindparam, exists, func, select, update
from sqlalchemy.orm import aliased

from backend.models import LabelEvent, LabelVote, Principal, Query, QueryData, Run
from backend.services import gold, runs
from backend.services.auth import Caller
from backend.services.errors import Conflict, NotFound
from collie.schemas import FINISHED, MAX_HOLD, MAX_TABS, QueryStatus

_RETURNED = (
    Query.id,
    Query.run_id,
    Query.query_id,
    Query.session,
    Query.epoch,
    Query.start,
    Query.score,
    Query.created_at,
    Query.lease_tab,
)
_DATA = select(QueryData.frames, QueryData.extra).where(QueryData.query_pk == bindparam("pk"))
_RUN_OPEN = exists().where(Run.id == bindparam("run"), Run.status.not_in(tuple(FINISHED)), Run.control != "stop")
# A revoked caller takes and renews nothing, even where a token cache (another service process,
# for COLLIE_TOKEN_CACHE_S) or a request already past its token check still lets them in.
_CALLER_ACTIVE = exists().where(Principal.id == bindparam("me"), Principal.revoked_at.is_(None))
_SWEEP = (
    update(Query)
    .where(Query.run_id == bindparam("run"), Query.status == "leased", Query.lease_expires_at <= bindparam("now"))
    .values(status="pending")
)


_RENEW = (
    update(Query)
    .where(
        Query.run_id == bindparam("run"),
        Query.status == "leased",
        Query.lease_owner_id == bindparam("me"),
        _RUN_OPEN,
        _CALLER_ACTIVE,
    )
    .values(lease_expires_at=bindparam("expires"))
    .returning(*_RETURNED)
)
_RENEW_TAB = _RENEW.where(Query.lease_tab == bindparam("tab"))
_HELD_IN_RUN = select(func.count()).where(
    Query.run_id == bindparam("run"), Query.status == "leased", Query.lease_owner_id == bindparam("me")
)
_RELEASE = (
    update(Query)
    .where(Query.id == bindparam("pk"), Query.status == "leased", Query.lease_owner_id == bindparam("me"))
    .values(status="pending", lease_owner_id=None, lease_tab=None, lease_expires_at=bindparam("now"))
)
_HELD = (
    select(Query.id, Query.lease_tab)
    .where(
        Query.run_id == bindparam("run"),
        Query.status == "leased",
        Query.lease_owner_id == bindparam("me"),
        Query.lease_expires_at > bindparam("now"),
    )
    .order_by(Query.session.desc(), Query.id.desc())
)


def _take(avoid_skipped: bool) -> Update:
    """Lease the oldest pending query (by session, then posting order) to the caller."""
    pool = aliased(Query)
    voted = exists().where(LabelVote.query_pk == pool.id, LabelVote.labeler_id == bindparam("me"))
    oldest = select(pool.id).where(
        pool.run_id == bindparam("run"), pool.status == "pending", pool.gold_of.is_(None), ~voted
    )
    if avoid_skipped:
        skipped = exists().where(
            LabelEvent.query_pk == pool.id, LabelEvent.labeler_id == bindparam("me"), LabelEvent.kind == "skip"
        )
        oldest = oldest.where(~skipped)
    oldest_id = oldest.order_by(pool.session, pool.id).limit(1).scalar_subquery()
    return (
        update(Query)
        .where(Query.id == oldest_id, Query.status == "pending", _RUN_OPEN, _CALLER_ACTIVE)
        .values(
            status="leased",
            lease_owner_id=bindparam("me"),
            lease_tab=bindparam("tab"),
            lease_expires_at=bindparam("expires"),
        )
        .returning(*_RETURNED)
    )


_TAKE = (_take(avoid_skipped=True), _take(avoid_skipped=False))


def claim(
    conn: Connection, run_id: int, caller: Caller, lease_s: float, hold: int = 1, tab: str | None = None
) -> bytes | None:
    """ClaimRead JSON for the caller's `hold`-th query (by session, then posting order) among those
    they hold for `tab` (with no tab: among all they hold), whose leases are renewed; with fewer
    than `hold` held, the oldest pending query is taken (for `tab`) and returned. None when one is
    needed and none is claimable right now."""
    now = time.time()
    params = {"run": run_id, "me": caller.id, "now": now, "expires": now + lease_s, "tab": tab}
    conn.execute(_SWEEP, params)
    held = sorted(conn.execute(_RENEW if tab is None else _RENEW_TAB, params).all(), key=lambda r: (r.session, r.id))
    row = held[hold - 1] if len(held) >= hold else None
    in_run = len(held) if tab is None or row is not None else conn.execute(_HELD_IN_RUN, params).scalar_one()
    room = tab is None or in_run < MAX_HOLD * MAX_TABS  # no more tabs' worth than that
    # PostgreSQL: a concurrent claim may win our candidate (the re-checked WHERE then fails); try again.
    attempts = 1 if conn.dialect.name == "sqlite" else 4
    if row is None and room and (gold_pk := gold.serve_if_due(conn, run_id, caller, now + lease_s, tab)) is not None:
        row = conn.execute(select(*_RETURNED).where(Query.id == gold_pk)).one()
        held.append(row)
    for take in [*_TAKE] * attempts if room else []:
        if row is not None:
            break
        row = conn.execute(take, params).first()
        if row is not None:
            held.append(row)
    if row is not None:
        data = conn.execute(_DATA, {"pk": row.id}).one()
        return claim_json(row, data, caller.name, now + lease_s, [r.query_id for r in held])
    state = conn.execute(select(Run.status, Run.control).where(Run.id == run_id)).first()
    if state is None:
        raise NotFound(f"no run {run_id}")
    if state.status in FINISHED or state.control == "stop":
        raise Conflict(f"{runs.ended(run_id, state.status, state.control)}: it takes no more labels")
    if not room and not held:  # a tab too many: say so, where an empty answer would read as "no work"
        raise Conflict(
            f"your other tabs hold {in_run} segments of run {run_id}, as many as {MAX_TABS} tabs may; "
            "close one of them (or label there) to label in this one"
        )
    return None


def release(conn: Connection, run_id: int, caller: Caller, query_id: str) -> QueryStatus:
    """Hand a held query back to the pool (not a skip: nothing is recorded). Releasing what is no
    longer held by the caller (expired, released already) is a no-op; the query's status comes back."""
    row = conn.execute(
        select(Query.id, Query.status, Query.lease_owner_id, Query.gold_of).where(
            Query.run_id == run_id, Query.query_id == query_id
        )
    ).first()
    if row is None:
        raise NotFound(f"no query {query_id!r} in run {run_id}")
    if row.status == "leased" and row.lease_owner_id != caller.id:
        raise Conflict(f"query {query_id!r} is held by another labeler")
    if row.status == "leased" and row.gold_of is not None:  # a gold copy is its labeler's: done, as a skip
        conn.execute(update(Query).where(Query.id == row.id).values(status="retired", lease_expires_at=None))
        return "retired"
    if row.status == "leased":
        conn.execute(_RELEASE, {"pk": row.id, "me": caller.id, "now": time.time()})
        return "pending"
    return row.status


def release_all_held_by(conn: Connection, principal: Caller) -> int:
    """A revoked principal's claims, in every run, go back to the pool now rather than when their
    leases expire, each as `release` hands one back (a gold copy is retired). Returns how many went
    back to the pool."""
    held = select(Query.run_id, Query.query_id).where(Query.status == "leased", Query.lease_owner_id == principal.id)
    return sum(release(conn, r.run_id, principal, r.query_id) == "pending" for r in conn.execute(held).all())


def make_room(conn: Connection, run_id: int, caller: Caller, now: float, tab: str | None = None) -> list[str]:
    """Before a query comes back to the caller's `tab` outside a claim (an undo of their label):
    release the last ones that tab holds (with no tab: they hold) in claim order (the preloaded) so
    it holds at most MAX_HOLD with it. Returns the released query ids."""
    rows = conn.execute(_HELD, {"run": run_id, "me": caller.id, "now": now})
    held = [r.id for r in rows if tab in (None, r.lease_tab)]
    extra = held[: max(0, len(held) - (MAX_HOLD - 1))]
    released = []
    for pk in extra:
        conn.execute(_RELEASE, {"pk": pk, "me": caller.id, "now": now})
        released.append(conn.execute(select(Query.query_id).where(Query.id == pk)).scalar_one())
    return released


def iso(t: float) -> str:
    return datetime.fromtimestamp(t, UTC).isoformat().replace("+00:00", "Z")


def claim_json(row: Any, data: Any, owner: str, expires: float, held: list[str]) -> bytes:
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
    return f'{{"query":{query},"lease_expires_at":"{iso(expires)}","held":{json.dumps(held)}}}'.encode()
