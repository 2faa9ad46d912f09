"""Tokens and roles. A token is 32 random bytes (url-safe base64); the service stores only its
sha256 — enough for high-entropy secrets, and a lookup by hash is one indexed read."""

from __future__ import annotations

import hashlib
import secrets
import threading
import time
from dataclasses import dataclass
from typing import Any

from sqlalchemy import Connection, Row, insert, select, update

from backend.db import Database
from backend.models import Principal
from backend.services.errors import Conflict, NotFound
from collie.schemas import LabelerRead, Role

ROLES: tuple[Role, ...] = ("operator", "trainer", "labeler")


@dataclass(frozen=True)
class Caller:
    id: int
    name: str
    role: Role


def hash_token(token: str) -> str:
    return hashlib.sha256(token.encode()).hexdigest()


def new_token() -> str:
    return secrets.token_urlsafe(32)


class TokenCache:
    """Resolved tokens for a few seconds, so a label submission costs no extra read; a revoke in
    this process takes effect at once, elsewhere within `ttl_s`."""

    def __init__(self, ttl_s: float) -> None:
        self.ttl_s = ttl_s
        self._entries: dict[str, tuple[Caller | None, float]] = {}
        self._lock = threading.Lock()

    def resolve(self, db: Database, token: str) -> Caller | None:
        digest = hash_token(token)
        now = time.monotonic()
        hit = self._entries.get(digest)
        if hit is not None and hit[1] > now:
            return hit[0]
        with db.read() as conn:
            caller = lookup(conn, digest)
        with self._lock:
            if len(self._entries) > 10_000:  # bound memory against token spraying
                self._entries.clear()
            self._entries[digest] = (caller, now + self.ttl_s)
        return caller

    def clear(self) -> None:
        with self._lock:
            self._entries.clear()


def lookup(conn: Connection, digest: str) -> Caller | None:
    row = conn.execute(
        select(Principal.id, Principal.name, Principal.role).where(
            Principal.token_sha256 == digest, Principal.revoked_at.is_(None)
        )
    ).first()
    return Caller(row.id, row.name, row.role) if row else None


def bootstrap(conn: Connection, role: Role, token: str) -> None:
    """Make `token` the token of the built-in principal named after `role` (created if missing)."""
    digest = hash_token(token)
    holder = conn.execute(select(Principal.id, Principal.name).where(Principal.token_sha256 == digest)).first()
    if holder is not None and holder.name != role:
        raise Conflict(f"the {role} bootstrap token is already the token of '{holder.name}'")
    existing = conn.execute(select(Principal.id).where(Principal.name == role)).scalar()
    if existing is None:
        conn.execute(insert(Principal).values(name=role, role=role, token_sha256=digest, created_at=time.time()))
    else:
        conn.execute(
            update(Principal).where(Principal.id == existing).values(role=role, token_sha256=digest, revoked_at=None)
        )


def _read(row: Row[Any]) -> LabelerRead:
    return LabelerRead(
        id=row.id, name=row.name, role=row.role, created_at=row.created_at, revoked=row.revoked_at is not None
    )


def create_principal(conn: Connection, name: str, role: Role) -> tuple[LabelerRead, str]:
    if conn.execute(select(Principal.id).where(Principal.name == name)).first():
        raise Conflict(f"name '{name}' is taken")
    token = new_token()
    conn.execute(insert(Principal).values(name=name, role=role, token_sha256=hash_token(token), created_at=time.time()))
    row = conn.execute(select(Principal).where(Principal.name == name)).one()
    return _read(row), token


def list_principals(conn: Connection) -> list[LabelerRead]:
    return [_read(r) for r in conn.execute(select(Principal).order_by(Principal.id))]


def revoke(conn: Connection, principal_id: int) -> LabelerRead:
    row = conn.execute(select(Principal).where(Principal.id == principal_id)).first()
    if row is None:
        raise NotFound(f"no principal {principal_id}")
    if row.revoked_at is None:
        conn.execute(update(Principal).where(Principal.id == principal_id).values(revoked_at=time.time()))
    return _read(conn.execute(select(Principal).where(Principal.id == principal_id)).one())
