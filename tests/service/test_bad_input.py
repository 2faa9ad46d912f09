"""Bad input gets a clear 4xx and leaves nothing half-written."""

from __future__ import annotations

import json
import logging
import os
import socket
import sqlite3
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import httpx
import pytest

from backend.main import create_app
from backend.server import BackgroundServer
from collie.client import ApiError, CollieClient
from collie.schemas import EnvDims, MetricsIn, RunRead

from .conftest import DIMS, TOKENS, make_run_spec, make_session, settings_for


@pytest.fixture(scope="module")
def database_url(both_databases: str) -> str:
    """This module runs on SQLite and on a real PostgreSQL server."""
    return both_databases


def post(url: str, role: str, path: str, **kwargs: object) -> httpx.Response:
    headers = {"Authorization": f"Bearer {TOKENS[role]}", **kwargs.pop("headers", {})}  # type: ignore[dict-item]
    return httpx.post(url + path, headers=headers, timeout=30, **kwargs)  # type: ignore[arg-type]


def snapshot(client: CollieClient, run_id: int) -> tuple[object, ...]:
    run = client.run(run_id)
    return run.queue, run.n_labels, run.last_event_id, len(client.label_events(run_id))


@pytest.mark.parametrize("value", [3, -1, "good", "1", True, 1.0, None, [1]])
def test_label_value_out_of_range(live: BackgroundServer, labeler: CollieClient, run: RunRead, value: object) -> None:
    labeler.claim(run.id)
    before = snapshot(labeler, run.id)
    body = {"query_id": "0-0", "value": value, "client_request_id": "x1"}
    response = post(live.url, "labeler", f"/api/runs/{run.id}/labels", json=body)
    assert response.status_code == 422
    # one error, in words, whatever the value (was: for "good" or -1 a second one, "Input should be
    # 'skip'", at a location naming pydantic's validators)
    (error,) = response.json()["detail"]
    assert error["loc"] == ["body", "value"], error
    assert error["msg"] == f"Value error, a label is the integer 0, 1 or 2, or the string 'skip'; got {value!r}"
    assert snapshot(labeler, run.id) == before


def test_unknown_ids(labeler: CollieClient, run: RunRead) -> None:
    for call in (
        lambda: labeler.run(987654),
        lambda: labeler.claim(987654),
        lambda: labeler.query(run.id, "no-such-query"),
        lambda: labeler.submit(run.id, "no-such-query", 1),
        lambda: labeler.submit(987654, "0-0", 1),
        lambda: labeler.undo(run.id, "no-such-query"),
        lambda: labeler.events(987654),
    ):
        with pytest.raises(ApiError) as err:
            call()
        assert err.value.status == 404 and "no " in str(err.value.detail)


@pytest.mark.parametrize("raw", ["%C2%B2", "%D9%A3", "99999999999999999999", "-1", "1" * 5000])  # 5000: past int()
@pytest.mark.parametrize("role", ["operator", "trainer", "labeler"])
def test_a_run_id_that_is_no_id_is_a_422(live: BackgroundServer, raw: str, role: str) -> None:
    """Run ids "²" and "٣" are digits to str.isdigit but no int; a number past MAX_INT fits no column. Was:
    500 from the scope check, which reads the path's run id before the route validates it."""
    headers = {"Authorization": f"Bearer {TOKENS[role]}"}
    for method, path in (("GET", "queries"), ("POST", "claim"), ("GET", "events")):
        answer = httpx.request(method, f"{live.url}/api/runs/{raw}/{path}", headers=headers, timeout=30)
        refused_role = role == "trainer" and path == "claim"  # a trainer may not claim: 403 before the path is read
        assert answer.status_code == (403 if refused_role else 422), (method, path, answer.status_code, answer.text)


@pytest.mark.parametrize("value", ["nan", "inf", "-inf"])
def test_a_wait_or_lease_that_is_no_number_says_so(live: BackgroundServer, run: RunRead, value: str) -> None:
    """Was: "Input should be less than or equal to 60" for wait_s=nan."""
    headers = {"Authorization": f"Bearer {TOKENS['operator']}"}
    for method, path in (
        ("GET", f"/api/runs/{run.id}/events?wait_s={value}"),
        ("GET", f"/api/dashboard/runs?wait_s={value}"),
        ("POST", f"/api/runs/{run.id}/claim?lease_s={value}"),
    ):
        answer = httpx.request(method, live.url + path, headers=headers, timeout=30)
        assert answer.status_code == 422 and "finite number" in answer.text, (path, answer.text)


