"""`collie export`: print a run's label events (or its effective labels) as JSON or CSV, straight
from the database file (the service may be running: SQLite in WAL mode lets readers in)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sqlalchemy.engine import make_url
from sqlalchemy.exc import DBAPIError

from backend import migrate
from backend.db import (
    SQLITE_DAMAGED,
    Database,
    UnusableDatabaseUrl,
    check_url,
    describe,
    is_sqlite,
    read_only_engine,
    sqlite_code,
)
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


def run(args: argparse.Namespace) -> int:
    url = f"sqlite:///{args.db.resolve()}" if args.db is not None else Settings().database_url
    try:
        check_url(url)
    except UnusableDatabaseUrl as exc:
        print(f"collie export: error: {exc}", file=sys.stderr)
        return 2
    where = describe(url) if args.db is None else str(args.db)
    path = Path(make_url(url).database or "") if is_sqlite(url) else None
    if path is not None and not path.is_file():  # never create an empty one by mistake
        what = "is a folder; give a SQLite file's path" if path.is_dir() else "does not exist"
        print(f"collie export: error: {where} {what}", file=sys.stderr)
        return 2
    db = Database(url)  # connects only when used
    # A SQLite file is read read-only: nothing written (the service's connections set WAL mode,
    # 4 KB into an empty file, before it could be refused), and a file on a read-only mount or in a
    # read-only folder is readable. Only an older schema needs a writable file, to be upgraded.
    reader = read_only_engine(path) if path is not None else db.engine
    try:
        try:
            found = migrate.current(reader)
        except DBAPIError as exc:  # a file that is no SQLite database, a server that refuses us
            fault = "is not a collie database" if path is not None else "cannot be read"
            print(f"collie export: error: {where} {fault} ({first_line(exc.orig)})", file=sys.stderr)
            return 2
        if found is None:
            print(f"collie export: error: {where} is not a collie database (no schema version)", file=sys.stderr)
            return 2
        try:
            if found == migrate.head():
                migrate.check_complete(reader, where)
            elif not migrate.known(found):
                raise migrate.newer(where, found)
            else:  # as `collie serve` does on start: older databases stay readable
                try:
                    older = migrate.bring_up_to_date(db.engine)
                except DBAPIError as exc:  # a read-only file, a read-only server
                    print(
                        f"collie export: error: {where} is at schema {found}, older than this collie's "
                        f"{migrate.head()}, and cannot be upgraded here ({first_line(exc.orig)}): "
                        "export a writable copy of it",
                        file=sys.stderr,
                    )
                    return 2
                reader.dispose()  # its read-only connection: the upgraded file is read through db's
                reader = db.engine
                print(f"collie export: {migrate.upgraded(url, older or found)}", file=sys.stderr)
        except migrate.UnknownRevision as exc:  # Damaged too
            print(f"collie export: error: {exc}", file=sys.stderr)
            return 2
        with reader.connect() as conn, conn.begin():
            text = export.render(export.rows(conn, args.run, args.effective), args.format, args.effective)
    except DBAPIError as exc:
        if sqlite_code(exc) not in SQLITE_DAMAGED:
            raise
        said = f"{where} is damaged ({first_line(exc.orig)}): restore it from a backup"
        print(f"collie export: error: {said}", file=sys.stderr)
        return 2
    except ServiceError as exc:  # no such run: a wrong --run, refused as every other wrong argument is
        print(f"collie export: error: {exc.detail}", file=sys.stderr)
        return 2
    finally:
        reader.dispose()
        db.dispose()
    sys.stdout.write(text if text.endswith("\n") else text + "\n")
    return 0
