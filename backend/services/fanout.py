"""One reader for every open SSE stream. Streams subscribe to a run; the feed reads each run's new
events once — when a commit in this process wakes it (EventHub), or when a cheap poll of the runs'
last ids (one query for all runs, every `poll_s`: writers in other processes) shows news — and
hands the same SSE frames to every subscriber. A subscriber reads its own backlog from the log
(resume from any id) and again whenever it fell too far behind, so nothing is missed or doubled:
ids are gap-free per run and a subscriber keeps the last one it sent."""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections import Counter, defaultdict, deque

import anyio
from sqlalchemy import select
from sqlalchemy.exc import DBAPIError

from backend.db import Database, DatabaseFileGone
from backend.models import Run
from backend.services import auth, events
from backend.services.errors import first_line
from backend.services.events import EventHub
from collie.schemas import StreamEvent

MAX_QUEUED = 2000  # frames a subscriber may fall behind before it re-reads the log itself

Frame = tuple[int, str]  # (event id, SSE text)
log = logging.getLogger("collie.service")


def sse_frame(event: StreamEvent) -> str:
    return f"id: {event.id}\nevent: {event.kind}\ndata: {event.model_dump_json()}\n\n"


class Subscription:
    def __init__(self, run_id: int, after: int, caller_id: int) -> None:
        self.run_id = run_id
        self.caller_id = caller_id
        self.ended = False  # its caller was revoked: the stream closes
        self.last = after
        self.frames: deque[Frame] = deque()
        self.lagged = True  # the backlog comes from the log first
        self.signal = asyncio.Event()

    def offer(self, frame: Frame) -> None:
        if self.lagged:
            return
        if len(self.frames) >= MAX_QUEUED:
            self.frames.clear()
            self.lagged = True
        else:
            self.frames.append(frame)
        self.signal.set()


