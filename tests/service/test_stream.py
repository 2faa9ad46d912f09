"""The run's stream: ordered per-run ids, resumable (long poll and SSE), nothing missed or doubled,
also across a service restart."""

from __future__ import annotations

import logging
import socket
import threading
import time
import typing
from pathlib import Path

import httpx
import pytest

from backend.main import create_app
from backend.server import BackgroundServer, bind
from collie.client import CollieClient
from collie.labels import Label
from collie.schemas import EventData, LabelChangedEvent, MetricsIn, RolloutsIn, RunRead, StreamEvent

from .conftest import TOKENS, make_run_spec, make_session, settings_for


@pytest.fixture(scope="module")
def database_url(both_databases: str) -> str:
    """This module runs on SQLite and on a real PostgreSQL server."""
    return both_databases


def label_all(labeler: CollieClient, run_id: int) -> list[str]:
    done = []
    while (claim := labeler.claim(run_id)) is not None:
        labeler.submit(run_id, claim.query.query_id, 1)
        done.append(claim.query.query_id)
    return done


def test_long_poll_wakes_when_a_label_arrives(trainer: CollieClient, labeler: CollieClient, run: RunRead) -> None:
    after = trainer.events(run.id).last_id
    claim = labeler.claim(run.id)
    timer = threading.Timer(0.3, labeler.submit, args=(run.id, claim.query.query_id, 2))
    timer.start()
    started = time.monotonic()
    page = trainer.events(run.id, after=after, wait_s=10)
    assert time.monotonic() - started < 9  # woken by the label, not by the 10 s wait
    assert [(e.kind, e.data.query_id, e.data.label) for e in page.events if isinstance(e, LabelChangedEvent)] == [
        ("label", "0-0", 2)
    ]
    assert [e.kind for e in page.events] == ["label"]
    assert page.last_id == page.events[-1].id
    timer.join()
    assert trainer.events(run.id, after=page.last_id, wait_s=0.2).events == []


def test_paging_misses_nothing_and_repeats_nothing(trainer: CollieClient, labeler: CollieClient) -> None:
    created = trainer.create_run(make_run_spec(n_total=25))
    trainer.post_session(created.id, make_session(0, 25))
    label_all(labeler, created.id)
    everything = trainer.events(created.id).events
    seen, after = [], 0
    while page := trainer.events(created.id, after=after, limit=7).events:
        seen += page
        after = page[-1].id
    assert [e.id for e in seen] == list(range(1, len(everything) + 1))
    assert seen == everything
    kinds = [e.kind for e in everything]
    assert kinds[:2] == ["status", "queries"] and kinds.count("label") == 25


def test_sse_resumes_from_last_event_id(live: BackgroundServer, trainer: CollieClient, run: RunRead) -> None:
    headers = {"Authorization": f"Bearer {TOKENS['labeler']}", "Last-Event-ID": "1"}
    with httpx.stream("GET", f"{live.url}/api/runs/{run.id}/stream", headers=headers, timeout=5) as response:
        assert response.headers["content-type"].startswith("text/event-stream")
        lines = response.iter_lines()
        ids = []
        for line in lines:
            if line.startswith("id:"):
                ids.append(int(line[3:]))
                break
    assert ids == [2]  # event 1 (run created) is not repeated


def test_sse_accepts_access_token_for_eventsource(live: BackgroundServer, run: RunRead) -> None:
    url = f"{live.url}/api/runs/{run.id}/stream?after=0&access_token={TOKENS['labeler']}"
    with httpx.stream("GET", url, timeout=5) as response:
        assert response.status_code == 200
    assert httpx.get(f"{live.url}/api/runs/{run.id}/stream?access_token=bad").status_code == 401


