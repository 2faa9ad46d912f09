"""A run's stream: every label change, status and control change, in order, with per-run ids.

Two ways to read it, both resumable from the last id seen (nothing missed, nothing twice):
- GET /events?after=ID&wait_s=S — a JSON page; waits up to S seconds for something new (long poll,
  what synchronous clients such as the trainer use);
- GET /stream — Server-Sent Events; resumes from the Last-Event-ID header (browsers send it on
  reconnect) or ?after=ID. EventSource cannot send headers, so ?access_token= is accepted here.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from typing import Annotated

from fastapi import APIRouter, Depends, Header, Query, Request
from fastapi.responses import StreamingResponse
from fastapi.security import HTTPAuthorizationCredentials

from backend.routes.deps import ANY, DB, AnyCaller, Hub, RunId, SettingsDep, authenticate, bearer, check_scope
from backend.services import events
from backend.services.auth import Caller
from collie.schemas import MAX_INT, EventPage

router = APIRouter(prefix="/runs/{run_id}", tags=["stream"])

HEARTBEAT_S = 15.0


@router.get("/events")
async def events_page(
    run_id: RunId,
    _: AnyCaller,
    db: DB,
    hub: Hub,
    settings: SettingsDep,
    after: Annotated[int, Query(ge=0, le=MAX_INT)] = 0,
    limit: Annotated[int, Query(ge=1, le=events.MAX_PAGE)] = events.MAX_PAGE,
    wait_s: Annotated[float, Query(ge=0, le=60)] = 0.0,
) -> EventPage:
    loop = asyncio.get_running_loop()
    deadline = loop.time() + wait_s
    with db.read() as conn:
        events.last_id(conn, run_id)  # 404 for an unknown run
    while True:
        with db.read() as conn:
            page = events.read_after(conn, run_id, after, limit)
        remaining = deadline - loop.time()
        if page or remaining <= 0:
            return EventPage(events=page, last_id=page[-1].id if page else after)
        await hub.wait(run_id, after, min(remaining, settings.stream_poll_s))


async def _stream_caller(
    request: Request,
    credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(bearer)],
    access_token: Annotated[str | None, Query(description="for EventSource, which cannot send headers")] = None,
) -> Caller:
    caller = authenticate(request, credentials.credentials if credentials else access_token)
    check_scope(request, caller, ANY)  # every role may read, within its scope
    return caller


@router.get(
    "/stream",
    response_class=StreamingResponse,
    responses={200: {"content": {"text/event-stream": {}}, "description": "Server-Sent Events"}},
)
async def stream(
    run_id: RunId,
    request: Request,
    _: Annotated[Caller, Depends(_stream_caller)],
    db: DB,
    hub: Hub,
    settings: SettingsDep,
    after: Annotated[int | None, Query(ge=0, le=MAX_INT)] = None,
    last_event_id: Annotated[int | None, Header(ge=0, le=MAX_INT)] = None,
) -> StreamingResponse:
    with db.read() as conn:
        events.last_id(conn, run_id)
    start = last_event_id if last_event_id is not None else (after or 0)

    async def frames() -> AsyncIterator[str]:
        loop = asyncio.get_running_loop()
        last, idle_since = start, loop.time()
        yield "retry: 1000\n\n"
        while not await request.is_disconnected():
            with db.read() as conn:
                page = events.read_after(conn, run_id, last)
            for event in page:
                yield f"id: {event.id}\nevent: {event.kind}\ndata: {event.model_dump_json()}\n\n"
                last = event.id
            if page:
                idle_since = loop.time()
                continue
            if loop.time() - idle_since > HEARTBEAT_S:
                yield ": keep-alive\n\n"
                idle_since = loop.time()
            await hub.wait(run_id, last, settings.stream_poll_s)

    headers = {"Cache-Control": "no-cache", "X-Accel-Buffering": "no"}
    return StreamingResponse(frames(), media_type="text/event-stream", headers=headers)
