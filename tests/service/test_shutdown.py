"""A graceful stop while clients wait: the trainer's long poll (`/events?wait_s=30`, it always holds
one) answers its empty page at once and an SSE stream ends, so the service stops promptly and
cleanly — not after the graceful timeout, with the waiting requests cancelled and a traceback."""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from pathlib import Path

import httpx

from backend.main import create_app
from backend.server import BackgroundServer
from collie.client import CollieClient

from .conftest import TOKENS, make_run_spec, next_data, settings_for


def test_a_stop_ends_long_polls_and_streams_at_once(tmp_path: Path, logged: list[logging.LogRecord]) -> None:
    server = BackgroundServer(create_app(settings_for(tmp_path / "stop.db"))).start()
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
    with httpx.Client(base_url=server.url, timeout=60) as http, contextlib.ExitStack() as stack:
        held = stack.enter_context(http.stream("GET", f"/api/runs/{run.id}/stream", headers=auth))
        lines = held.iter_lines()
        assert next_data(lines)["data"]["epoch"] == 0  # the stream waits for news now
        poll.start()
        time.sleep(0.5)  # the long poll waits too
        began = time.monotonic()
        server.stop()
        stopped_s = time.monotonic() - began
        assert [line for line in lines if line] == []  # the stream ended cleanly (no broken chunked body)
    poll.join(10)
    assert answers and answers[0].status_code == 200, answers
    assert answers[0].json() == {"events": [], "last_id": after}
    assert stopped_s < 1.5  # well within uvicorn's 2 s graceful timeout: nothing was cancelled
    assert [r.getMessage() for r in logged if r.levelno >= logging.ERROR] == []
