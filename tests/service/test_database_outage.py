"""A PostgreSQL outage, for real: the server is stopped under a running service (as `pg_ctl stop
-m fast` does) and started again. Meanwhile every route answers 503 JSON (health saying the
database is unreachable, the others with Retry-After), the log gets single lines and no
traceback, and everything works again once the database is back: an SSE stream held open across
the outage too (the one reader that feeds the streams survives it)."""

from __future__ import annotations

import contextlib
import logging
import time

import httpx
import pytest

from backend.main import create_app
from backend.routes import stream as stream_route
from backend.server import BackgroundServer
from collie.client import CollieClient

from .conftest import TOKENS, make_run_spec, next_data, settings_for
from .postgres import PostgresServer


def test_an_outage_is_503_json_and_the_service_recovers(
    logged: list[logging.LogRecord], monkeypatch: pytest.MonkeyPatch
) -> None:
    # A heartbeat checks the caller in the database: one inside the outage would end the held stream.
    monkeypatch.setattr(stream_route, "HEARTBEAT_S", 3600.0)
    pg = PostgresServer().start()  # its own server: the session's one stays up for the others
    try:
        app = create_app(settings_for(pg.new_database(), token_cache_s=0.0, stream_poll_s=0.1))
        with (
            BackgroundServer(app) as server,
            httpx.Client(base_url=server.url, timeout=30) as http,
            CollieClient(server.url, TOKENS["trainer"]) as trainer,
            contextlib.ExitStack() as stack,
        ):
            auth = {"Authorization": f"Bearer {TOKENS['trainer']}"}
            run = trainer.create_run(make_run_spec())
            trainer.set_status(run.id, "training", epoch=0)
            # silent through the outage (no heartbeat): a read may wait as long as the outage lasts
            held = stack.enter_context(http.stream("GET", f"/api/runs/{run.id}/stream", headers=auth, timeout=60))
            frames = held.iter_lines()
            assert next_data(frames)["data"]["epoch"] == 0  # its backlog: now it waits on the one reader
            pg.halt()
            deadline = time.monotonic() + 30  # the stream reader polls (every 0.1 s) into the outage
            while not any(r.getMessage().startswith("stream reader: database unreachable") for r in list(logged)):
                assert time.monotonic() < deadline, "the stream reader did not notice the outage"
                time.sleep(0.05)

            health = http.get("/api/health")
            assert health.status_code == 503 and "database is unreachable" in health.json()["detail"]
            assert health.headers["retry-after"]
            for path in ("/api/runs", f"/api/runs/{run.id}", f"/api/runs/{run.id}/events?after=0&wait_s=1"):
                down = http.get(path, headers=auth)
                assert down.status_code == 503, (path, down.text)
                assert "database is unreachable" in down.json()["detail"] and down.headers["retry-after"]
            assert http.post("/api/runs", content=make_run_spec().model_dump_json(), headers=auth).status_code == 503

            lines = [r.getMessage() for r in logged if r.levelno >= logging.WARNING]
            assert any("unreachable" in line for line in lines) and all("\n" not in line for line in lines)

            pg.start()
            deadline = time.monotonic() + 60
            while http.get("/api/health").status_code != 200:
                assert time.monotonic() < deadline, "the service did not see the database come back"
                time.sleep(0.1)
            assert http.get(f"/api/runs/{run.id}", headers=auth).json()["id"] == run.id
            trainer.set_status(run.id, "training", epoch=1)
            assert next_data(frames)["data"]["epoch"] == 1  # the held stream goes on
        assert [r for r in logged if r.exc_info] == []  # no traceback, from the outage or the shutdown
    finally:
        pg.stop()
