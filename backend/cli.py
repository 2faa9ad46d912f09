"""`collie serve`: run the labeling service with uvicorn on one address.

Tokens for the three built-in principals (operator, trainer, labeler) come from COLLIE_*_TOKEN,
else from the --tokens-json file an earlier start wrote; a principal the database already has keeps
its token; only a missing one gets a new token, printed, and written to --tokens-json when given.
So a restart never locks out clients that hold the tokens. COLLIE_TEACHER_TOKEN, when set, is the
token of the oracle teacher's own labeler, `teacher` (compose's teacher profile; never made
here, nor written to --tokens-json). Port 0 picks a free port; the bound URL is printed either way
(and written to the tokens file as "api")."""

from __future__ import annotations

import argparse
import contextlib
import errno
import json
import os
import signal
import socket
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn

from pydantic import SecretStr

from backend.services.auth import ROLES, builtin_principals, new_token
from backend.services.errors import Conflict, first_line
from backend.settings import Settings
from collie.addresses import link_host
from collie.argtypes import file_descriptor, port, sqlite_file
from collie.schemas import SERVED_TEACHER_PRINCIPAL
from collie.tokens import read_tokens_file, weakness, write_secret
from collie.whole_files import broken_link, nearly_full, not_replaceable, read_only_disk

if TYPE_CHECKING:
    from sqlalchemy.exc import DBAPIError

STRONG = "use a long random one, e.g. python -c 'import secrets; print(secrets.token_urlsafe(32))'"
TEACHER_TOKEN = "COLLIE_TEACHER_TOKEN"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    parser.add_argument("--port", type=port, default=8000, help="port; 0 picks a free one (default 8000)")
    parser.add_argument(
        "--db", type=sqlite_file, help="SQLite file (default: COLLIE_DATABASE_URL, e.g. PostgreSQL, else ./collie.db)"
    )
    parser.add_argument(
        "--fd",
        type=file_descriptor,
        default=None,
        help="serve on this inherited listening socket (instead of --host/--port)",
    )
    parser.add_argument("--tokens-json", type=Path, help="write {api, tokens: {operator, trainer, labeler}} here")
    parser.add_argument(
        "--no-generate-tokens",
        action="store_true",
        help="only use tokens from the environment (none generated; a --tokens-json file's other tokens are kept, "
        "not used)",
    )
    parser.add_argument(
        "--log-level", default="warning", choices=("critical", "error", "warning", "info", "debug", "trace")
    )


def written_tokens(path: Path | None) -> dict[str, str]:
    """The tokens an earlier start wrote to --tokens-json (none if there is no such file)."""
    if path is None or not path.exists():
        return {}
    try:
        tokens = read_tokens_file(path)
    except ValueError as exc:
        raise ValueError(f"--tokens-json {exc}; move it away") from None
    return {role: tokens[role] for role in ROLES if role in tokens}


def kept_in_file(path: Path, tokens: dict[str, str], alive: set[str]) -> dict[str, str]:
    """With --no-generate-tokens: the tokens file's entries for the roles the environment does not
    set, which an earlier start generated and wrote only there. Rewriting the file without them
    would lose the one copy of tokens the database still accepts. Only roles the database has,
    unrevoked (`alive`): a new database's file keeps no token of an old one. An unreadable file has
    none."""
    try:
        written = written_tokens(path)
    except ValueError:
        return {}
    return {role: t for role, t in written.items() if role not in tokens and role in alive}