class StreamFeed:
    """Lives on the service's event loop (start() in the lifespan)."""

    def __init__(self, db: Database, hub: EventHub, poll_s: float) -> None:
        self.db, self.hub, self.poll_s = db, hub, poll_s
        self._subscribers: dict[int, set[Subscription]] = defaultdict(set)
        self._cursor: dict[int, int] = {}  # per run: the last event id handed out
        self._woken: set[int] = set()
        self._wake = asyncio.Event()
        self._task: asyncio.Task[None] | None = None
        self.open_by_caller: Counter[int] = Counter()
        self._closed = False
        hub.listen(self._published)

    def start(self) -> None:
        self._task = asyncio.get_running_loop().create_task(self._run())

    def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()

    def _published(self, items: list[tuple[int, int]]) -> None:
        """Called by the hub on the loop after a commit in this process."""
        runs = {run_id for run_id, _ in items if run_id in self._subscribers}
        if runs:
            self._woken |= runs
            self._wake.set()

    async def subscribe(self, run_id: int, after: int, caller_id: int) -> Subscription:
        """A stream of `run_id` for `caller_id`, ended at once if the caller was revoked or lost the
        run since its token was checked (another process's change, a token cache's old scope)."""
        subscription = Subscription(run_id, after, caller_id)
        self._subscribers[run_id].add(subscription)  # first: a change in this process from now on ends it
        try:
            last, allowed = await anyio.to_thread.run_sync(self._opening, run_id, caller_id)  # one made before
        except BaseException:
            self.unsubscribe(subscription)
            raise
        self._cursor.setdefault(run_id, last)
        subscription.ended = subscription.ended or not allowed or self._closed
        return subscription

    def end_streams_of(self, caller_id: int) -> None:
        """A revoked principal's open streams close now (those in other processes within 15 s, when
        their next check finds the principal revoked)."""
        for subscribers in self._subscribers.values():
            for subscription in subscribers:
                if subscription.caller_id == caller_id:
                    subscription.ended = True
                    subscription.signal.set()

    def end_streams_outside(self, caller_id: int, runs: list[int] | None) -> None:
        """A labeler's scope changed: its open streams of runs it may no longer see close now."""
        for run_id, subscribers in self._subscribers.items():
            for subscription in subscribers:
                if subscription.caller_id == caller_id and runs is not None and run_id not in runs:
                    subscription.ended = True
                    subscription.signal.set()

    def close(self) -> None:
        """The service is stopping: every open stream ends now (clients resume from their last id)."""
        self._closed = True
        for subscribers in self._subscribers.values():
            for subscription in subscribers:
                subscription.ended = True
                subscription.signal.set()

    def unsubscribe(self, subscription: Subscription) -> None:
        subscribers = self._subscribers.get(subscription.run_id)
        if subscribers is None:
            return
        subscribers.discard(subscription)
        if not subscribers:
            del self._subscribers[subscription.run_id]
            self._cursor.pop(subscription.run_id, None)

    async def backlog(self, subscription: Subscription) -> list[Frame]:
        """The subscriber's events from the log, after the last one it sent (one page)."""
        subscription.lagged = False
        page = await anyio.to_thread.run_sync(self._read, subscription.run_id, subscription.last)
        if len(page) == events.MAX_PAGE:
            subscription.lagged = True  # more to read
            subscription.signal.set()
        return [(e.id, sse_frame(e)) for e in page]

    # ---------------------------------------------------------------- the one reader

    async def _run(self) -> None:
        """Reads on through a database outage: one line when it starts, one when it ends; nothing
        is lost meanwhile (the poll of the runs' last ids finds what the failed reads missed)."""
        polled, failing = asyncio.get_running_loop().time(), False
        while True:
            try:
                polled = await self._step(polled)
            except (DBAPIError, DatabaseFileGone) as exc:
                if not failing:
                    how = "database unreachable" if isinstance(exc, DBAPIError) else "database file gone"
                    cause = first_line(exc.orig if isinstance(exc, DBAPIError) else exc)
                    log.warning("stream reader: %s, retrying every %g s: %s", how, self.poll_s, cause)
                failing = True
                await asyncio.sleep(self.poll_s)
                continue
            if failing:
                log.warning("stream reader: the database answers again")
                failing = False

    async def _step(self, polled: float) -> float:
        """Wait for a wakeup or the next poll, hand out what is new; the time of the last poll."""
        loop = asyncio.get_running_loop()
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(self._wake.wait(), max(0.0, polled + self.poll_s - loop.time()))
        self._wake.clear()
        woken, self._woken = self._woken, set()
        watched = dict(self._cursor)
        if watched and loop.time() >= polled + self.poll_s:  # which runs did other processes write to?
            latest = await anyio.to_thread.run_sync(self._last_ids, list(watched))
            woken |= {run_id for run_id, last in latest.items() if last > watched[run_id]}
        if loop.time() >= polled + self.poll_s:
            polled = loop.time()
        for run_id in woken & set(watched):
            page = await anyio.to_thread.run_sync(self._read, run_id, watched[run_id])
            self._dispatch(run_id, page)
            if len(page) == events.MAX_PAGE:
                self._woken.add(run_id)
                self._wake.set()
        return polled

    def _dispatch(self, run_id: int, page: list[StreamEvent]) -> None:
        if run_id not in self._cursor or not page:
            return
        for event in page:
            if event.id <= self._cursor[run_id]:
                continue
            frame = (event.id, sse_frame(event))
            for subscription in self._subscribers.get(run_id, ()):
                subscription.offer(frame)
            self._cursor[run_id] = event.id

    def _read(self, run_id: int, after: int) -> list[StreamEvent]:
        with self.db.read() as conn:
            return events.read_after(conn, run_id, after)

    def _opening(self, run_id: int, caller_id: int) -> tuple[int, bool]:
        """The run's last event id, and whether the caller may still see the run."""
        with self.db.read() as conn:
            return events.last_id(conn, run_id), auth.may_still_see(conn, caller_id, run_id)

    def _last_ids(self, run_ids: list[int]) -> dict[int, int]:
        with self.db.read() as conn:
            rows = conn.execute(select(Run.id, Run.last_event_id).where(Run.id.in_(run_ids)))
            return {r.id: r.last_event_id for r in rows}