def test_label_for_another_runs_query(trainer: CollieClient, labeler: CollieClient, run: RunRead) -> None:
    other = trainer.create_run(make_run_spec())
    trainer.post_session(other.id, make_session(7, 1))
    claim = labeler.claim(other.id)
    assert claim is not None and claim.query.query_id == "7-0"
    before = snapshot(labeler, run.id)
    with pytest.raises(ApiError) as err:
        labeler.submit(run.id, "7-0", 1)  # that id lives in the other run only
    assert err.value.status == 404
    with pytest.raises(ApiError) as err:
        labeler.submit(run.id, "0-1", 1)  # exists here, but this labeler holds no lease on it here
    assert err.value.status == 409
    assert snapshot(labeler, run.id) == before


def test_label_on_a_query_leased_to_someone_else(
    labeler: CollieClient, new_labeler: Callable[[str], CollieClient], run: RunRead
) -> None:
    claim = labeler.claim(run.id)
    intruder = new_labeler("intruder")
    before = snapshot(labeler, run.id)
    for call in (
        lambda: intruder.submit(run.id, claim.query.query_id, 0),
        lambda: intruder.skip(run.id, claim.query.query_id),
    ):
        with pytest.raises(ApiError) as err:
            call()
        assert err.value.status == 409 and "leased to someone else" in err.value.detail
    assert snapshot(labeler, run.id) == before


@pytest.mark.parametrize("body", [b"{not json", b'{"query_id": "0-0", "value": 1', b"", b"[]", b'"x"'])
def test_malformed_json(live: BackgroundServer, labeler: CollieClient, run: RunRead, body: bytes) -> None:
    before = snapshot(labeler, run.id)
    response = post(
        live.url, "labeler", f"/api/runs/{run.id}/labels", content=body, headers={"Content-Type": "application/json"}
    )
    assert response.status_code == 422 and response.json()["detail"]
    assert snapshot(labeler, run.id) == before


def test_unknown_fields_and_bad_ids_are_refused(live: BackgroundServer, run: RunRead) -> None:
    body = {"query_id": "0-0", "value": 1, "client_request_id": "a", "extra": 1}
    assert post(live.url, "labeler", f"/api/runs/{run.id}/labels", json=body).status_code == 422
    body = {"query_id": "../etc", "value": 1, "client_request_id": "a"}
    assert post(live.url, "labeler", f"/api/runs/{run.id}/labels", json=body).status_code == 422
    assert post(live.url, "labeler", "/api/runs/abc/claim").status_code == 422


def test_oversize_bodies(live: BackgroundServer, labeler: CollieClient, run: RunRead) -> None:
    before = snapshot(labeler, run.id)
    big = {"query_id": "0-0", "value": 1, "client_request_id": "x" * (2 * 1024 * 1024)}
    response = post(live.url, "labeler", f"/api/runs/{run.id}/labels", json=big)
    assert response.status_code == 413 and "larger than" in response.json()["detail"]

    def chunks() -> Iterator[bytes]:  # no Content-Length: counted while read
        yield b'{"query_id": "0-0", "value": 1, "client_request_id": "'
        for _ in range(40):
            yield b"y" * 65536
        yield b'"}'

    response = post(
        live.url,
        "labeler",
        f"/api/runs/{run.id}/labels",
        content=chunks(),
        headers={"Content-Type": "application/json"},
    )
    assert response.status_code == 413
    assert snapshot(labeler, run.id) == before


@pytest.fixture(scope="module")
def tight(tmp_path_factory: pytest.TempPathFactory) -> Iterator[BackgroundServer]:
    """A service with small limits, to reach them cheaply."""
    settings = settings_for(
        tmp_path_factory.mktemp("tight") / "t.db", max_session_bytes=200_000, max_queries_per_session=5
    )
    with BackgroundServer(create_app(settings)) as server:
        yield server


