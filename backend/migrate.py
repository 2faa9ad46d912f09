"""Bring a database to the newest schema with Alembic, programmatically (no alembic.ini needed)."""

from __future__ import annotations

from pathlib import Path

from alembic import command
from alembic.config import Config
from alembic.migration import MigrationContext
from alembic.script import ScriptDirectory
from alembic.util.exc import CommandError
from sqlalchemy import Engine

from backend.db import describe

MIGRATIONS = Path(__file__).parent / "migrations"


class UnknownRevision(Exception):
    """The database's schema cannot be brought up to date: a revision this code does not know (a
    newer collie made it), or an upgrade that failed."""


def alembic_config(url: str) -> Config:
    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS))
    config.set_main_option("sqlalchemy.url", url.replace("%", "%%"))
    return config


def upgrade(engine: Engine) -> None:
    config = alembic_config(engine.url.render_as_string(hide_password=False))
    with engine.begin() as conn:
        config.attributes["connection"] = conn
        command.upgrade(config, "head")


def bring_up_to_date(engine: Engine) -> str | None:
    """Upgrade the database to head (what `collie serve` and `collie export` do first); the revision
    it was at when that was an older one (None for a new or current database)."""
    found = current(engine)
    if found == head():
        return None
    try:
        upgrade(engine)
    except CommandError as exc:  # a one-line error for `collie serve` and `collie export`, not alembic's traceback
        where = describe(engine.url.render_as_string(hide_password=False))
        if found is not None and not known(found):
            raise UnknownRevision(
                f"database {where} is at schema revision {found}, which this collie does not know: "
                "a newer collie made it (upgrade collie)"
            ) from None
        raise UnknownRevision(f"database {where}: upgrading its schema from {found} failed: {exc}") from None
    return found


def upgraded(url: str, older: str) -> str:
    """The one line `collie serve` and `collie export` say after upgrading a database."""
    return f"upgraded {describe(url)} from schema {older} to {head()}"


def known(revision: str) -> bool:
    try:
        return ScriptDirectory.from_config(alembic_config("sqlite://")).get_revision(revision) is not None
    except CommandError:
        return False


def head() -> str:
    """The newest schema revision this code knows."""
    return str(ScriptDirectory.from_config(alembic_config("sqlite://")).get_current_head())


def current(engine: Engine) -> str | None:
    """The database's schema revision; None for a database collie never migrated."""
    with engine.connect() as conn:
        return MigrationContext.configure(conn).get_current_revision()
