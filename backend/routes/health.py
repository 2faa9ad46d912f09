"""Liveness and whether the database takes writes; needs no token."""

from __future__ import annotations

from fastapi import APIRouter
from sqlalchemy import text
from sqlalchemy.exc import DBAPIError

from backend import __version__
from backend.errors import database_fault
from backend.routes.deps import DB
from backend.services.errors import DatabaseUnreachable, DatabaseUnwritable
from collie.schemas import ErrorBody, Health

router = APIRouter(tags=["health"])


# HEAD too (`curl -I`, load balancers' probes), out of the schema: one route for both methods would
# give the two one operation id, whose suffix then changes from process to process
@router.head("/health", include_in_schema=False)
@router.get(
    "/health",
    responses={
        503: {"model": ErrorBody, "description": "the database is unreachable, busy or cannot be written"},
        500: {"model": ErrorBody, "description": "the database file is damaged (restore it from a backup)"},
    },
)
def health(db: DB) -> Health:
    try:
        with db.read() as conn:
            conn.execute(text("SELECT 1"))
        # and a write: a full disk or read-only files answer every read but refuse every write
        refused = db.unwritable()
    except DBAPIError as exc:  # 503 with Retry-After (500 for a damaged file), the cause in one log line
        raise database_fault(exc, db.engine.dialect.name) or DatabaseUnreachable(exc.orig) from None
    if refused is not None:
        raise DatabaseUnwritable(refused)
    return Health(status="ok", version=__version__, database=db.engine.dialect.name)