def settings_from(args: argparse.Namespace) -> tuple[Settings, dict[str, str], set[str], set[str], set[str]]:
    """Settings from the environment, with --db and the bootstrap tokens filled in; the tokens
    known (from the environment, the tokens file or new), the roles whose token is new, the
    built-in principals an operator revoked (their tokens are left out: revoking is final), and
    those the database already had, unrevoked."""
    overrides: dict[str, object] = {}
    if args.db is not None:
        overrides["database_url"] = f"sqlite:///{args.db.resolve()}"
    try:
        written = {} if args.no_generate_tokens else written_tokens(args.tokens_json)
    except ValueError as exc:
        refuse(str(exc))
    given = {role: os.environ.get(f"COLLIE_{role.upper()}_TOKEN") or written.get(role) for role in ROLES}
    for role, token in given.items():  # refused before the database is touched
        why = None if token is None else weakness(token)
        if why is not None:
            variable = f"COLLIE_{role.upper()}_TOKEN"
            source = variable if os.environ.get(variable) else f"the {role} token in {args.tokens_json}"
            refuse(f"{source} {why}; {STRONG}")
    overrides["teacher_token"] = teacher_token()
    settings = Settings(**overrides)  # type: ignore[arg-type]  # pydantic-settings validates the overrides
    known = builtin_principals(settings.database_url)
    tokens: dict[str, str] = {}
    new: set[str] = set()
    for role in ROLES:
        token = None if known.get(role) else given[role]  # a revoked one's token is valid nowhere: left out
        if token is None and role not in known and not args.no_generate_tokens:
            token = new_token()
            new.add(role)
        if token is not None:
            tokens[role] = token
            overrides[f"{role}_token"] = SecretStr(token)
    if not tokens and not known:  # a new database and no token given or made: no request could ever get in
        refuse(
            "--no-generate-tokens with no COLLIE_OPERATOR_TOKEN, COLLIE_TRAINER_TOKEN or "
            "COLLIE_LABELER_TOKEN set, on a new database: nobody could sign in (set them, or drop --no-generate-tokens)"
        )
    revoked = {role for role, gone in known.items() if gone}
    alive = {role for role, gone in known.items() if not gone}
    return Settings(**overrides), tokens, new, revoked, alive  # type: ignore[arg-type]  # as above


def teacher_token() -> SecretStr | None:
    """COLLIE_TEACHER_TOKEN, refused as a weak role token is (empty: none, as compose passes it unset)."""
    token = os.environ.get(TEACHER_TOKEN) or None
    why = None if token is None else weakness(token)
    if why is not None:
        refuse(f"{TEACHER_TOKEN} {why}; {STRONG}")
    return None if token is None else SecretStr(token)


def inherited(fd: int) -> tuple[socket.socket, str]:
    """The listening socket a parent bound for us (`collie up` binds it before we start, so the
    others can connect while we import: their requests queue until we serve), and its URL."""
    try:
        sock = socket.socket(fileno=fd)
    except OSError as exc:
        refuse(f"--fd {fd} is not an open socket: {exc}")
    host, port = sock.getsockname()[:2]
    return sock, f"http://{link_host(host)}:{port}"


def listening(host: str, port: int) -> tuple[socket.socket, str]:
    """`bind`'s socket and URL, or a one-line error naming host:port and why (in use, not an address
    of this machine, a name that does not resolve)."""
    from backend.server import bind

    try:
        return bind(host, port)
    except OSError as exc:  # socket.gaierror included
        where = f"[{host}]:{port}" if ":" in host else f"{host}:{port}"
        hint = " (--port 0 takes any free port)" if exc.errno == errno.EADDRINUSE else ""
        print(f"collie serve: error: cannot listen on {where}: {exc.strerror or exc}{hint}", file=sys.stderr)
        raise SystemExit(2) from None  # a usage error, as argparse's


def why_not(exc: DBAPIError, db: Path | None) -> str:
    """The driver's words, and for a SQLite file on a full disk that it is full: SQLite may say only
    "disk I/O error" or "unable to open database file" (it cannot make the -shm file of WAL mode)."""
    from backend.db import SQLITE_CANTOPEN, SQLITE_IOERR, sqlite_code

    said = first_line(exc.orig)
    if db is None or "full" in said or sqlite_code(exc) not in (SQLITE_IOERR, SQLITE_CANTOPEN):
        return said
    return said if nearly_full(db.resolve().parent) is None else f"its disk is full ({said})"