def test_a_websocket_knock_leaves_no_token_in_the_log(tmp_path: Path) -> None:
    """uvicorn logs each refused WebSocket upgrade at info with its query string, where the
    dashboard's streams carry their token (the access log is off; this line is uvicorn's own).
    Was: `collie serve --log-level info` wrote the operator's token to its log."""
    lines: list[str] = []
    handler = logging.Handler()
    handler.emit = lambda record: lines.append(record.getMessage())  # type: ignore[method-assign]
    uvicorn_log = logging.getLogger("uvicorn.error")
    with BackgroundServer(create_app(settings_for(tmp_path / "ws.db")), log_level="info") as server:
        uvicorn_log.addHandler(handler)
        try:
            host, port = server.url.removeprefix("http://").split(":")
            knock = (
                f"GET /api/runs/1/stream?after=0&access_token={TOKENS['operator']} HTTP/1.1\r\nHost: x\r\n"
                "Connection: Upgrade\r\nUpgrade: websocket\r\nSec-WebSocket-Version: 13\r\n"
                "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n\r\n"
            )
            with socket.create_connection((host, int(port)), timeout=10) as sock:
                sock.sendall(knock.encode())
                assert b"403" in sock.recv(1000)
            deadline = time.monotonic() + 5
            while not any("WebSocket" in line for line in lines) and time.monotonic() < deadline:
                time.sleep(0.05)
        finally:
            uvicorn_log.removeHandler(handler)
    logged = [line for line in lines if "WebSocket" in line]
    assert logged and "access_token=…" in logged[0], lines  # the line is still there, its token is not
    assert not [line for line in lines if TOKENS["operator"] in line], lines


def test_sse_consumer_survives_a_service_restart(database_url: str) -> None:
    settings = settings_for(database_url)  # a second service on the module's database
    # The clients keep the service's URL, so the restarted service must have its port. The test holds
    # the port, as `collie up` holds the service's, and each service serves a dup of it: no other
    # process can take it in between (was: a freed port bound again, now and then taken meanwhile).
    listener, url = bind("127.0.0.1", 0)
    port = listener.getsockname()[1]
    try:
        server = BackgroundServer(create_app(settings), sock=listener.dup()).start()
        trainer = CollieClient(url, TOKENS["trainer"])
        labeler = CollieClient(url, TOKENS["labeler"])
        run = trainer.create_run(make_run_spec())
        trainer.post_session(run.id, make_session(0, 10))
        stream = CollieClient(url, TOKENS["operator"]).stream(run.id, max_backoff_s=0.2)
        received: list[StreamEvent] = []
        consumer = threading.Thread(target=lambda: received.extend(stream) or None, daemon=True)
        consumer.start()
        for _ in range(5):
            claim = labeler.claim(run.id)
            labeler.submit(run.id, claim.query.query_id, 0)
        server.stop()
        with pytest.raises(OSError, match="in use"):  # another process binding it as a service does
            bind("127.0.0.1", port)[0].close()
        server = BackgroundServer(create_app(settings), sock=listener.dup()).start()
        label_all(labeler, run.id)
        expected = trainer.events(run.id).events
        deadline = time.monotonic() + 60  # the client reconnects with backoff; a busy machine is slow
        while len(received) < len(expected) and time.monotonic() < deadline:
            time.sleep(0.05)
        stream.close()
        server.stop()
    finally:
        listener.close()
    assert [e.id for e in received] == [e.id for e in expected] == list(range(1, len(expected) + 1))
    assert stream.reconnects >= 1
    for client in (trainer, labeler, stream.client):
        client.close()


def test_every_event_kind_has_its_own_typed_data(
    trainer: CollieClient, labeler: CollieClient, operator: CollieClient
) -> None:
    """Each envelope's kind names its data model's kind, and a run's life produces only typed data."""
    for member in typing.get_args(typing.get_args(StreamEvent)[0]):
        (kind,) = typing.get_args(member.model_fields["kind"].annotation)
        assert member.model_fields["data"].annotation.kind == kind
    created = trainer.create_run(make_run_spec())
    trainer.post_session(created.id, make_session(0, 2))
    claim = labeler.claim(created.id)
    assert claim is not None
    labeler.submit(created.id, claim.query.query_id, 2)
    labeler.undo(created.id, claim.query.query_id)
    trainer.retire(created.id, ["0-1"])
    operator.pause(created.id)
    operator.set_feedback_policy(created.id, 5.0)
    trainer.post_metrics(created.id, MetricsIn(epoch=1, values={"safe_coverage": 1.0}))
    trainer.post_rollouts(created.id, RolloutsIn(epoch=1, rollouts=[]))
    events = trainer.events(created.id).events
    assert {e.kind for e in events} == {
        "status", "queries", "label", "withdrawn", "retired", "control", "policy", "metrics", "rollouts"
    }  # fmt: skip
    for e in events:
        assert isinstance(e.data, EventData) and type(e.data).kind == e.kind
    label = next(e for e in events if isinstance(e, LabelChangedEvent))
    assert (label.data.query_id, label.data.label, label.data.labeler) == (claim.query.query_id, Label.GOOD, "labeler")
