"""Engine and transactions. SQLite gets WAL (readers never block the writer), synchronous=FULL
(an acknowledged commit survives a power cut), foreign keys, a busy timeout and explicit BEGIN /
BEGIN IMMEDIATE (write transactions take the write lock up front, so a read-then-write never
fails half way with SQLITE_BUSY); any other URL (PostgreSQL) is used as given."""

from __future__ import annotations

import functools
import math
import os
import re
import sqlite3
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Literal
from urllib.parse import quote

from sqlalchemy import Connection, Engine, create_engine, event
from sqlalchemy.engine import make_url
from sqlalchemy.exc import ArgumentError, DBAPIError, NoSuchModuleError
from sqlalchemy.pool import StaticPool

Publisher = Callable[[list[tuple[int, int]]], None]
WROTE_RECENTLY_S = 5.0  # a write this recent answers whether the database takes writes (health)


DRIVERS = ("pysqlite", "psycopg")  # the drivers collie installs and is tested on
ACCEPTED = "a SQLite file (--db PATH, or sqlite:///PATH) or postgresql+psycopg://USER:PASSWORD@HOST:5432/DB"


# SQLite's primary result codes (the low byte of an extended one: SQLITE_IOERR_WRITE is 778)
SQLITE_BUSY, SQLITE_LOCKED, SQLITE_READONLY, SQLITE_IOERR, SQLITE_FULL, SQLITE_CANTOPEN = 5, 6, 8, 10, 13, 14
SQLITE_UNWRITABLE = {SQLITE_READONLY, SQLITE_IOERR, SQLITE_FULL}
SQLITE_DAMAGED = {11, 26}  # SQLITE_CORRUPT ("database disk image is malformed"), SQLITE_NOTADB


def sqlite_code(exc: DBAPIError) -> int | None:
    """SQLite's primary result code of the driver's error; None for another database's."""
    code = getattr(exc.orig, "sqlite_errorcode", None)
    return code & 0xFF if isinstance(code, int) else None


class UnusableDatabaseUrl(ValueError):
    """A database URL that names no database collie can open."""


def check_url(url: str) -> None:
    """UnusableDatabaseUrl, in one line without the password, unless `url` is one of ACCEPTED."""
    try:
        parsed = make_url(url)
        usable = parsed.get_dialect().driver in DRIVERS
        shown = parsed.render_as_string(hide_password=True)
    except (ArgumentError, NoSuchModuleError):  # not a URL; a dialect SQLAlchemy does not know
        usable, shown = False, re.sub(r"(://[^:/@]*:)[^@]*@", r"\1***@", url)
    if not usable:
        raise UnusableDatabaseUrl(f"COLLIE_DATABASE_URL {shown!r} is no database collie can use: give {ACCEPTED}")


def is_sqlite(url: str) -> bool:
    return make_url(url).get_backend_name() == "sqlite"


def describe(url: str) -> str:
    """The database as a person names it: a SQLite file's path, else the URL without its password."""
    parsed = make_url(url)
    return str(parsed.database) if is_sqlite(url) else parsed.render_as_string(hide_password=True)


Synchronous = Literal["NORMAL", "FULL"]


def _sqlite_connect(
    dbapi_connection: Any, _record: Any, background_checkpoints: bool = False, synchronous: Synchronous = "FULL"
) -> None:
    dbapi_connection.isolation_level = None  # we issue BEGIN ourselves (see _sqlite_begin)
    cursor = dbapi_connection.cursor()
    if background_checkpoints:  # the fsync of a checkpoint must not land on a request (Database.checkpoint)
        cursor.execute("PRAGMA wal_autocheckpoint=0")
    cursor.execute("PRAGMA journal_mode=WAL")
    # FULL: every commit (an acknowledged label) is fsynced before it is answered, so it survives a
    # power cut; NORMAL survives only a crash of the process (bench_service measures the cost).
    cursor.execute(f"PRAGMA synchronous={synchronous}")
    cursor.execute("PRAGMA foreign_keys=ON")
    cursor.execute("PRAGMA busy_timeout=5000")
    cursor.close()


def _sqlite_begin(conn: Connection) -> None:
    conn.exec_driver_sql("BEGIN IMMEDIATE" if conn.get_execution_options().get("write") else "BEGIN")


def _open_read_only(path: Path) -> sqlite3.Connection:
    """The SQLite file at `path`, read-only (mode=ro: nothing is written or created, and a missing
    file is an error). A WAL database closed cleanly in a read-only folder cannot be read so (SQLite
    wants to create its -shm file there): with no write-ahead log, the file alone is the whole
    database, and immutable=1 reads it without one."""
    uri = f"file:{quote(str(path.resolve()))}?mode=ro"
    conn = sqlite3.connect(uri, uri=True, check_same_thread=False)
    try:
        conn.execute("SELECT count(*) FROM sqlite_master").fetchall()  # opening is lazy: this reads the file
    except sqlite3.OperationalError:
        conn.close()
        wal = path.with_name(path.name + "-wal")
        if os.access(path.parent, os.W_OK) or (wal.exists() and wal.stat().st_size > 0):
            raise
        conn = sqlite3.connect(uri + "&immutable=1", uri=True, check_same_thread=False)
    conn.isolation_level = None  # we issue BEGIN ourselves: one snapshot per transaction
    return conn


def read_only_engine(path: Path) -> Engine:
    """An engine that reads the SQLite file at `path` and never writes to it: no WAL switch, no
    migration (`collie export`, and `collie serve`'s look at a file before it is used)."""
    engine = create_engine("sqlite://", creator=functools.partial(_open_read_only, path), poolclass=StaticPool)
    event.listen(engine, "begin", _sqlite_begin)
    return engine


