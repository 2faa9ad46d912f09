"""Open streams share one reader: idle streams cost no database reads of their own, a new event
reaches every one of them, and a token may hold only so many streams open (429 beyond)."""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from sqlalchemy import event

from backend.main import create_app
from backend.routes import stream as stream_route
from backend.server import BackgroundServer
from collie.client import CollieClient

from .conftest import TOKENS, make_run_spec, make_session, settings_for


@pytest.fixture(scope="module")
def database_url(both_databases: str) -> str:
    """This module runs on SQLite and on a real PostgreSQL server."""
    return both_databases


class Reader(threading.Thread):
    """One SSE consumer in a thread: the ids it received."""

    def __init__(self, url: str, token: str, after: int) -> None:
        super().__init__(daemon=True)
        self.url, self.token, self.after = url, token, after
        self.ids: list[int] = []
        self.opened = threading.Event()
        self.status = 0
        self.stop = False

    def run(self) -> None:
        headers = {"Authorization": f"Bearer {self.token}"}
        timeout = httpx.Timeout(30, read=120)  # a stream may stay silent a while: no heartbeat in some tests
        try:
            with httpx.stream("GET", f"{self.url}?after={self.after}", headers=headers, timeout=timeout) as response:
                self.status = response.status_code
                self.opened.set()
                for line in response.iter_lines():
                    if line.startswith("id:"):
                        self.ids.append(int(line[3:]))
                    if self.stop:
                        return
        except httpx.HTTPError:  # the service went away at the end of the module
            return


def wait_for(condition: Any, timeout_s: float = 20.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while not condition() and time.monotonic() < deadline:
        time.sleep(0.05)
    return bool(condition())


def test_idle_streams_share_one_reader(
    live: BackgroundServer, trainer: CollieClient, labeler: CollieClient, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(stream_route, "HEARTBEAT_S", 3600.0)  # no keep-alive (and its read) in the window
    run = trainer.create_run(make_run_spec())
    trainer.post_session(run.id, make_session(0, 2))
    after = trainer.events(run.id).last_id
    url = f"{live.url}/api/runs/{run.id}/stream"
    seen: list[str] = []

    def count(_conn: Any, _cursor: Any, statement: str, *_: Any) -> None:
        if statement.lstrip().upper().startswith("SELECT"):
            seen.append(statement)

    engine = live.app.state.db.engine
    event.listen(engine, "before_cursor_execute", count)
    try:
        readers = [Reader(url, TOKENS["operator"], after) for _ in range(20)]
        for reader in readers:
            reader.start()
            assert reader.opened.wait(60) and reader.status == 200
        # every stream has read its (empty) backlog from the log: one read of stream_events each
        assert wait_for(lambda: sum("FROM stream_events" in s for s in list(seen)) >= 20, timeout_s=60), seen
        idle_from = len(seen)
        time.sleep(3.0)  # idle: each stream polling the log every second would read 60 times
        statements = seen[idle_from:]
    finally:
        event.remove(engine, "before_cursor_execute", count)
    assert len(statements) <= 6, statements  # the one reader's poll, about once a second
    claim = labeler.claim(run.id)
    labeler.submit(run.id, claim.query.query_id, 2)
    label_id = trainer.events(run.id, after=after).last_id
    assert wait_for(lambda: all(label_id in r.ids for r in readers))
    for reader in readers:
        assert reader.ids == list(range(after + 1, label_id + 1))  # nothing missed or doubled
        reader.stop = True
    trainer.set_status(run.id, "training", epoch=1)  # an event, so the readers wake and hang up (no heartbeat)
    for reader in readers:
        reader.join(30)


def streams(server: BackgroundServer, run_id: int, token: str, n: int) -> Iterator[Reader]:
    for _ in range(n):
        reader = Reader(f"{server.url}/api/runs/{run_id}/stream", token, 0)
        reader.start()
        assert reader.opened.wait(20)
        yield reader


def test_open_streams_per_token_are_capped(tmp_path: Path) -> None:
    settings = settings_for(tmp_path / "cap.db", max_streams_per_token=2)
    with BackgroundServer(create_app(settings)) as server, CollieClient(server.url, TOKENS["trainer"]) as trainer:
        run = trainer.create_run(make_run_spec())
        held = list(streams(server, run.id, TOKENS["operator"], 2))
        assert [r.status for r in held] == [200, 200]
        url = f"{server.url}/api/runs/{run.id}/stream"
        refused = httpx.get(url, headers={"Authorization": f"Bearer {TOKENS['operator']}"}, timeout=10)
        assert refused.status_code == 429 and "at most 2 open streams" in refused.json()["detail"]
        other = next(streams(server, run.id, TOKENS["labeler"], 1))  # another token has its own allowance
        assert other.status == 200
        for reader in (*held, other):
            reader.stop = True
        trainer.set_status(run.id, "training", epoch=1)  # an event, so the readers wake and hang up

        def reopened() -> bool:
            with httpx.stream("GET", url, headers={"Authorization": f"Bearer {TOKENS['operator']}"}) as r:
                return r.status_code == 200

        assert wait_for(reopened)


def test_streams_opened_at_once_are_capped_too(tmp_path: Path) -> None:
    """Twenty opens sent at the same moment with one token: only the allowance (3) gets a stream."""
    settings = settings_for(tmp_path / "race.db", max_streams_per_token=3)
    with BackgroundServer(create_app(settings)) as server, CollieClient(server.url, TOKENS["trainer"]) as trainer:
        run = trainer.create_run(make_run_spec())
        url = f"{server.url}/api/runs/{run.id}/stream"

        async def open_all() -> list[int]:
            headers = {"Authorization": f"Bearer {TOKENS['operator']}"}
            async with httpx.AsyncClient(timeout=20, limits=httpx.Limits(max_connections=40)) as client:
                sent = [client.send(client.build_request("GET", url, headers=headers), stream=True) for _ in range(20)]
                responses = await asyncio.gather(*sent)
                for response in responses:
                    await response.aclose()
                return [r.status_code for r in responses]

        assert sorted(asyncio.run(open_all())) == [200] * 3 + [429] * 17


def test_revoking_a_token_ends_its_open_streams(
    live: BackgroundServer, operator: CollieClient, trainer: CollieClient
) -> None:
    created = operator.create_labeler("stream-revoked")
    run = trainer.create_run(make_run_spec())
    reader = next(streams(live, run.id, created.token, 1))
    assert reader.status == 200
    operator.revoke(created.id)
    reader.join(10)
    assert not reader.is_alive()  # the service closed the stream at once