def test_session_limits(tight: BackgroundServer) -> None:
    with CollieClient(tight.url, TOKENS["trainer"]) as trainer:
        created = trainer.create_run(make_run_spec())
        with pytest.raises(ApiError) as err:
            trainer.post_session(created.id, make_session(0, 6))
        assert err.value.status == 422 and "at most 5" in err.value.detail
        big = make_session(0, 1, EnvDims(obs_dim=4000, nq=2, nv=2, horizon=5, skill_dim=2))
        with pytest.raises(ApiError) as err:
            trainer.post_session(created.id, big)
        assert err.value.status == 413
        assert trainer.run(created.id).queue.pending == 0


@pytest.mark.parametrize("bad", ["NaN", "Infinity", "-Infinity", "1e999"])
def test_non_finite_arrays(live: BackgroundServer, trainer: CollieClient, bad: str) -> None:
    created = trainer.create_run(make_run_spec())
    session = make_session(0, 3).model_dump(mode="json")
    session["queries"][2]["obs"][1][0] = "__BAD__"
    text = json.dumps(session).replace('"__BAD__"', bad)
    response = post(
        live.url,
        "trainer",
        f"/api/runs/{created.id}/sessions",
        content=text,
        headers={"Content-Type": "application/json"},
    )
    assert response.status_code == 422 and "finite" in response.text
    assert trainer.run(created.id).queue.pending == 0  # not even the two good queries


@pytest.mark.parametrize(
    ("field", "change", "words"),
    [
        ("obs", lambda q: q["obs"][0].append(0.5), "unequal length"),
        ("obs", lambda q: [row.append(0.5) for row in q["obs"]], "width 5, run expects 4"),
        ("qpos", lambda q: q["qpos"].pop(), "qpos has 4 frames"),
        ("xy", lambda q: [row.append(0.0) for row in q["xy"]], "2 columns"),
        ("skill", lambda q: q["skill"].append(1.0), "skill has 3 dims"),
        ("all", lambda q: [q[k].pop() for k in ("obs", "xy", "pitch", "qpos", "qvel")], "H=5"),
    ],
)
def test_segment_shapes_must_match_the_run(
    live: BackgroundServer, trainer: CollieClient, field: str, change: Callable[[dict], object], words: str
) -> None:
    created = trainer.create_run(make_run_spec())
    session = make_session(0, 3).model_dump(mode="json")
    change(session["queries"][1])
    response = post(live.url, "trainer", f"/api/runs/{created.id}/sessions", json=session)
    assert response.status_code == 422 and words in response.text, response.text
    assert trainer.run(created.id).queue.pending == 0


def test_repeated_query_ids_in_one_session(live: BackgroundServer, trainer: CollieClient) -> None:
    created = trainer.create_run(make_run_spec())
    session = make_session(0, 2).model_dump(mode="json")
    session["queries"][1]["query_id"] = session["queries"][0]["query_id"]
    response = post(live.url, "trainer", f"/api/runs/{created.id}/sessions", json=session)
    assert response.status_code == 422 and "repeat" in response.text


def test_run_spec_is_validated(live: BackgroundServer) -> None:
    spec = make_run_spec().model_dump(mode="json")
    for change in (
        lambda s: s["dims"].update(obs_dim=0),
        lambda s: s.update(env="point; drop table runs"),
        lambda s: s.update(config={"x": "y" * 70_000}),
        lambda s: s.pop("dims"),
    ):
        bad = json.loads(json.dumps(spec))
        change(bad)
        assert post(live.url, "trainer", "/api/runs", json=bad).status_code == 422


def test_a_run_whose_dims_are_not_its_envs_is_refused(live: BackgroundServer) -> None:
    """Was 201: the labeling UI, which replays the env's model, then failed every segment."""
    spec = make_run_spec().model_dump(mode="json")
    for env, dims, said in (
        ("humanoid", {"nq": 2}, "dims nq 2, nv 2 are not humanoid's (nq 28, nv 27)"),
        ("point", {"nv": 3}, "dims nq 2, nv 3 are not point's (nq 2, nv 2)"),
    ):
        body = {**spec, "env": env, "task": "north", "dims": {**spec["dims"], **dims}}
        response = post(live.url, "trainer", "/api/runs", json=body)
        assert response.status_code == 422 and said in response.text, response.text


RULE = {
    "name": "pit",
    "description": "Keep out of the pit.",
    "meaning": {"bad": "in the pit"},
    "regions": [{"kind": "disc", "desirability": 0, "centre": [0, 0], "radius": 1, "name": "pit"}],
    "source": "pit.toml",
}


