"""Liveness and database reachability; needs no token."""

from __future__ import annotations

from fastapi import APIRouter
from sqlalchemy import text
from sqlalchemy.exc import DBAPIError

from backend import __version__
from backend.routes.deps import DB
from backend.services.errors import DatabaseUnreachable
from collie.schemas import ErrorBody, Health

router = APIRouter(tags=["health"])


@router.get("/health", responses={503: {"model": ErrorBody, "description": "the database is unreachable"}})
def health(db: DB) -> Health:
    try:
        with db.read() as conn:
            conn.execute(text("SELECT 1"))
    except DBAPIError as exc:  # whatever the cause, the database does not answer: 503 with Retry-After
        raise DatabaseUnreachable(exc.orig) from None
    return Health(status="ok", version=__version__, database=db.engine.dialect.name)