def check_sqlite_file(path: Path, shown: str) -> None:
    """A usage error unless the SQLite file at `path` is new (in a folder that exists), empty or
    collie's: serving another program's database would add collie's tables to it (and switch it to
    WAL mode). Looked at read-only, so a refused file is left exactly as it was."""
    from sqlalchemy import inspect

    from backend.db import read_only_engine

    if not path.parent.is_dir():  # SQLite would say only "unable to open database file"
        refuse(f"{shown}: the folder {path.parent} does not exist (make it first)")
    if read_only_disk(path.parent):  # SQLite would say "unable to open database file", or "attempt to write"
        refuse(f"{shown} is on a read-only file system: the service writes to it (collie export reads it there)")
    if not path.is_file() or path.stat().st_size == 0:
        return
    engine = read_only_engine(path)
    try:
        with engine.connect() as conn:
            tables = sorted(inspect(conn).get_table_names())
    finally:
        engine.dispose()
    if tables and "alembic_version" not in tables:
        named = ", ".join(tables[:5]) + (f" and {len(tables) - 5} more" if len(tables) > 5 else "")
        shown = f"{shown} is not a collie database (no schema version; its tables: {named})"
        refuse(f"{shown}: give a new file or a collie one")


def check_tokens_json(path: Path) -> None:
    """--tokens-json must take a file before any token is made: one made and stored (as a hash)
    but neither written there nor printed would lock everybody out (the next start finds it kept)."""
    if not_replaceable(path):  # /dev/stdout, a FIFO: written in place
        return
    if path.is_dir():
        refuse(f"--tokens-json {path} is a folder; give a file's path")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=path.parent):  # root may write where access() would say no
            pass
    except OSError as exc:
        refuse(f"--tokens-json {path}: cannot write a file in {path.parent} ({broken_link(exc) or exc.strerror})")


@contextlib.contextmanager
def tokens_written(path: Path | None, url: str, tokens: dict[str, str]) -> Iterator[None]:
    """--tokens-json written before the block, which stores the tokens' hashes (a token stored but
    never written locks everybody out), and put back as it was if the block fails: nothing was
    stored then, and the file may hold the only copy of the tokens that are (a start refused for
    one token given to two roles must not replace them)."""
    if path is None:
        yield
        return
    before: str | None = None
    restorable = not not_replaceable(path)
    if restorable and path.exists():
        try:
            before = path.read_text()
        except (OSError, ValueError):  # cannot be read back (or not text), then not put back either
            restorable = False
    write_tokens_json(path, url, tokens)
    try:
        yield
    except BaseException:
        if restorable:
            with contextlib.suppress(OSError):  # the refusal is the error to show
                if before is None:
                    path.unlink(missing_ok=True)
                else:
                    write_secret(path, before)
        raise


def write_tokens_json(path: Path, url: str, tokens: dict[str, str]) -> None:
    """The tokens file, written whole, then renamed (a watcher never reads half a file); refused in
    a line where the disk will not take it (full, read-only, an immutable file): no token is stored
    then, and the next start makes them again. (Tokens written but not stored, should the start
    fail after, are read back from the file by the next start.)"""
    try:
        write_secret(path, json.dumps({"api": url, "tokens": tokens}, indent=1))
    except OSError as exc:
        said = (exc.strerror or str(exc)).lower()
        refuse(f"--tokens-json {path}: cannot write it ({said}); no token was stored, nothing changed")


def refuse(why: str) -> NoReturn:
    """A refusal no restart mends, as argparse reports its own: one line, exit status 2 (the
    supervisor of `collie up` stops restarting on it)."""
    print(f"collie serve: error: {why}", file=sys.stderr)
    raise SystemExit(2)


