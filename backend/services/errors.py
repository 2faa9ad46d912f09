"""Errors a service raises; main.py turns them into JSON 4xx answers."""

from __future__ import annotations

from collie.schemas import NotHeld, NotHeldReason, OutOfScope, OutOfScopeReason


def first_line(error: object) -> str:
    """A driver's error in one log line (psycopg adds hints on more lines)."""
    return str(error).strip().split("\n")[0]


class ServiceError(Exception):
    status = 400

    def __init__(self, detail: str) -> None:
        super().__init__(detail)
        self.detail = detail


class NotFound(ServiceError):
    status = 404


class Forbidden(ServiceError):
    status = 403


class RunOutOfScope(Forbidden):
    """A valid token on a run outside its scope; the answer is an OutOfScope body."""

    def __init__(self, run_id: int, reason: OutOfScopeReason, detail: str) -> None:
        super().__init__(detail)
        self.body = OutOfScope(detail=detail, reason=reason, run_id=run_id)


class Conflict(ServiceError):
    status = 409


class Invalid(ServiceError):
    status = 422


class Unavailable(ServiceError):
    """Not now: the client may retry (the answer carries Retry-After)."""

    status = 503


class DatabaseUnreachable(Unavailable):
    """The database server is down, restarting or refusing us; the cause (the driver's error) goes
    to the log only, in one line: it names the server's address, no business of a client."""

    def __init__(self, cause: object) -> None:
        super().__init__("the database is unreachable; retry later")
        self.cause = first_line(cause)


class DatabaseUnwritable(Unavailable):
    """The database answers but cannot store anything: its disk is full, its files read-only (or
    immutable), a PostgreSQL server read-only, or the disk failing. Nothing was written; the cause
    goes to the log only, in one line."""

    def __init__(self, cause: object) -> None:
        super().__init__("the database cannot be written (disk full, read-only or failing); nothing was stored, retry")
        self.cause = first_line(cause)


class DatabaseDamaged(ServiceError):
    """SQLite found a page of its file damaged (a disk fault, a copy taken mid-write): no retry
    mends it, and what the damaged pages held is out of reach; the cause goes to the log only."""

    status = 500

    def __init__(self, cause: object) -> None:
        super().__init__(
            "the database file is damaged; its operator must stop the service and restore it from a backup "
            "(sqlite3's .recover may save what it holds)"
        )
        self.cause = first_line(cause)


class DatabaseBusy(Unavailable):
    """SQLite's busy timeout ran out (another process holds the write lock: one service process per
    SQLite file is supported), or PostgreSQL rolled the transaction back for a concurrent one (a
    deadlock between service processes). Nothing was written; the client may retry."""

    def __init__(self) -> None:
        super().__init__("the database is busy with another process's writes; nothing was written, retry")


class TabNotHolding(Conflict):
    """A label from a tab that does not hold the query's lease; the answer is a NotHeld body."""

    def __init__(self, query_id: str, reason: NotHeldReason, detail: str) -> None:
        super().__init__(detail)
        self.body = NotHeld(detail=detail, reason=reason, query_id=query_id)