def make_engine(url: str, background_checkpoints: bool = False, synchronous: Synchronous = "FULL") -> Engine:
    check_url(url)
    if is_sqlite(url):
        in_memory = make_url(url).database in (None, "", ":memory:")
        # An in-memory database lives in one connection: share it (handy for tools and tests).
        pooling: dict[str, Any] = {"poolclass": StaticPool} if in_memory else {"pool_size": 8, "max_overflow": 24}
        engine = create_engine(url, connect_args={"check_same_thread": False}, **pooling)
        event.listen(
            engine,
            "connect",
            functools.partial(_sqlite_connect, background_checkpoints=background_checkpoints, synchronous=synchronous),
        )
        event.listen(engine, "begin", _sqlite_begin)
        return engine
    return create_engine(url, pool_pre_ping=True, pool_size=8, max_overflow=24)


def _changes(conn: Connection) -> int | None:
    """Rows SQLite's connection has changed since it opened (None for other databases)."""
    changes = getattr(conn.connection.dbapi_connection, "total_changes", None)
    return changes if isinstance(changes, int) else None


class DatabaseFileGone(RuntimeError):
    """The SQLite file the service opened was deleted, or another file put in its place, while it
    ran: what it would write now goes to a file nobody sees again (or a new empty one)."""

    def __init__(self, path: Path) -> None:
        super().__init__(
            f"the database file {path} was deleted or replaced while the service ran: stop the service, put the "
            "file back (from a backup) and start it again"
        )


class Database:
    """Short transactions over one engine. Stream events a write appended (conn.info["published"],
    (run_id, event id) pairs) are handed to `publisher` only once the transaction is durable."""

    def __init__(
        self,
        url: str,
        publisher: Publisher | None = None,
        background_checkpoints: bool = False,
        synchronous: Synchronous = "FULL",
    ) -> None:
        self.url = url
        self.background_checkpoints = background_checkpoints and is_sqlite(url)
        self.engine = make_engine(url, self.background_checkpoints, synchronous)
        self.publisher = publisher
        self._wrote_at = -math.inf  # when a write transaction last committed
        database = make_url(url).database if is_sqlite(url) else None
        self._file = Path(database) if database not in (None, "", ":memory:") else None
        self._file_id: tuple[int, int] | None = None  # (device, inode) of the file first opened

    def _check_file(self) -> None:
        """DatabaseFileGone once the SQLite file first opened is no longer at its path (one stat:
        about a microsecond a transaction). Its connections would go on writing to the deleted file,
        and a new one would make an empty database there."""
        if self._file is None:
            return
        try:
            found = os.stat(self._file)
            here: tuple[int, int] | None = (found.st_dev, found.st_ino)
        except FileNotFoundError:
            here = None
        if self._file_id is None:  # not made yet (the first connection makes it), or just made
            self._file_id = here
        elif here != self._file_id:
            raise DatabaseFileGone(self._file)

    @contextmanager
    def write(self) -> Iterator[Connection]:
        self._check_file()
        try:
            with self.engine.connect() as conn:
                conn.execution_options(write=True)
                conn.info["published"] = []
                changes_before = _changes(conn)
                with conn.begin():
                    yield conn
                published: list[tuple[int, int]] = conn.info.pop("published")
                changed = changes_before is not None and _changes(conn) != changes_before  # unknown: no proof
        except DBAPIError:
            self._wrote_at = -math.inf  # perhaps a full disk, read-only files: the next check writes
            raise
        if changed:  # SQLite commits a transaction that changed nothing on a full disk too: no proof
            self._wrote_at = time.monotonic()
        if published and self.publisher is not None:
            self.publisher(published)

    @contextmanager
    def read(self) -> Iterator[Connection]:
        self._check_file()
        with self.engine.connect() as conn, conn.begin():
            yield conn

    def unwritable(self) -> str | None:
        """None when the database takes writes, else why not (or the write's DBAPIError). SQLite: a
        write that changed rows, committed in the last WROTE_RECENTLY_S, says so; else a write
        transaction that rewrites the header's user_version unchanged (one log frame) fails exactly
        when a real write would: full disk, read-only or immutable files, I/O error. A server
        database: whether its transactions are read-only (a standby, default_transaction_read_only),
        asked every time; its full disk shows on the writes themselves."""
        if time.monotonic() - self._wrote_at < WROTE_RECENTLY_S:
            return None  # a busy service is not slowed by a health check taking the write lock
        if not is_sqlite(self.url):  # a question, not a write: its answer proves no write
            with self.read() as conn:
                read_only = conn.exec_driver_sql("SHOW transaction_read_only").scalar()
            return "its transactions are read-only" if read_only == "on" else None
        with self.write() as conn:
            version = int(conn.exec_driver_sql("PRAGMA user_version").scalar() or 0)
            conn.exec_driver_sql(f"PRAGMA user_version = {version}")
        self._wrote_at = time.monotonic()  # a frame was written, though no row changed
        return None

    def checkpoint(self) -> None:
        """Copy the write-ahead log into the database file. PASSIVE never waits for readers or the
        writer; the service calls it from a worker thread about once a second (SQLite only)."""
        if self.background_checkpoints:
            with self.engine.connect() as conn:
                conn.exec_driver_sql("PRAGMA wal_checkpoint(PASSIVE)")

    def dispose(self) -> None:
        self.engine.dispose()
