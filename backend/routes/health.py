"""Liveness and database reachability; needs no token."""

from __future__ import annotations

from fastapi import APIRouter
from sqlalchemy import text

from backend import __version__
from backend.routes.deps import DB
from collie.schemas import Health

router = APIRouter(tags=["health"])


@router.get("/health")
def health(db: DB) -> Health:
    with db.read() as conn:
        conn.execute(text("SELECT 1"))
    return Health(status="ok", version=__version__, database=db.engine.dialect.name)
