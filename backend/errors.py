"""Error answers that always encode. A request may carry text that is no valid UTF-8 (a lone
UTF-16 surrogate from a JSON escape); an error that echoes it must still be sent, so every error
body is written as ASCII JSON and echoed input is dropped unless it is small, plain and valid."""

from __future__ import annotations

import json
import logging
import threading
import time
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, Response
from sqlalchemy.exc import DBAPIError, IntegrityError, InterfaceError, OperationalError
from starlette.exceptions import HTTPException
from starlette.requests import ClientDisconnect

from backend.db import (
    SQLITE_BUSY,
    SQLITE_CANTOPEN,
    SQLITE_DAMAGED,
    SQLITE_LOCKED,
    SQLITE_UNWRITABLE,
    DatabaseFileGone,
    sqlite_code,
)
from backend.services.errors import (
    DatabaseBusy,
    DatabaseDamaged,
    DatabaseUnreachable,
    DatabaseUnwritable,
    RunOutOfScope,
    ServiceError,
    TabNotHolding,
    Unavailable,
)

MAX_ECHO = 200
RETRY_AFTER = {"Retry-After": "5"}
log = logging.getLogger("collie.service")


class SafeJSONResponse(JSONResponse):
    """JSON with every non-ASCII character escaped: encodes whatever strings it holds."""

    def render(self, content: Any) -> bytes:
        return json.dumps(content, ensure_ascii=True, allow_nan=False, separators=(",", ":")).encode("ascii")


def clean_text(value: object) -> str:
    """`value` as text fit for an answer: surrogates and other unencodable characters replaced."""
    return str(value).encode("utf-8", "backslashreplace").decode("utf-8")


def plain_error(error: dict[str, Any]) -> dict[str, Any]:
    """A validation error fit to send back: the offending input only when small, plain JSON and
    valid UTF-8 (it may hold NaN or a surrogate, or be a whole session)."""
    plain: dict[str, Any] = {
        "type": clean_text(error.get("type")),
        "loc": [x if isinstance(x, int) else clean_text(x) for x in error.get("loc", ())],
        "msg": clean_text(error.get("msg")),
    }
    if "input" not in error:  # already dropped (e.g. by the session worker's pass)
        return plain
    try:
        text = json.dumps(error.get("input"), allow_nan=False, ensure_ascii=False)
        text.encode("utf-8")
    except (TypeError, ValueError):  # UnicodeEncodeError is a ValueError
        text = None
    if text is not None and len(text) <= MAX_ECHO:
        plain["input"] = error.get("input")
    return plain


class OutageLog:
    """One warning line about a database fault every `every_s` at most, with the count of answers
    refused since: an outage under load must not bury the log (nor be a traceback each)."""

    def __init__(self, what: str, every_s: float = 10.0, status: int = 503) -> None:
        self.what, self.status = what, status
        self.every_s = every_s
        self._lock = threading.Lock()
        self._next = 0.0
        self._refused = 0

    def note(self, cause: str) -> None:
        with self._lock:
            self._refused += 1
            if time.monotonic() < self._next:
                return
            refused, self._refused, self._next = self._refused, 0, time.monotonic() + self.every_s
        log.warning("database %s (%d answer(s) refused with %d): %s", self.what, refused, self.status, cause)


# PostgreSQL's: read_only_sql_transaction (a standby, default_transaction_read_only), disk_full, io_error
PG_UNWRITABLE = {"25006", "53100", "58030"}
# serialization_failure, deadlock_detected: two transactions of service processes took rows in
# different orders, and the server rolled this one back (nothing written; a retry succeeds)
PG_CONFLICT = {"40001", "40P01"}


