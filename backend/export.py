"""`collie export`: print a run's label events (or its effective labels) as JSON or CSV, straight
from the database file (the service may be running: SQLite in WAL mode lets readers in)."""

from __future__ import annotations

import argparse
import sqlite3
import sys
from contextlib import closing
from pathlib import Path

from sqlalchemy.engine import make_url
from sqlalchemy.exc import DBAPIError

from backend import migrate
from backend.db import Database, UnusableDatabaseUrl, check_url, describe, is_sqlite
from backend.services import export
from backend.services.errors import ServiceError, first_line
from backend.settings import Settings
from collie.argtypes import record_id, sqlite_file


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--db", type=sqlite_file, help="SQLite file (default: COLLIE_DATABASE_URL, e.g. PostgreSQL, else ./collie.db)"
    )
    parser.add_argument("--run", type=record_id, required=True, help="run id")
    parser.add_argument("--format", choices=("json", "csv"), default="json")
    parser.add_argument("--effective", action="store_true", help="one effective label per query, not every event")


def unversioned(path: Path) -> str | None:
    """Why the SQLite file at `path` is no collie database, if it is not, found read-only: the
    service's connection sets WAL mode, which writes into the file (4 KB into an empty one) before
    the file could be refused."""
    try:
        with closing(sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro", uri=True)) as conn:
            tables = {row[0] for row in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
            versioned = "alembic_version" in tables and conn.execute("SELECT 1 FROM alembic_version").fetchone()
    except sqlite3.Error as exc:
        return f"is not a collie database ({exc})"
    return None if versioned else "is not a collie database (no schema version)"


def run(args: argparse.Namespace) -> int:
    url = f"sqlite:///{args.db.resolve()}" if args.db is not None else Settings().database_url
    try:
        check_url(url)
    except UnusableDatabaseUrl as exc:
        print(f"collie export: error: {exc}", file=sys.stderr)
        return 2
    where = describe(url) if args.db is None else str(args.db)
    if is_sqlite(url) and not Path(make_url(url).database or "").is_file():  # never create an empty one by mistake
        print(f"collie export: error: no database at {where}", file=sys.stderr)
        return 2
    refused = unversioned(Path(make_url(url).database or "")) if is_sqlite(url) else None
    if refused is not None:  # left as it was
        print(f"collie export: error: {where} {refused}", file=sys.stderr)
        return 2
    db = Database(url)
    try:
        try:
            found = migrate.current(db.engine)
        except DBAPIError as exc:  # a file that is no SQLite database, a server that refuses us
            fault = "is not a collie database" if is_sqlite(url) else "cannot be read"
            print(f"collie export: error: {where} {fault} ({first_line(exc.orig)})", file=sys.stderr)
            return 2
        if found is None:
            print(f"collie export: error: {where} is not a collie database (no schema version)", file=sys.stderr)
            return 2
        try:  # as `collie serve` does on start: older databases stay readable
            older = migrate.bring_up_to_date(db.engine)
        except migrate.UnknownRevision as exc:
            print(f"collie export: error: {exc}", file=sys.stderr)
            return 2
        if older is not None:
            print(f"collie export: {migrate.upgraded(url, older)}", file=sys.stderr)
        with db.read() as conn:
            text = export.render(export.rows(conn, args.run, args.effective), args.format, args.effective)
    except ServiceError as exc:
        print(f"collie export: error: {exc.detail}", file=sys.stderr)
        return 1
    finally:
        db.dispose()
    sys.stdout.write(text if text.endswith("\n") else text + "\n")
    return 0
