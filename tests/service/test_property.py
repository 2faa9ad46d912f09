"""Property-based requests generated from the OpenAPI schema (schemathesis, on Hypothesis): with
an operator token every request reaches its handler, and none may answer 5xx."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
import schemathesis
from hypothesis import HealthCheck, settings
from schemathesis import Case

from backend.main import create_app
from backend.server import BackgroundServer
from backend.settings import Settings
from collie.client import CollieClient

from .conftest import TOKENS, make_run_spec, make_session, settings_for

pytestmark = pytest.mark.slow  # run first under `make test`'s two workers (tests/conftest.py)


@pytest.fixture(scope="module")
def fuzzed(both_databases: str) -> Iterator[BackgroundServer]:
    """A service of its own (on SQLite, then on PostgreSQL), with a few runs and queries for
    generated ids to hit."""
    with BackgroundServer(create_app(settings_for(both_databases))) as server:
        with CollieClient(server.url, TOKENS["trainer"]) as trainer:
            for _ in range(3):
                run = trainer.create_run(make_run_spec())
                trainer.post_session(run.id, make_session(0, 3))
        yield server


# The schema of the app itself (an in-memory database is enough to build it). The SSE stream never
# ends by design; test_stream.py covers it.
schema = schemathesis.openapi.from_dict(create_app(Settings(database_url="sqlite://")).openapi()).exclude(
    path_regex=r"/stream$"
)


@schema.parametrize()
@settings(max_examples=10, deadline=None, suppress_health_check=list(HealthCheck))
def test_no_server_errors(case: Case, fuzzed: BackgroundServer) -> None:
    if case.query and "wait_s" in case.query:
        case.query["wait_s"] = 0  # a long poll would only make the test slow
    if case.path_parameters and case.path_parameters.get("labeler_id") in (1, 2, 3):
        case.path_parameters["labeler_id"] = 99  # keep the bootstrap tokens alive for the next cases
    headers = {"Authorization": f"Bearer {TOKENS['operator']}"}
    response = case.call(base_url=fuzzed.url, headers=headers, timeout=30)
    assert response.status_code < 500, f"{case.method} {case.formatted_path}: {response.text[:500]}"
