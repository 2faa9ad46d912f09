"""PostgreSQL for real: the migrations build exactly the models on a real server (twice: they
are idempotent), and the service reports the database it runs on. The API tests run on it too
(the modules that override `database_url` with `both_databases`)."""

from __future__ import annotations

from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext
from alembic.script import ScriptDirectory

from backend.db import Database
from backend.main import create_app
from backend.migrate import alembic_config, upgrade
from backend.models import Base
from backend.server import BackgroundServer
from collie.client import CollieClient

from .conftest import TOKENS, settings_for
from .postgres import PostgresServer


def test_migrations_build_exactly_the_models_on_postgresql(postgres: PostgresServer) -> None:
    db = Database(postgres.new_database())
    upgrade(db.engine)
    upgrade(db.engine)
    with db.engine.connect() as conn:
        assert compare_metadata(MigrationContext.configure(conn), Base.metadata) == []
        head = ScriptDirectory.from_config(alembic_config(db.url)).get_current_head()
        assert conn.exec_driver_sql("SELECT version_num FROM alembic_version").scalar() == head
    db.dispose()


def test_the_service_runs_on_postgresql(postgres: PostgresServer) -> None:
    app = create_app(settings_for(postgres.new_database()))
    with BackgroundServer(app) as server, CollieClient(server.url, TOKENS["operator"]) as operator:
        assert operator.health().database == "postgresql"