def database_fault(exc: DBAPIError, dialect: str) -> Unavailable | DatabaseDamaged | None:
    """The database error as a 503 the client may retry, a damaged SQLite file (a 500 that says
    so), or None for a fault of ours (a 500 and a traceback). Judged by the driver's code, not its
    words: SQLite's result code, PostgreSQL's SQLSTATE. On a server database every other
    OperationalError is an outage (the DB-API's "errors related to the database's operation":
    connection refused, shut down, too many connections); SQLite, a file, only loses a connection
    it had or cannot open the file."""
    primary = sqlite_code(exc)
    if primary in SQLITE_DAMAGED:
        return DatabaseDamaged(exc.orig)
    if primary in SQLITE_UNWRITABLE or getattr(exc.orig, "sqlstate", None) in PG_UNWRITABLE:
        return DatabaseUnwritable(exc.orig)
    if primary in (SQLITE_BUSY, SQLITE_LOCKED) or getattr(exc.orig, "sqlstate", None) in PG_CONFLICT:
        return DatabaseBusy()
    if (
        exc.connection_invalidated
        or primary == SQLITE_CANTOPEN
        or (dialect != "sqlite" and isinstance(exc, OperationalError | InterfaceError))
    ):
        return DatabaseUnreachable(exc.orig)
    return None


def install(app: FastAPI) -> None:
    outages, unwritable = OutageLog("unreachable"), OutageLog("cannot be written")
    damaged = OutageLog("file is damaged", status=500)
    gone = OutageLog("file is gone", status=500)

    @app.exception_handler(ServiceError)
    async def _service_error(_: Request, exc: ServiceError) -> JSONResponse:
        if isinstance(exc, TabNotHolding | RunOutOfScope):  # typed: the reason is a value (NotHeld, OutOfScope)
            return SafeJSONResponse(exc.body.model_dump(mode="json"), status_code=exc.status)
        if isinstance(exc, DatabaseUnreachable):
            outages.note(exc.cause)
        elif isinstance(exc, DatabaseUnwritable):
            unwritable.note(exc.cause)
        elif isinstance(exc, DatabaseDamaged):
            damaged.note(exc.cause)
        headers = RETRY_AFTER if isinstance(exc, Unavailable) else None
        return SafeJSONResponse({"detail": clean_text(exc.detail)}, status_code=exc.status, headers=headers)

    @app.exception_handler(RequestValidationError)
    async def _invalid_request(_: Request, exc: RequestValidationError) -> JSONResponse:
        return SafeJSONResponse({"detail": [plain_error(e) for e in exc.errors()[:20]]}, status_code=422)

    @app.exception_handler(HTTPException)
    async def _http_error(_: Request, exc: HTTPException) -> JSONResponse:
        detail = exc.detail if isinstance(exc.detail, str) else clean_text(exc.detail)
        return SafeJSONResponse({"detail": clean_text(detail)}, status_code=exc.status_code, headers=exc.headers)

    @app.exception_handler(ClientDisconnect)
    async def _client_gone(_: Request, __: ClientDisconnect) -> Response:
        # the client hung up before its body was whole: nobody to answer, nothing to log as an error
        return Response(status_code=400)

    @app.exception_handler(DBAPIError)
    async def _database_error(request: Request, exc: DBAPIError) -> JSONResponse:
        fault = database_fault(exc, request.app.state.db.engine.dialect.name)
        if fault is None:
            raise exc  # a real fault: the 500 handler and its log
        return await _service_error(request, fault)

    @app.exception_handler(DatabaseFileGone)
    async def _database_file_gone(_: Request, exc: DatabaseFileGone) -> JSONResponse:
        gone.note(str(exc))  # no retry mends it: a 500, said in the log every 10 s, not a traceback each
        return SafeJSONResponse({"detail": clean_text(str(exc))}, status_code=500)

    @app.exception_handler(IntegrityError)
    async def _integrity_error(_: Request, exc: IntegrityError) -> JSONResponse:
        # A race lost against a concurrent writer (e.g. the same client_request_id twice at once).
        return SafeJSONResponse({"detail": clean_text(f"conflicting write: {exc.orig}")}, status_code=409)
