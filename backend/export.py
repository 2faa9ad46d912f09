"""`collie export`: print a run's label events (or its effective labels) as JSON or CSV, straight
from the database file (the service may be running: SQLite in WAL mode lets readers in)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from backend.db import Database
from backend.services import export
from backend.services.errors import ServiceError
from backend.settings import Settings


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--db", type=Path, help="SQLite file (default: COLLIE_DATABASE_URL)")
    parser.add_argument("--run", type=int, required=True, help="run id")
    parser.add_argument("--format", choices=("json", "csv"), default="json")
    parser.add_argument("--effective", action="store_true", help="one effective label per query, not every event")


def run(args: argparse.Namespace) -> int:
    if args.db is not None and not args.db.is_file():  # never create an empty database by mistake
        print(f"collie export: no database at {args.db}", file=sys.stderr)
        return 2
    url = f"sqlite:///{args.db.resolve()}" if args.db is not None else Settings().database_url
    db = Database(url)
    try:
        with db.read() as conn:
            text = export.render(export.rows(conn, args.run, args.effective), args.format, args.effective)
    except ServiceError as exc:
        print(f"collie export: {exc.detail}", file=sys.stderr)
        return 1
    finally:
        db.dispose()
    sys.stdout.write(text if text.endswith("\n") else text + "\n")
    return 0