@pytest.mark.parametrize(
    "change",
    [
        lambda d: d.update(description="Keep out\x00"),
        lambda d: d["meaning"].update(bad="in\x00the pit"),
        lambda d: d["regions"][0].update(name="p\x00t"),
        lambda d: d.update(source="pit\x00.toml"),
    ],
)
def test_a_nul_in_a_rules_text_is_refused_as_in_other_free_text(live: BackgroundServer, change: Callable) -> None:
    """Was 201 (free text elsewhere, an instruction for one, refuses it: PostgreSQL text cannot hold it)."""
    rule = json.loads(json.dumps(RULE))
    change(rule)
    body = {**make_run_spec(task="pit").model_dump(mode="json"), "task_definition": rule}
    response = post(live.url, "trainer", "/api/runs", json=body)
    assert response.status_code == 422 and "NUL character" in response.text, response.text


def test_a_nul_in_a_status_message_is_refused(live: BackgroundServer, trainer: CollieClient) -> None:
    created = trainer.create_run(make_run_spec())
    body = {"status": "failed", "epoch": 1, "message": "diverged\x00"}
    response = httpx.put(
        f"{live.url}/api/runs/{created.id}/status", json=body, headers={"Authorization": f"Bearer {TOKENS['trainer']}"}
    )
    assert response.status_code == 422 and "NUL character" in response.text, response.text
    assert trainer.run(created.id).status == "training"


@pytest.mark.parametrize(
    ("path", "body"),
    [
        ("metrics", {"epoch": 1, "values": {"loss\x00": 1.0}}),
        ("rollouts", {"epoch": 1, "rollouts": [{"skill": [1.0], "xy": [[0.0, 0.0]], "extra": {"k": ["a\x00"]}}]}),
        ("rollouts", {"epoch": 1, "rollouts": [{"skill": [1.0], "xy": [[0.0, 0.0]], "extra": {"k\x00": 1}}]}),
        ("", {"config": {"notes": {"who": "me\x00"}}}),
        ("", {"config": {"a\x00": 1}}),
    ],
)
def test_a_nul_in_json_a_run_stores_is_refused(
    live: BackgroundServer, trainer: CollieClient, path: str, body: dict
) -> None:
    """Metric names, a run's config and a rollout's extra are stored as JSON; PostgreSQL's JSON
    cannot hold \\u0000 either. Was: 201 on SQLite, and a 500 on PostgreSQL."""
    created = trainer.create_run(make_run_spec())
    if not path:
        body = {**make_run_spec().model_dump(mode="json"), **body}
    response = post(live.url, "trainer", f"/api/runs/{created.id}/{path}" if path else "/api/runs", json=body)
    assert response.status_code == 422 and "NUL character" in response.text, response.text


def test_rollout_states_of_another_width_than_the_runs_env_are_refused(
    live: BackgroundServer, trainer: CollieClient
) -> None:
    """Was 201: the labeling UI's watch mode then replayed states of no joint layout of the run's env."""
    created = trainer.create_run(make_run_spec())
    fits = {"skill": [1.0, 0.0], "xy": [[0.0, 0.0]], "qpos": [[0.0] * DIMS.nq]}
    for qpos in ([[0.0] * (DIMS.nq + 1)], [[]]):
        body = {"epoch": 1, "rollouts": [fits, {**fits, "qpos": qpos}]}
        response = post(live.url, "trainer", f"/api/runs/{created.id}/rollouts", json=body)
        assert response.status_code == 422, response.text
        assert f"rollout 1: qpos width {len(qpos[0])}" in response.text and f"nq {DIMS.nq}" in response.text
    assert trainer.rollouts(created.id) == []
    assert (
        post(live.url, "trainer", f"/api/runs/{created.id}/rollouts", json={"epoch": 1, "rollouts": [fits]}).status_code
        == 201
    )


