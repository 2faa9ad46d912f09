"""`collie export`: print a run's label events (or its effective labels) as JSON or CSV, straight
from the database file (the service may be running: SQLite in WAL mode lets readers in)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sqlalchemy import create_engine
from sqlalchemy.engine import Engine, make_url
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


def looking(url: str, db: Database) -> Engine:
    """An engine to read the schema version with before anything is written: a SQLite file opened
    read-only (the service's connections set WAL mode, which writes into the file, 4 KB into an
    empty one, before it could be refused); a server's database through `db`."""
    if not is_sqlite(url):
        return db.engine
    return create_engine(f"sqlite:///file:{Path(make_url(url).database or '').resolve()}?mode=ro&uri=true")


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
    db = Database(url)  # connects only when used
    probe = looking(url, db)
    try:
        try:
            found = migrate.current(probe)
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
        probe.dispose()
        db.dispose()
    sys.stdout.write(text if text.endswith("\n") else text + "\n")
    return 0
