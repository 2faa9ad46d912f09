"""Bring a database to the newest schema with Alembic, programmatically (no alembic.ini needed)."""

from __future__ import annotations

from pathlib import Path

from alembic import command
from alembic.config import Config
from alembic.migration import MigrationContext
from alembic.script import ScriptDirectory
from alembic.util.exc import CommandError
from sqlalchemy import Engine, inspect

from backend.db import describe
from backend.models import Base

MIGRATIONS = Path(__file__).parent / "migrations"


class UnknownRevision(Exception):
    """The database's schema cannot be brought up to date: a revision this code does not know (a
    newer collie made it), or an upgrade that failed."""


class Damaged(UnknownRevision):
    """A database at collie's schema revision that lacks some of that schema's tables (dropped by
    hand, a partial restore): every request touching them would fail with "no such table"."""


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
        check_complete(engine)
        return None
    try:
        upgrade(engine)
    except CommandError as exc:  # a one-line error for `collie serve` and `collie export`, not alembic's traceback
        where = describe(engine.url.render_as_string(hide_password=False))
        if found is not None and not known(found):
            raise newer(where, found) from None
        raise UnknownRevision(f"database {where}: upgrading its schema from {found} failed: {exc}") from None
    check_complete(engine)
    return found


def newer(where: str, found: str) -> UnknownRevision:
    """The error for a database a newer collie made (at a revision this code does not know)."""
    return UnknownRevision(
        f"database {where} is at schema revision {found}, which this collie does not know: "
        "a newer collie made it (upgrade collie)"
    )


def check_complete(engine: Engine, where: str | None = None) -> None:
    """Damaged, in one line naming the missing tables, unless the database (at head) has every
    table of collie's schema (Base's: test_migrations_build_exactly_the_models). One query: cheap
    enough for every start and export. `where` names the database (default: the engine's URL)."""
    with engine.connect() as conn:
        missing = sorted(set(Base.metadata.tables) - set(inspect(conn).get_table_names()))
    if missing:
        where = where or describe(engine.url.render_as_string(hide_password=False))
        tables = f"table {missing[0]} is" if len(missing) == 1 else f"tables {', '.join(missing)} are"
        raise Damaged(f"database {where} is damaged: its {tables} missing (restore it from a backup)")


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
