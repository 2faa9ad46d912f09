"""A run's stream: every label change, status and control change, in order, with per-run ids.

Two ways to read it, both resumable from the last id seen (nothing missed, nothing twice):
- GET /events?after=ID&wait_s=S — a JSON page; waits up to S seconds for something new (long poll,
  what synchronous clients such as the trainer use);
- GET /stream — Server-Sent Events; resumes from the Last-Event-ID header (browsers send it on
  reconnect) or ?after=ID. EventSource cannot send headers, so ?access_token= is accepted here.
  One reader feeds every open stream (services/fanout.py); a token may hold
  `max_streams_per_token` streams open at once (429 beyond).
"""

from __future__ import annotations

import asyncio
import logging
from collections import Counter
from collections.abc import AsyncIterator
from typing import Annotated, Any

import anyio
from fastapi import APIRouter, Depends, Header, HTTPException, Query, Request, Response
from fastapi.responses import StreamingResponse
from fastapi.security import HTTPAuthorizationCredentials
from sqlalchemy.exc import DBAPIError
from starlette.types import Receive, Scope, Send

from backend.db import DatabaseFileGone
from backend.routes.deps import (
    ANY,
    DB,
    AnyCaller,
    Hub,
    RunId,
    SettingsDep,
    authenticate,
    bearer,
    check_scope,
    note_trainer_contact,
)
from backend.services import auth, events
from backend.services.auth import Caller
from backend.services.errors import first_line
from backend.services.fanout import StreamFeed, Subscription
from collie.schemas import MAX_INT, EventPage

router = APIRouter(prefix="/runs/{run_id}", tags=["stream"])

HEARTBEAT_S = 15.0
log = logging.getLogger("collie.service")


@router.get("/events", response_model=EventPage)
async def events_page(
    run_id: RunId,
    _: AnyCaller,
    db: DB,
    hub: Hub,
    settings: SettingsDep,
    after: Annotated[int, Query(ge=0, le=MAX_INT)] = 0,
    limit: Annotated[int, Query(ge=1, le=events.MAX_PAGE)] = events.MAX_PAGE,
    wait_s: Annotated[float, Query(ge=0, le=60, allow_inf_nan=False)] = 0.0,
) -> Response:
    loop = asyncio.get_running_loop()
    deadline = loop.time() + wait_s
    checked = False
    while True:
        with db.read() as conn:  # one read per wakeup; the run is looked up only while its page is empty
            page = events.read_after(conn, run_id, after, limit)
            if not page and not checked:
                events.last_id(conn, run_id)  # 404 for an unknown run
                checked = True
        remaining = deadline - loop.time()
        if page or remaining <= 0 or hub.closed:  # closed: the service stops, the client asks again later
            # written straight from the typed page: FastAPI would turn it into dicts, then JSON
            body = EventPage(events=page, last_id=page[-1].id if page else after).model_dump_json()
            return Response(body, media_type="application/json")
        await hub.wait(run_id, after, min(remaining, settings.stream_poll_s))


async def _stream_caller(
    request: Request,
    credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(bearer)],
    access_token: Annotated[str | None, Query(description="for EventSource, which cannot send headers")] = None,
) -> Caller:
    caller = authenticate(request, credentials.credentials if credentials else access_token)
    check_scope(request, caller, ANY)  # every role may read, within its scope
    note_trainer_contact(request, caller)  # as every other route does (the trainer long-polls /events today)
    return caller


@router.get(
    "/stream",
    response_class=StreamingResponse,
    responses={200: {"content": {"text/event-stream": {}}, "description": "Server-Sent Events"}},
)
async def stream(
    run_id: RunId,
    request: Request,
    caller: Annotated[Caller, Depends(_stream_caller)],
    db: DB,
    settings: SettingsDep,
    after: Annotated[int | None, Query(ge=0, le=MAX_INT)] = None,
    last_event_id: Annotated[int | None, Header(ge=0, le=MAX_INT)] = None,
) -> StreamingResponse:
    with db.read() as conn:
        events.last_id(conn, run_id)
    start = last_event_id if last_event_id is not None else (after or 0)
    feed: StreamFeed = request.app.state.feed
    if feed.open_by_caller[caller.id] >= settings.max_streams_per_token:
        raise HTTPException(429, f"at most {settings.max_streams_per_token} open streams per token; close one first")

    def still_allowed() -> bool:
        with db.read() as conn:
            return auth.may_still_see(conn, caller.id, run_id)

    async def frames() -> AsyncIterator[str]:
        subscription: Subscription | None = None
        try:
            subscription = await feed.subscribe(run_id, start, caller.id)
            yield "retry: 1000\n\n"
            loop = asyncio.get_running_loop()
            checked = loop.time()
            while not subscription.ended:
                if loop.time() >= checked + HEARTBEAT_S:  # revoked or narrowed by another process, busy or silent
                    checked = loop.time()
                    if not await anyio.to_thread.run_sync(still_allowed):
                        return
                if subscription.lagged:
                    sent = await feed.backlog(subscription)
                else:
                    sent = list(subscription.frames)
                    subscription.frames.clear()
                fresh = [(i, text) for i, text in sent if i > subscription.last]
                if fresh:
                    subscription.last = fresh[-1][0]
                    yield "".join(text for _, text in fresh)
                    continue
                if subscription.lagged or subscription.frames:
                    continue
                subscription.signal.clear()
                try:
                    await asyncio.wait_for(subscription.signal.wait(), max(0.0, checked + HEARTBEAT_S - loop.time()))
                except TimeoutError:
                    yield ": keep-alive\n\n"
        except DBAPIError as exc:  # the database went away: the stream ends, the client resumes from its last id
            log.warning("stream of run %d ended: database unreachable: %s", run_id, first_line(exc.orig))
        except DatabaseFileGone as exc:  # its file deleted under the service: ended, said once, no traceback
            log.warning("stream of run %d ended: %s", run_id, exc)
        finally:
            if subscription is not None:
                feed.unsubscribe(subscription)

    headers = {"Cache-Control": "no-cache", "X-Accel-Buffering": "no"}
    return SlotStream(feed.open_by_caller, caller.id, frames(), media_type="text/event-stream", headers=headers)


class SlotStream(StreamingResponse):
    """Holds one of its caller's stream slots from the handler's check until the response ends,
    however it ends: a slot taken only once the body starts would let concurrent opens all pass."""

    def __init__(self, slots: Counter[int], caller_id: int, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.slots, self.caller_id = slots, caller_id
        slots[caller_id] += 1

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        try:
            await super().__call__(scope, receive, send)
        finally:
            self.slots[self.caller_id] -= 1
            if self.slots[self.caller_id] <= 0:
                del self.slots[self.caller_id]