def test_database_stays_consistent(tmp_path: Path) -> None:
    """After a burst of refused requests the effective labels recomputed from the event log equal
    the cached ones."""
    with BackgroundServer(create_app(settings_for(tmp_path / "c.db"))) as server:
        trainer = CollieClient(server.url, TOKENS["trainer"])
        labeler = CollieClient(server.url, TOKENS["labeler"])
        created = trainer.create_run(make_run_spec())
        trainer.post_session(created.id, make_session(0, 5))
        for i in range(5):
            claim = labeler.claim(created.id)
            labeler.submit(created.id, claim.query.query_id, i % 3)
            for bad in (5, "x"):
                post(
                    server.url,
                    "labeler",
                    f"/api/runs/{created.id}/labels",
                    json={"query_id": claim.query.query_id, "value": bad, "client_request_id": f"b{i}{bad}"},
                )
        labeler.undo(created.id, "0-2")
        cached = {q.query_id: q.label for q in trainer.queries(created.id) if q.label is not None}
        assert {e.query_id: e.label for e in trainer.effective_labels(created.id)} == cached
        assert trainer.run(created.id).n_labels == len(cached) == 4
        trainer.close()
        labeler.close()
    assert DIMS.horizon == 5


def test_a_body_cut_short_is_no_error_in_the_log(
    live: BackgroundServer, labeler: CollieClient, run: RunRead, caplog: pytest.LogCaptureFixture
) -> None:
    """A client that announces 100 bytes, sends 11 and hangs up: the service logs no traceback."""
    host, port = live.url.removeprefix("http://").split(":")
    head = (
        f"POST /api/runs/{run.id}/labels HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {TOKENS['labeler']}\r\n"
        "Content-Type: application/json\r\nContent-Length: 100\r\n\r\n"
    )
    with caplog.at_level(logging.ERROR), socket.create_connection((host, int(port)), timeout=10) as sock:
        sock.sendall(head.encode() + b'{"query_id"')
        sock.shutdown(socket.SHUT_WR)
        sock.recv(1000)
    assert labeler.run(run.id).id == run.id  # still serving
    time.sleep(0.2)
    assert not [r for r in caplog.records if r.levelno >= logging.ERROR], caplog.text


def resident_mb() -> float:
    return int(Path("/proc/self/statm").read_text().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def test_a_body_announced_but_not_sent_holds_no_memory(live: BackgroundServer, run: RunRead) -> None:
    """30 clients announce 16 MB of rollouts each (the route's limit) and send one byte. Was: the
    service reserved each announced body up front, 480 MB held by clients that sent nothing (the
    service runs in this process: its memory is ours)."""
    host, port = live.url.removeprefix("http://").split(":")
    head = (
        f"POST /api/runs/{run.id}/rollouts HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {TOKENS['trainer']}\r\n"
        "Content-Type: application/json\r\nContent-Length: 16000000\r\n\r\n{"
    )
    before = resident_mb()
    socks = [socket.create_connection((host, int(port)), timeout=10) for _ in range(30)]
    try:
        for sock in socks:
            sock.sendall(head.encode())
        time.sleep(1.0)  # each request is in its route, reading the body
        grown = resident_mb() - before
    finally:
        for sock in socks:
            sock.close()
    assert grown < 100, f"{grown:.0f} MB held for bodies not sent"
    assert httpx.get(f"{live.url}/api/health", timeout=10).status_code == 200


def test_a_database_locked_by_another_process_is_a_503_to_retry(tmp_path: Path) -> None:
    """Another process holds SQLite's write lock past the busy timeout: a JSON 503 with Retry-After,
    nothing written, and the service answers again once the lock is gone."""
    settings = settings_for(tmp_path / "locked.db")
    with BackgroundServer(create_app(settings)) as server, CollieClient(server.url, TOKENS["trainer"]) as trainer:
        run = trainer.create_run(make_run_spec())
        holder = sqlite3.connect(tmp_path / "locked.db", isolation_level=None, timeout=10)
        holder.execute("BEGIN IMMEDIATE")
        try:
            response = post(
                server.url, "trainer", f"/api/runs/{run.id}/metrics", json={"epoch": 1, "values": {"a": 1.0}}
            )
        finally:
            holder.execute("ROLLBACK")
            holder.close()
        assert response.status_code == 503 and response.headers["retry-after"] == "5"
        assert "busy" in response.json()["detail"]
        assert trainer.metrics(run.id) == []
        trainer.post_metrics(run.id, MetricsIn(epoch=1, values={"a": 1.0}))
        assert len(trainer.metrics(run.id)) == 1
