"""A byte-level fuzzer of every route, beside schemathesis (which sends only valid UTF-8 JSON):
each request body is a valid one with one value replaced by raw bytes — lone UTF-16 surrogates,
invalid UTF-8, NaN, huge numbers, deep nesting — and path segments get the same treatment. No
answer may be a 5xx, and afterwards every read route still answers (nothing stored poisons it)."""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

import httpx
import pytest

from backend.server import BackgroundServer
from collie.client import CollieClient

from .conftest import TOKENS, make_run_spec, make_session


@pytest.fixture(scope="module")
def database_url(both_databases: str) -> str:
    """This module runs on SQLite and on a real PostgreSQL server."""
    return both_databases


POISONS: tuple[bytes, ...] = (
    b'"\\ud800"',  # a lone high surrogate, as a JSON escape
    b'"a\\udfffb"',  # a lone low surrogate inside text
    b'"\xed\xa0\x80"',  # a surrogate encoded as UTF-8 bytes (invalid UTF-8)
    b'"\xff\xfe\x80"',  # bytes that are no UTF-8 at all
    b"NaN",
    b"-Infinity",
    b"1e999999",
    b"9" * 5000,  # an integer far beyond any column
    b"4294967296",  # beyond a 32-bit column (PostgreSQL's INTEGER)
    b'"a\\u0000b"',  # NUL, which PostgreSQL text cannot hold
    b"[" * 5000 + b"]" * 5000,  # deep nesting
    b'{"\\ud800": 1}',  # a surrogate as an object key
)


PATH_POISONS = ("%ED%A0%80", "%FF%FE", "%00", "9" * 400, "..%2F..%2Fetc")
PLACEHOLDER = "__POISON__"


def leaves(value: Any, path: tuple[Any, ...] = ()) -> Iterator[tuple[Any, ...]]:
    """Paths to every scalar of a JSON value, and to a new key in every object."""
    if isinstance(value, dict):
        yield (*path, "__new__")
        for key, item in value.items():
            yield from leaves(item, (*path, key))
    elif isinstance(value, list):
        for i, item in enumerate(value[:2]):  # two items are enough to reach every field
            yield from leaves(item, (*path, i))
    else:
        yield path


def replaced(body: Any, path: tuple[Any, ...]) -> str:
    """The body as JSON text with the value at `path` replaced by the placeholder string."""
    copy = json.loads(json.dumps(body))
    target = copy
    for key in path[:-1]:
        target = target[key]
    target[path[-1]] = PLACEHOLDER
    return json.dumps(copy)


def bodies(run_id: int) -> dict[tuple[str, str], Any]:
    """A valid body for every route that takes one."""
    session = make_session(90, 1).model_dump(mode="json")
    session["queries"][0]["extra"] = {"note": "x"}
    rollout = {"skill": [0.1, 0.2], "xy": [[0.0, 0.0], [1.0, 1.0]], "extra": {"k": "v"}}
    return {
        ("POST", "/api/labelers"): {"name": "fuzz", "role": "labeler"},
        ("POST", "/api/runs"): make_run_spec().model_dump(mode="json") | {"config": {"preset": "smoke", "n": 1}},
        ("PUT", f"/api/runs/{run_id}/status"): {"status": "training", "epoch": 1, "message": "m"},
        ("POST", f"/api/runs/{run_id}/feedback-policy"): {"timeout_s": 30.0},
        ("POST", f"/api/runs/{run_id}/sessions"): session,
        ("POST", f"/api/runs/{run_id}/retire"): {"query_ids": ["nope"]},
        ("POST", f"/api/runs/{run_id}/labels"): {"query_id": "0-0", "value": 1, "client_request_id": "r"},
        ("POST", f"/api/runs/{run_id}/undo"): {"query_id": "0-0", "client_request_id": "u"},
        ("POST", f"/api/runs/{run_id}/metrics"): {"epoch": 1, "values": {"loss": 0.5}},
        ("POST", f"/api/runs/{run_id}/rollouts"): {"epoch": 1, "rollouts": [rollout]},
    }


@pytest.fixture(scope="module")
def run_id(live: BackgroundServer) -> int:
    with CollieClient(live.url, TOKENS["trainer"]) as trainer:
        created = trainer.create_run(make_run_spec())
        trainer.post_session(created.id, make_session(0, 2))
        return created.id


