"""Error answers that always encode. A request may carry text that is no valid UTF-8 (a lone
UTF-16 surrogate from a JSON escape); an error that echoes it must still be sent, so every error
body is written as ASCII JSON and echoed input is dropped unless it is small, plain and valid."""

from __future__ import annotations

import json
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, Response
from sqlalchemy.exc import IntegrityError, OperationalError
from starlette.exceptions import HTTPException
from starlette.requests import ClientDisconnect

from backend.services.errors import ServiceError, TabNotHolding

MAX_ECHO = 200


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


def install(app: FastAPI) -> None:
    @app.exception_handler(ServiceError)
    async def _service_error(_: Request, exc: ServiceError) -> JSONResponse:
        if isinstance(exc, TabNotHolding):  # typed: the reason is a value (collie.schemas.NotHeld)
            return SafeJSONResponse(exc.body.model_dump(mode="json"), status_code=exc.status)
        return SafeJSONResponse({"detail": clean_text(exc.detail)}, status_code=exc.status)

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

    @app.exception_handler(OperationalError)
    async def _database_busy(_: Request, exc: OperationalError) -> JSONResponse:
        if "locked" not in str(exc.orig):  # anything else is a real fault: the 500 handler and its log
            raise exc
        # SQLite's busy timeout ran out: another process holds the write lock (docs/service.md:
        # one service process per SQLite file); nothing was written, the client may retry
        detail = "the database is busy (another process holds its write lock); nothing was written, retry"
        return SafeJSONResponse({"detail": detail}, status_code=503, headers={"Retry-After": "5"})

    @app.exception_handler(IntegrityError)
    async def _integrity_error(_: Request, exc: IntegrityError) -> JSONResponse:
        # A race lost against a concurrent writer (e.g. the same client_request_id twice at once).
        return SafeJSONResponse({"detail": clean_text(f"conflicting write: {exc.orig}")}, status_code=409)
