"""Alembic environment: runs on the connection handed over by backend.migrate (or the URL in the config)."""

from __future__ import annotations

from alembic import context
from sqlalchemy import Connection, create_engine

from backend.models import Base

config = context.config
connection: Connection | None = config.attributes.get("connection")  # set by backend/migrate.py


def _run(conn: Connection) -> None:
    context.configure(connection=conn, target_metadata=Base.metadata, render_as_batch=True)
    with context.begin_transaction():
        context.run_migrations()


if connection is not None:
    _run(connection)
else:
    with create_engine(config.get_main_option("sqlalchemy.url") or "").connect() as conn:
        _run(conn)