def every_read(client: httpx.Client, run_id: int) -> list[str]:
    """The read routes with real ids: what a stored bad value would break for good."""
    paths = [
        "/api/runs",
        f"/api/runs/{run_id}",
        f"/api/runs/{run_id}/queries",
        f"/api/runs/{run_id}/queries/90-0",
        f"/api/runs/{run_id}/labels",
        f"/api/runs/{run_id}/labels/effective",
        f"/api/runs/{run_id}/export",
        f"/api/runs/{run_id}/metrics",
        f"/api/runs/{run_id}/rollouts",
        f"/api/runs/{run_id}/events",
        f"/api/runs/{run_id}/labelled",
        "/api/labelers",
        "/api/dashboard/runs",
        f"/api/dashboard/runs/{run_id}",
        f"/api/dashboard/runs/{run_id}/metrics",
        f"/api/dashboard/runs/{run_id}/labeling",
    ]
    return [f"GET {p}: {r.status_code}" for p in paths if (r := client.get(p)).status_code >= 500]


def test_no_body_byte_gives_a_server_error(live: BackgroundServer, run_id: int) -> None:
    failures = []
    headers = {"Authorization": f"Bearer {TOKENS['operator']}", "Content-Type": "application/json"}
    with httpx.Client(base_url=live.url, headers=headers, timeout=30) as client:
        for (method, path), body in bodies(run_id).items():
            targets = [(), *leaves(body)]
            for target in targets:
                text = replaced(body, target) if target else json.dumps(PLACEHOLDER)
                for poison in POISONS:
                    raw = text.encode().replace(f'"{PLACEHOLDER}"'.encode(), poison)
                    response = client.request(method, path, content=raw)
                    if response.status_code >= 500:
                        failures.append(f"{method} {path} {target} {poison[:20]!r}: {response.status_code}")
                    else:
                        response.json()  # an answer, and one that decodes
        failures += every_read(client, run_id)
    assert not failures, "\n".join(failures[:30])


def test_no_path_or_query_byte_gives_a_server_error(live: BackgroundServer, run_id: int) -> None:
    paths = [p for (_, p) in bodies(run_id)] + [
        f"/api/runs/{run_id}/queries/QID",
        f"/api/runs/{run_id}/queries/QID/release",
        "/api/labelers/QID",
    ]
    failures = []
    headers = {"Authorization": f"Bearer {TOKENS['operator']}"}
    with httpx.Client(base_url=live.url, headers=headers, timeout=30) as client:
        for poison in PATH_POISONS:
            for path in paths:
                bad = path.replace(str(run_id), poison, 1) if "QID" not in path else path.replace("QID", poison)
                for method in ("GET", "POST", "DELETE"):
                    response = client.request(method, bad)
                    if response.status_code >= 500:
                        failures.append(f"{method} {bad}: {response.status_code}")
            for query in (f"status={poison}", f"after={poison}", f"limit={poison}", f"session={poison}"):
                for path in (f"/api/runs/{run_id}/queries", f"/api/runs/{run_id}/events", "/api/runs"):
                    response = client.get(f"{path}?{query}")
                    if response.status_code >= 500:
                        failures.append(f"GET {path}?{query}: {response.status_code}")
        failures += every_read(client, run_id)
    assert not failures, "\n".join(failures[:30])


@pytest.mark.parametrize(
    ("method", "path", "body"),
    [
        ("POST", "/api/runs", {"config": {"k": "\ud800"}}),
        ("POST", "/api/runs", {"config": {"\udfff": 1}}),
        ("POST", "/api/runs/{run}/metrics", {"epoch": 1, "values": {"\ud800": 1.0}}),
        ("PUT", "/api/runs/{run}/status", {"status": "training", "message": "\ud800"}),
        (
            "POST",
            "/api/runs/{run}/rollouts",
            {"epoch": 1, "rollouts": [{"skill": [0.0], "xy": [], "extra": {"x": "\ud800"}}]},
        ),
    ],
)
def test_surrogates_are_refused_and_never_stored(
    live: BackgroundServer, run_id: int, method: str, path: str, body: dict[str, Any]
) -> None:
    if path == "/api/runs":
        body = make_run_spec().model_dump(mode="json") | body
    headers = {"Authorization": f"Bearer {TOKENS['operator']}", "Content-Type": "application/json"}
    raw = json.dumps(body).encode()  # ensure_ascii: the surrogate travels as a \\u escape
    response = httpx.request(method, live.url + path.format(run=run_id), content=raw, headers=headers, timeout=30)
    assert response.status_code == 422, response.text
    with httpx.Client(base_url=live.url, headers=headers, timeout=30) as client:
        assert every_read(client, run_id) == []
