"""Queries: a session posted by the trainer; claimed under a lease by labelers; read by UIs."""

from __future__ import annotations

from typing import Annotated

import anyio
from fastapi import APIRouter, Query, Request, Response

from backend.db import Database
from backend.limits import declared_length
from backend.routes.deps import (
    DB,
    OFF_LOOP_BYTES,
    AnyCaller,
    LabelerCaller,
    LeaseS,
    RunId,
    SettingsDep,
    TrainerCaller,
    json_body,
    parse_body,
)
from backend.routes.responses import CLAIMING
from backend.services import leases, queries
from collie.schemas import (
    MAX_HOLD,
    MAX_INT,
    ClaimRead,
    LabelledPage,
    QueryId,
    QueryRead,
    QueryStatus,
    QuerySummary,
    Released,
    Retired,
    RetireRequest,
    SessionPost,
    SessionPosted,
    TabId,
)

router = APIRouter(prefix="/runs/{run_id}", tags=["queries"])


@router.post("/sessions", status_code=201, openapi_extra=json_body(SessionPost))
async def post_session(
    run_id: RunId, request: Request, _: TrainerCaller, db: DB, settings: SettingsDep
) -> SessionPosted:
    """A feedback session's segments in one call; ids already stored are kept as they were."""
    declared = declared_length(request.headers.get("content-length"))
    if declared is not None and declared <= OFF_LOOP_BYTES:
        body = await parse_body(request, SessionPost)
    else:  # a big one: validated in the worker process, stored from a thread (SQLite frees the GIL)
        body = await request.app.state.session_parser.parse(request)
        return await anyio.to_thread.run_sync(_store, db, run_id, body, settings.max_queries_per_session)
    return _store(db, run_id, body, settings.max_queries_per_session)


def _store(db: Database, run_id: int, body: SessionPost, max_queries: int) -> SessionPosted:
    with db.write() as conn:
        return queries.post_session(conn, run_id, body, max_queries)


@router.post("/retire", openapi_extra=json_body(RetireRequest))
async def retire(run_id: RunId, request: Request, _: TrainerCaller, db: DB) -> Retired:
    """Close unlabelled queries the trainer will never use (a restarted trainer's leftovers)."""
    body = await parse_body(request, RetireRequest)
    with db.write() as conn:
        return queries.retire(conn, run_id, body.query_ids)


@router.get("/queries")
def list_queries(
    run_id: RunId,
    _: AnyCaller,
    db: DB,
    session: Annotated[int | None, Query(ge=0, le=MAX_INT)] = None,
    status: QueryStatus | None = None,
    limit: Annotated[int, Query(ge=1, le=5000)] = 1000,
    offset: Annotated[int, Query(ge=0, le=MAX_INT)] = 0,
) -> list[QuerySummary]:
    with db.read() as conn:
        return queries.list_queries(conn, run_id, session, status, limit, offset)


@router.get("/queries/{query_id}")
async def get_query(run_id: RunId, query_id: QueryId, _: AnyCaller, db: DB) -> QueryRead:
    with db.read() as conn:
        return queries.get(conn, run_id, query_id)


@router.post(
    "/claim", response_model=ClaimRead, responses={204: {"description": "nothing to claim right now"}, **CLAIMING}
)
async def claim(
    run_id: RunId,
    caller: LabelerCaller,
    db: DB,
    settings: SettingsDep,
    lease_s: LeaseS = None,
    hold: Annotated[int, Query(ge=1, le=MAX_HOLD, description="hold up to this many (2: preload the next)")] = 1,
    tab: Annotated[TabId | None, Query(description="the browser tab the claim is for: only it may label it")] = None,
) -> Response:
    """Renew every lease the caller holds here and return their `hold`-th query (of those held for
    `tab`), taking the oldest pending one when they hold fewer (204: none to take now; 409 for a
    finished run, or a tab beyond the labeler's MAX_TABS tabs' worth of held queries)."""
    with db.write() as conn:
        claimed = leases.claim(conn, run_id, caller, lease_s or settings.lease_s, hold, tab)
    if claimed is None:
        return Response(status_code=204)
    return Response(claimed, media_type="application/json")


@router.post("/queries/{query_id}/release")
async def release(run_id: RunId, query_id: QueryId, caller: LabelerCaller, db: DB) -> Released:
    """Hand a held query back to the pool without a skip (a preloaded segment nobody will see)."""
    with db.write() as conn:
        return Released(query_id=query_id, status=leases.release(conn, run_id, caller, query_id))


@router.get("/labelled")
def labelled(
    run_id: RunId,
    _: TrainerCaller,
    db: DB,
    cursor: Annotated[int, Query(ge=0, le=MAX_INT)] = 0,
    limit: Annotated[int, Query(ge=1, le=1000)] = 200,
) -> LabelledPage:
    """Every query with an effective label, with its frames: what a restarted trainer rebuilds from."""
    with db.read() as conn:
        return queries.labelled_page(conn, run_id, cursor, limit)
