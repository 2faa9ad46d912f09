"""The per-run event log behind the stream. Each event gets the run's next id inside the writing
transaction, so ids are gap-free and in commit order; readers resume with `after=id`. The hub only
wakes readers: they always re-read the log, so a lost or spurious wakeup costs latency, never an event."""

from __future__ import annotations

import asyncio
from collections import defaultdict
from collections.abc import Callable

from sqlalchemy import Connection, bindparam, insert, select, update

from backend.models import Run, StreamEvent
from backend.services.errors import NotFound
from collie.schemas import STREAM_EVENT, EventData
from collie.schemas import StreamEvent as StreamEventSchema

MAX_PAGE = 1000


_NEXT_ID = (
    update(Run)
    .where(Run.id == bindparam("run"))
    .values(
        last_event_id=Run.last_event_id + 1,
        n_labels=Run.n_labels + bindparam("labels_delta"),
        updated_at=bindparam("now"),
    )
    .returning(Run.last_event_id)
)
_INSERT = insert(StreamEvent)


def append(conn: Connection, run_id: int, data: EventData, now: float, labels_delta: int = 0) -> int:
    """Add one event to the run's log (and `labels_delta` to its label count); returns the event's
    id. Its kind is the data's. Readers are woken after commit."""
    params = {"run": run_id, "now": now, "labels_delta": labels_delta}
    seq = conn.execute(_NEXT_ID, params).scalar_one()
    row = {"run_id": run_id, "seq": seq, "kind": data.kind, "data": data.model_dump(mode="json"), "created_at": now}
    conn.execute(_INSERT, row)
    conn.info.setdefault("published", []).append((run_id, seq))
    return seq


def read_after(conn: Connection, run_id: int, after: int, limit: int = MAX_PAGE) -> list[StreamEventSchema]:
    rows = conn.execute(
        select(StreamEvent.seq, StreamEvent.kind, StreamEvent.data, StreamEvent.created_at)
        .where(StreamEvent.run_id == run_id, StreamEvent.seq > after)
        .order_by(StreamEvent.seq)
        .limit(min(limit, MAX_PAGE))
    )
    return [
        STREAM_EVENT.validate_python(
            {"id": r.seq, "run_id": run_id, "kind": r.kind, "data": r.data, "created_at": r.created_at}
        )
        for r in rows
    ]


def last_id(conn: Connection, run_id: int) -> int:
    value = conn.execute(select(Run.last_event_id).where(Run.id == run_id)).scalar()
    if value is None:
        raise NotFound(f"no run {run_id}")
    return value


class EventHub:
    """Wakes the readers of a run when its log grows. Lives on the service's event loop."""

    def __init__(self) -> None:
        self._loop: asyncio.AbstractEventLoop | None = None
        self._latest: dict[int, int] = {}
        self._waiters: dict[int, list[asyncio.Future[None]]] = defaultdict(list)
        self._listeners: list[Callable[[list[tuple[int, int]]], None]] = []
        self.closed = False  # the service is stopping: waits return at once

    def bind(self, loop: asyncio.AbstractEventLoop) -> None:
        self._loop = loop

    def listen(self, callback: Callable[[list[tuple[int, int]]], None]) -> None:
        """Also call `callback` (on the loop) with every published (run_id, event id) batch."""
        self._listeners.append(callback)

    def publish(self, items: list[tuple[int, int]]) -> None:
        """Thread-safe: called after a commit, from the loop or from a worker thread."""
        if self._loop is None or not items:
            return
        try:
            running = asyncio.get_running_loop()
        except RuntimeError:
            running = None
        if running is self._loop:
            self._wake(items)
        else:
            self._loop.call_soon_threadsafe(self._wake, items)

    def _wake(self, items: list[tuple[int, int]]) -> None:
        for run_id, seq in items:
            if seq > self._latest.get(run_id, 0):
                self._latest[run_id] = seq
            for future in self._waiters.pop(run_id, []):
                if not future.done():
                    future.set_result(None)
        for listener in self._listeners:
            listener(items)

    def close(self) -> None:
        """The service is stopping: every wait returns now, and later ones at once."""
        self.closed = True
        for waiters in self._waiters.values():
            for future in waiters:
                if not future.done():
                    future.set_result(None)

    async def wait(self, run_id: int, after: int, timeout: float) -> None:
        """Return when the run may have an event past `after`, after `timeout` seconds, or when
        the hub closes."""
        if self._latest.get(run_id, 0) > after or timeout <= 0 or self.closed:
            return
        future: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        self._waiters[run_id].append(future)
        try:
            await asyncio.wait_for(future, timeout)
        except TimeoutError:
            pass
        finally:
            waiters = self._waiters.get(run_id)
            if waiters and future in waiters:
                waiters.remove(future)
