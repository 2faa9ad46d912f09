"""Large bodies: the caller is checked before a body is read (a stranger's 16 MiB is never
buffered), and the schemas bound what one segment may carry."""

from __future__ import annotations

import json
import socket
from urllib.parse import urlsplit

import httpx
import pytest

from backend.routes.deps import OFF_LOOP_BYTES
from backend.server import BackgroundServer
from collie.client import ApiError, CollieClient
from collie.schemas import MAX_FRAMES, MAX_PATH_POINTS

from .conftest import TOKENS, make_run_spec, make_session


def body_routes(live: BackgroundServer) -> list[tuple[str, str]]:
    paths = live.app.openapi()["paths"]
    return [
        (method.upper(), path.format(run_id=1, labeler_id=1))
        for path, operations in paths.items()
        for method, operation in operations.items()
        if "requestBody" in operation
    ]


def answer_without_body(live: BackgroundServer, method: str, path: str, token: str | None) -> bytes:
    """Send only the head of a request that announces a large body within the route's limit: an
    answer must come before any body."""
    size = 8 * 1024 * 1024 if path.endswith(("/sessions", "/rollouts")) else 512 * 1024
    url = urlsplit(live.url)
    head = f"{method} {path} HTTP/1.1\r\nHost: {url.hostname}\r\nContent-Type: application/json\r\n"
    head += f"Content-Length: {size}\r\n"
    if token is not None:
        head += f"Authorization: Bearer {token}\r\n"
    with socket.create_connection((url.hostname, url.port), timeout=10) as sock:
        sock.sendall(head.encode() + b"\r\n")
        try:
            return sock.recv(200)
        except TimeoutError:
            return b"(no answer before the body)"


def test_every_body_route_refuses_a_stranger_before_reading(live: BackgroundServer, trainer: CollieClient) -> None:
    trainer.create_run(make_run_spec())  # run 1 exists
    routes = body_routes(live)
    assert ("POST", "/api/runs/1/rollouts") in routes and len(routes) >= 10
    for method, path in routes:
        for token in (None, "not-a-token"):
            answer = answer_without_body(live, method, path, token)
            assert answer.startswith(b"HTTP/1.1 401"), (method, path, token, answer)


def test_a_role_that_may_not_is_refused_before_reading(live: BackgroundServer) -> None:
    for method, path, role in (
        ("POST", "/api/runs/1/rollouts", "labeler"),
        ("POST", "/api/runs/1/sessions", "labeler"),
        ("POST", "/api/runs/1/labels", "trainer"),
        ("POST", "/api/labelers", "trainer"),
    ):
        answer = answer_without_body(live, method, path, TOKENS[role])
        assert answer.startswith(b"HTTP/1.1 403"), (method, path, role, answer)


@pytest.mark.parametrize(
    ("field", "size", "words"),
    [
        ("path_xy", MAX_PATH_POINTS + 1, "path_xy"),
        ("xy", MAX_FRAMES + 1, "xy"),
    ],
)
def test_segment_arrays_are_bounded(
    live: BackgroundServer, trainer: CollieClient, field: str, size: int, words: str
) -> None:
    created = trainer.create_run(make_run_spec())
    session = make_session(0, 1).model_dump(mode="json")
    session["queries"][0][field] = [[0.0, 0.0]] * size
    response = httpx.post(
        f"{live.url}/api/runs/{created.id}/sessions",
        json=session,
        headers={"Authorization": f"Bearer {TOKENS['trainer']}"},
        timeout=60,
    )
    assert response.status_code == 422 and words in response.text and "at most" in response.text, response.text
    with pytest.raises(ApiError):
        trainer.query(created.id, "0-0")


def test_a_big_session_is_parsed_in_the_worker_like_a_small_one(live: BackgroundServer, trainer: CollieClient) -> None:
    """Above OFF_LOOP_BYTES the worker process validates the body: the same answers, the same rows."""
    created = trainer.create_run(make_run_spec(n_total=600))
    session = make_session(0, 600)
    assert len(session.model_dump_json()) > OFF_LOOP_BYTES
    posted = trainer.post_session(created.id, session)
    assert len(posted.created) == 600 and posted.existing == []
    stored = trainer.query(created.id, "0-599")
    sent = session.queries[599]
    assert (stored.xy, stored.qpos, stored.path_xy, stored.start) == (sent.xy, sent.qpos, sent.path_xy, sent.start)
    again = trainer.post_session(created.id, session)  # idempotent, through the worker too
    assert again.created == [] and len(again.existing) == 600

    bad = make_session(1, 600).model_dump(mode="json")
    bad["queries"][599]["obs"][0][0] = "__BAD__"
    text = json.dumps(bad).replace('"__BAD__"', "NaN")
    headers = {"Authorization": f"Bearer {TOKENS['trainer']}", "Content-Type": "application/json"}
    response = httpx.post(f"{live.url}/api/runs/{created.id}/sessions", content=text, headers=headers, timeout=60)
    assert response.status_code == 422 and "finite" in response.text
    assert "599" in response.text  # the location of the bad value is named
    assert '"input"' not in response.text  # not echoed (a NaN), nor claimed to be null
    assert trainer.run(created.id).queue.pending == 600  # nothing of the bad session stored


def test_a_dead_session_worker_is_replaced(live: BackgroundServer, trainer: CollieClient) -> None:
    """The worker killed (as the kernel's OOM killer would): the next big session still stores."""
    created = trainer.create_run(make_run_spec(n_total=None))
    trainer.post_session(created.id, make_session(0, 600))
    pool = live.app.state.session_parser._pool
    for process in list(pool._processes.values()):
        process.kill()
        process.join(10)
    posted = trainer.post_session(created.id, make_session(1, 600))
    assert len(posted.created) == 600
