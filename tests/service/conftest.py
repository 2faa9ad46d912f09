"""A real service for the tests: uvicorn on an ephemeral 127.0.0.1 port over a SQLite file, or a
real PostgreSQL server (tests/service/postgres.py) in the modules that run on both databases."""

from __future__ import annotations

import json
import logging
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from sqlalchemy import Connection

from backend.main import create_app
from backend.server import BackgroundServer
from backend.settings import Settings
from collie.client import CollieClient
from collie.schemas import EnvDims, QueryIn, RunCreate, RunRead, SessionPost

from .postgres import PostgresServer

TOKENS = {"operator": "op-token-0123456789", "trainer": "tr-token-0123456789", "labeler": "lb-token-0123456789"}
DIMS = EnvDims(obs_dim=4, nq=2, nv=2, horizon=5, skill_dim=2)  # a point run's joints (nq, nv)


DATABASES = ("sqlite", "postgresql")


def settings_for(db: Path | str, **overrides: object) -> Settings:
    """A SQLite file (a path) or any database URL (a str), with the bootstrap tokens."""
    return Settings(
        database_url=db if isinstance(db, str) else f"sqlite:///{db}",
        operator_token=TOKENS["operator"],
        trainer_token=TOKENS["trainer"],
        labeler_token=TOKENS["labeler"],
        **overrides,  # type: ignore[arg-type]
    )


class Records(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.DEBUG)
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)


@pytest.fixture
def logged() -> Iterator[list[logging.LogRecord]]:
    """What the service and uvicorn log (uvicorn's loggers do not propagate to the root)."""
    handler = Records()
    loggers = [logging.getLogger(name) for name in ("uvicorn.error", "collie.service")]
    for logger in loggers:
        logger.addHandler(handler)
    yield handler.records
    for logger in loggers:
        logger.removeHandler(handler)


def next_data(lines: Iterator[str]) -> dict[str, Any]:
    """The next SSE event's data, from a stream's lines."""
    return json.loads(next(line for line in lines if line.startswith("data: "))[len("data: ") :])


@pytest.fixture(scope="session")
def postgres() -> Iterator[PostgresServer]:
    """One real PostgreSQL server for the session (started on first use)."""
    server = PostgresServer().start()
    yield server
    server.stop()


def new_database_url(kind: str, request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> str:
    """A fresh, empty database of `kind` ("sqlite" or "postgresql")."""
    if kind == "postgresql":
        return request.getfixturevalue("postgres").new_database()
    return f"sqlite:///{tmp_path_factory.mktemp('svc') / 'collie.db'}"


@pytest.fixture(scope="module")
def database_url(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> str:
    """SQLite; a module that runs on both databases overrides this with `both_databases`:
    `database_url = both_databases` (params over DATABASES)."""
    return new_database_url("sqlite", request, tmp_path_factory)


@pytest.fixture(scope="module", params=DATABASES)
def both_databases(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> str:
    return new_database_url(request.param, request, tmp_path_factory)


@pytest.fixture(scope="module")
def live(database_url: str) -> Iterator[BackgroundServer]:
    with BackgroundServer(create_app(settings_for(database_url))) as server:
        yield server


@pytest.fixture(scope="module")
def operator(live: BackgroundServer) -> Iterator[CollieClient]:
    with CollieClient(live.url, TOKENS["operator"]) as client:
        yield client


@pytest.fixture(scope="module")
def trainer(live: BackgroundServer) -> Iterator[CollieClient]:
    with CollieClient(live.url, TOKENS["trainer"]) as client:
        yield client


@pytest.fixture(scope="module")
def labeler(live: BackgroundServer) -> Iterator[CollieClient]:
    with CollieClient(live.url, TOKENS["labeler"]) as client:
        yield client


@pytest.fixture(scope="module")
def new_labeler(live: BackgroundServer, operator: CollieClient) -> Iterator[Callable[[str], CollieClient]]:
    """Another labeler with a token of their own."""
    made: list[CollieClient] = []

    def make(name: str) -> CollieClient:
        created = operator.create_labeler(name)
        made.append(CollieClient(live.url, created.token))
        return made[-1]

    yield make
    for client in made:
        client.close()


def database_at(path: Path, revision: str, task: str, more: Callable[[Connection], object] = lambda _: None) -> None:
    """A SQLite file at schema `revision`, as an older collie left it: a trainer principal (id 1)
    and its run 1 of `task` on the point mass; `more` adds rows in the same transaction."""
    from alembic import command
    from sqlalchemy import text

    from backend.db import Database
    from backend.migrate import alembic_config

    db = Database(f"sqlite:///{path}")
    config = alembic_config(db.url)
    with db.engine.begin() as conn:
        config.attributes["connection"] = conn
        command.upgrade(config, revision)
        conn.execute(
            text("INSERT INTO principals (id, name, role, token_sha256, created_at) VALUES (1, 'o', 'trainer', 'x', 0)")
        )
        conn.execute(
            text(
                "INSERT INTO runs (id, env, task, method, config, dims, status, control, epoch, n_labels,"
                " last_event_id, created_by, created_at, updated_at) VALUES (1, 'point', :task, 'collie', '{}',"
                " :dims, 'training', 'run', 0, 0, 0, 1, 0, 0)"
            ),
            {"task": task, "dims": DIMS.model_dump_json()},
        )
        more(conn)
    db.dispose()


def make_run_spec(dims: EnvDims = DIMS, task: str = "range_north", n_total: int | None = 10) -> RunCreate:
    """A run whose rule takes all three classes (North never calls a state good: the service refuses a 2).
    Its budget (n_total) is 10 queries: a test that posts more gives a larger one, or None (no budget)."""
    return RunCreate(env="point", task=task, method="collie", config={"preset": "smoke"}, dims=dims, n_total=n_total)


def make_query(query_id: str, dims: EnvDims = DIMS, seed: int = 0) -> QueryIn:
    rng = np.random.default_rng(seed)
    h = dims.horizon
    return QueryIn(
        query_id=query_id,
        start=int(rng.integers(0, 100)),
        score=float(rng.random()),
        skill=rng.normal(size=dims.skill_dim).tolist(),
        obs=rng.normal(size=(h, dims.obs_dim)).tolist(),
        xy=rng.normal(size=(h, 2)).tolist(),
        pitch=[None if i == 0 else float(v) for i, v in enumerate(rng.normal(size=h))],
        qpos=rng.normal(size=(h, dims.nq)).tolist(),
        qvel=rng.normal(size=(h, dims.nv)).tolist(),
        path_xy=rng.normal(size=(3 * h, 2)).tolist(),
    )


def make_session(session: int, n: int, dims: EnvDims = DIMS, epoch: int = 0) -> SessionPost:
    queries = [make_query(f"{session}-{i}", dims, seed=1000 * session + i) for i in range(n)]
    return SessionPost(session=session, epoch=epoch, queries=queries)


@pytest.fixture
def run(trainer: CollieClient) -> RunRead:
    """A fresh run with one session of 4 queries (0-0 … 0-3)."""
    created = trainer.create_run(make_run_spec())
    trainer.post_session(created.id, make_session(0, 4))
    return created
