"""A graceful stop while clients wait: the trainer's long poll (`/events?wait_s=30`, it always holds
one) and the dashboard's (`/dashboard/runs?wait_s=…`) answer at once and an SSE stream ends, so the
service stops promptly and cleanly — not after the graceful timeout, with the waiting requests
cancelled and a traceback."""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Callable
from pathlib import Path

import httpx

from backend.main import create_app
from backend.server import BackgroundServer
from backend.services.events import EventHub
from collie.client import CollieClient

from .conftest import TOKENS, make_run_spec, next_data, settings_for


def test_a_stop_ends_long_polls_and_streams_at_once(tmp_path: Path, logged: list[logging.LogRecord]) -> None:
    # No fallback re-read within the wait: a poll the stop did not wake would wait its full 30 s
    # (and be cancelled at uvicorn's graceful timeout), not just until its next re-read.
    server = BackgroundServer(create_app(settings_for(tmp_path / "stop.db", stream_poll_s=60.0))).start()
    auth = {"Authorization": f"Bearer {TOKENS['trainer']}"}
    with CollieClient(server.url, TOKENS["trainer"]) as trainer:
        run = trainer.create_run(make_run_spec())
        trainer.set_status(run.id, "training", epoch=0)
        after = trainer.events(run.id).last_id
    answers: list[httpx.Response] = []
    poll = threading.Thread(
        target=lambda: answers.append(
            httpx.get(f"{server.url}/api/runs/{run.id}/events?after={after}&wait_s=30", headers=auth, timeout=60)
        )
    )
    version = httpx.get(f"{server.url}/api/dashboard/runs", headers=auth).json()["version"]
    pages: list[httpx.Response] = []
    dashboard = threading.Thread(  # it reads the log's version every POLL_S: no hub to be parked in
        target=lambda: pages.append(
            httpx.get(f"{server.url}/api/dashboard/runs?after={version}&wait_s=30", headers=auth, timeout=60)
        )
    )
    with httpx.Client(base_url=server.url, timeout=60) as http, contextlib.ExitStack() as stack:
        held = stack.enter_context(http.stream("GET", f"/api/runs/{run.id}/stream", headers=auth))
        lines = held.iter_lines()
        assert next_data(lines)["data"]["epoch"] == 0  # the stream waits for news now
        poll.start()
        dashboard.start()
        hub: EventHub = server.app.state.hub
        wait_while_alive(lambda: bool(hub._waiters.get(run.id)), poll, "the long poll waited in the hub")
        # uvicorn runs one task per open request: the stream, the long poll and now the dashboard's
        requests = server.server.server_state.tasks
        wait_while_alive(lambda: sum(not t.done() for t in requests) >= 3, dashboard, "the dashboard's poll arrived")
        time.sleep(0.5)  # and has looked twice
        assert dashboard.is_alive()
        server.stop()
        assert not server._thread.is_alive()  # stopped (stop() gives up after 10 s)
        assert [line for line in lines if line] == []  # the stream ended cleanly (no broken chunked body)
    poll.join(30)
    assert answers and answers[0].status_code == 200, answers
    assert answers[0].json() == {"events": [], "last_id": after}
    dashboard.join(30)
    assert pages and pages[0].status_code == 200 and pages[0].json()["version"] == version, pages
    # Nothing was cancelled: a request still open after uvicorn's 2 s graceful timeout is cancelled
    # with "Cancel N running task(s), timeout graceful shutdown exceeded" on uvicorn.error (an ERROR,
    # captured by `logged`), so this, not a wall-clock bound, tells a prompt stop from a late one.
    assert [r.getMessage() for r in logged if r.levelno >= logging.ERROR] == []


def wait_while_alive(reached: Callable[[], bool], thread: threading.Thread, what: str, timeout_s: float = 30.0) -> None:
    """Until `reached()`, failing if `thread` (the request that should get there) ends first."""
    deadline = time.monotonic() + timeout_s
    while not reached():
        assert thread.is_alive(), f"ended before: {what}"
        assert time.monotonic() < deadline, f"never: {what}"
        time.sleep(0.01)
