"""Every endpoint × every role: no or unknown token → 401, a role that may not → 403, and the roles
that may get past authorisation. The table is the policy; a route missing from it fails the test."""

from __future__ import annotations

import httpx
import pytest
from sqlalchemy import select

from backend.models import Principal
from backend.server import BackgroundServer
from collie.client import CollieClient

from .conftest import TOKENS


@pytest.fixture(scope="module")
def database_url(both_databases: str) -> str:
    """This module runs on SQLite and on a real PostgreSQL server."""
    return both_databases


PUBLIC, ANY, TRAINER, LABELER, OPERATOR = "public", "any", "trainer", "labeler", "operator"

POLICY: dict[tuple[str, str], str] = {
    ("GET", "/api/health"): PUBLIC,
    ("GET", "/api/me"): ANY,
    ("POST", "/api/labelers"): OPERATOR,
    ("GET", "/api/labelers"): OPERATOR,
    ("DELETE", "/api/labelers/{labeler_id}"): OPERATOR,
    ("PUT", "/api/labelers/{labeler_id}/runs"): OPERATOR,
    ("POST", "/api/runs"): TRAINER,
    ("GET", "/api/runs"): ANY,
    ("GET", "/api/runs/{run_id}"): ANY,
    ("PUT", "/api/runs/{run_id}/status"): TRAINER,
    ("POST", "/api/runs/{run_id}/extend"): TRAINER,
    ("POST", "/api/runs/{run_id}/pause"): OPERATOR,
    ("POST", "/api/runs/{run_id}/resume"): OPERATOR,
    ("POST", "/api/runs/{run_id}/stop"): OPERATOR,
    ("POST", "/api/runs/{run_id}/feedback-policy"): OPERATOR,
    ("PUT", "/api/runs/{run_id}/quality"): OPERATOR,
    ("POST", "/api/runs/{run_id}/sessions"): TRAINER,
    ("POST", "/api/runs/{run_id}/retire"): TRAINER,
    ("GET", "/api/runs/{run_id}/queries"): ANY,
    ("GET", "/api/runs/{run_id}/queries/{query_id}"): ANY,
    ("POST", "/api/runs/{run_id}/claim"): LABELER,
    ("POST", "/api/runs/{run_id}/queries/{query_id}/release"): LABELER,
    ("GET", "/api/runs/{run_id}/labelled"): TRAINER,
    ("POST", "/api/runs/{run_id}/labels"): LABELER,
    ("POST", "/api/runs/{run_id}/undo"): LABELER,
    ("POST", "/api/runs/{run_id}/labelers/{labeler_id}/discard"): OPERATOR,
    ("GET", "/api/runs/{run_id}/labels"): ANY,
    ("GET", "/api/runs/{run_id}/labels/effective"): ANY,
    ("GET", "/api/runs/{run_id}/labels/mine"): LABELER,
    ("PUT", "/api/runs/{run_id}/instructions"): OPERATOR,
    ("GET", "/api/runs/{run_id}/export"): TRAINER,
    ("POST", "/api/runs/{run_id}/metrics"): TRAINER,
    ("GET", "/api/runs/{run_id}/metrics"): ANY,
    ("POST", "/api/runs/{run_id}/rollouts"): TRAINER,
    ("GET", "/api/runs/{run_id}/rollouts"): ANY,
    ("GET", "/api/runs/{run_id}/events"): ANY,
    ("GET", "/api/runs/{run_id}/stream"): ANY,
    # the operators' dashboard (backend/routes/dashboard.py): read-only views
    ("GET", "/api/dashboard/runs"): ANY,
    ("GET", "/api/dashboard/runs/{run_id}"): ANY,
    ("GET", "/api/dashboard/runs/{run_id}/metrics"): ANY,
    ("GET", "/api/dashboard/runs/{run_id}/labeling"): ANY,
    ("GET", "/api/dashboard/runs/{run_id}/queries/{query_id}/review"): OPERATOR,
}


def allowed(policy: str, role: str) -> bool:
    return policy in (PUBLIC, ANY) or role in ("operator", policy)


def test_policy_covers_every_route(live: BackgroundServer) -> None:
    paths = live.app.openapi()["paths"]
    assert {(method.upper(), path) for path, ops in paths.items() for method in ops} == set(POLICY)


def test_the_schema_documents_the_refusals_a_client_meets(live: BackgroundServer) -> None:
    """Was: /openapi.json listed 200/201/204/422 only, so a client written from it knew of no 401,
    403, 404 or 409, nor of the typed NotHeld and OutOfScope bodies."""
    paths = live.app.openapi()["paths"]
    for (method, path), policy in POLICY.items():
        answers = paths[path][method.lower()]["responses"]
        assert policy == PUBLIC or {"401", "403", "404"} <= set(answers), (method, path)
    assert "409" in paths["/api/runs/{run_id}/claim"]["post"]["responses"]
    conflict = paths["/api/runs/{run_id}/labels"]["post"]["responses"]["409"]["content"]["application/json"]
    assert {"$ref": "#/components/schemas/NotHeld"} in conflict["schema"]["anyOf"]
    forbidden = paths["/api/runs/{run_id}/labels"]["post"]["responses"]["403"]["content"]["application/json"]
    assert {"$ref": "#/components/schemas/OutOfScope"} in forbidden["schema"]["anyOf"]


CASES = [(m, p, who) for (m, p) in POLICY for who in ("none", "wrong", "operator", "trainer", "labeler")]


@pytest.mark.parametrize(("method", "path", "who"), CASES, ids=[f"{m} {p} {w}" for m, p, w in CASES])
def test_matrix(live: BackgroundServer, method: str, path: str, who: str) -> None:
    # Ids that exist nowhere: an allowed caller gets past auth to a 404/422, and nothing changes.
    url = live.url + path.format(run_id=987654, query_id="nope", labeler_id=987654)
    headers = {}
    if who != "none":
        headers["Authorization"] = f"Bearer {TOKENS.get(who, 'not-a-real-token')}"
    body = {"name": f"matrix-{who}", "role": "labeler"} if path == "/api/labelers" else {}
    response = httpx.request(method, url, headers=headers, json=body if method in ("POST", "PUT") else None)
    policy = POLICY[(method, path)]
    if policy == PUBLIC:
        assert response.status_code == 200
    elif who in ("none", "wrong"):
        assert response.status_code == 401 and response.headers["www-authenticate"] == "Bearer"
    elif allowed(policy, who):
        assert response.status_code not in (401, 403), response.text
        assert response.status_code < 500
    else:
        assert response.status_code == 403, response.text


def test_revoked_token_is_refused(live: BackgroundServer, operator: CollieClient) -> None:
    created = operator.create_labeler("to-be-revoked")
    with CollieClient(live.url, created.token) as client:
        assert client.me().name == "to-be-revoked"
        assert operator.revoke(created.id).revoked
        response = httpx.get(f"{live.url}/api/me", headers={"Authorization": f"Bearer {created.token}"})
        assert response.status_code == 401


def test_tokens_are_stored_hashed(live: BackgroundServer, operator: CollieClient) -> None:
    created = operator.create_labeler("hash-check")
    with live.app.state.db.read() as conn:
        rows = conn.execute(select(Principal)).all()
    assert rows and not any(created.token in str(value) for row in rows for value in row)
    url = live.app.state.settings.database_url
    if url.startswith("sqlite:///"):  # nor anywhere in the file
        assert created.token.encode() not in open(url.removeprefix("sqlite:///"), "rb").read()  # noqa: SIM115