def run(args: argparse.Namespace) -> int:
    from sqlalchemy.engine import make_url
    from sqlalchemy.exc import DBAPIError

    from backend.db import UnusableDatabaseUrl, check_url, describe, is_sqlite
    from backend.main import create_app
    from backend.migrate import Damaged, UnknownRevision
    from backend.server import uvicorn_server
    from collie.startup import mark

    mark("imports")  # FastAPI, SQLAlchemy, the routes

    if args.db is not None and args.db.is_dir():
        refuse(f"--db {args.db} is a folder; give a SQLite file's path")
    url = f"sqlite:///{args.db.resolve()}" if args.db is not None else Settings().database_url
    try:
        check_url(url)
        where = str(args.db) if args.db is not None else describe(url)
        if is_sqlite(url) and make_url(url).database not in (None, "", ":memory:"):
            check_sqlite_file(Path(make_url(url).database or ""), where)
    except UnusableDatabaseUrl as exc:
        refuse(str(exc))
    except DBAPIError as exc:  # e.g. a file that is not SQLite
        raise SystemExit(f"collie serve: error: cannot open the database {where}: {why_not(exc, args.db)}") from None
    if args.tokens_json is not None:
        check_tokens_json(args.tokens_json)
    # Bound before the database is opened: a start that cannot listen must not create the database
    # and its tokens, which it would never print (the next start finds them "kept": a lockout).
    sock, url = inherited(args.fd) if args.fd is not None else listening(args.host, args.port)
    try:
        settings, tokens, generated, revoked, alive = settings_from(args)
        kept = kept_in_file(args.tokens_json, tokens, alive) if args.no_generate_tokens and args.tokens_json else {}
        with tokens_written(args.tokens_json, url, kept | tokens):
            app = create_app(settings)  # stores the tokens' hashes
    except Damaged as exc:  # a table dropped: every request touching it would fail, and no restart mends it
        refuse(str(exc))
    except (Conflict, UnknownRevision, UnusableDatabaseUrl) as exc:  # e.g. one token for two roles, postgres://
        refuse(str(exc))
    except DBAPIError as exc:  # e.g. a file that is not SQLite, a server that refuses us
        where = describe(Settings().database_url) if args.db is None else args.db
        raise SystemExit(f"collie serve: error: cannot open the database {where}: {why_not(exc, args.db)}") from None
    mark("app built")  # the database opened and migrated
    server = uvicorn_server(app, args.log_level)
    # Ctrl-C (or SIGTERM) is the way to stop, at any moment from here on: the handler only sets
    # uvicorn's exit flag, which it reads once it serves (and its own handlers do the same). Not a
    # KeyboardInterrupt: one raised inside a weakref callback or __del__ is printed and dropped, and
    # the service then ran on (seen in a loop of restarts beside busy processes).
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, server.handle_exit)
    print(f"collie service listening on {url}  (API docs: {url}/docs)", flush=True)
    for role in ROLES:  # secrets given through the environment or a file stay out of logs
        if role in revoked:
            shown = f"revoked (final: create another {role} with POST /api/labelers)"
        elif role in generated:
            shown = tokens[role] if args.tokens_json is None else f"(in {args.tokens_json})"
        elif f"COLLIE_{role.upper()}_TOKEN" in os.environ:
            shown = "(from environment)"
        elif role in tokens:
            shown = f"(kept, in {args.tokens_json})"
        elif args.no_generate_tokens:
            continue
        else:
            rotate = f"to replace it, set COLLIE_{role.upper()}_TOKEN"  # the database keeps only its hash
            shown = (
                f"(kept from the last start, which printed it; {rotate}; --tokens-json FILE writes tokens to a file)"
                if args.tokens_json is None
                else f"(kept from a start that printed it and wrote no {args.tokens_json}; {rotate} to write it there)"
            )
        print(f"  {role} token: {shown}", flush=True)
    if settings.teacher_token is not None:
        print(f"  {SERVED_TEACHER_PRINCIPAL} token: (from environment, {TEACHER_TOKEN})", flush=True)
    try:
        if not server.should_exit:  # stopped while the banner printed: nothing to serve
            server.run(sockets=[sock])
    finally:  # served and shut down: a later Ctrl-C (a hang on the way out) interrupts as usual
        signal.signal(signal.SIGINT, signal.default_int_handler)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
    return 0  # stopped by Ctrl-C or SIGTERM, after a clean shutdown


if __name__ == "__main__":
    parser = argparse.ArgumentParser(prog="collie serve", description=__doc__)
    add_arguments(parser)
    sys.exit(run(parser.parse_args()))
