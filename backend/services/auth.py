"""Tokens and roles. A token is 32 random bytes (url-safe base64); the service stores only its
sha256 — enough for high-entropy secrets, and a lookup by hash is one indexed read.

Scopes (docs/service.md): an operator may do everything; a trainer acts only on the runs it
created; a labeler may be limited to some runs (`runs`). Revoking is final: nothing — a restart
with the same bootstrap token included — brings a revoked principal back."""

from __future__ import annotations

import hashlib
import threading
import time
from dataclasses import dataclass
from typing import Any

from sqlalchemy import Connection, Row, insert, inspect, select, update

from backend.db import Database, make_engine
from backend.models import Principal, Run
from backend.services.errors import Conflict, Invalid, NotFound
from collie.schemas import LabelerRead, Role
from collie.tokens import random_token

ROLES: tuple[Role, ...] = ("operator", "trainer", "labeler")


@dataclass(frozen=True)
class Caller:
    id: int
    name: str
    role: Role
    runs: frozenset[int] | None = None  # a labeler limited to these runs; None: every run

    def may_see(self, run_id: int) -> bool:
        return self.runs is None or run_id in self.runs


def hash_token(token: str) -> str:
    return hashlib.sha256(token.encode()).hexdigest()


def new_token() -> str:
    return random_token()


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
        select(Principal.id, Principal.name, Principal.role, Principal.runs).where(
            Principal.token_sha256 == digest, Principal.revoked_at.is_(None)
        )
    ).first()
    if row is None:
        return None
    return Caller(row.id, row.name, row.role, None if row.runs is None else frozenset(row.runs))


def builtin_principals(database_url: str) -> dict[str, bool]:
    """The built-in principals a database already has (none for a new database): name → revoked."""
    engine = make_engine(database_url)
    try:
        with engine.connect() as conn:
            if not inspect(conn).has_table(Principal.__tablename__):
                return {}
            rows = conn.execute(select(Principal.name, Principal.revoked_at).where(Principal.name.in_(ROLES)))
            return {str(row.name): row.revoked_at is not None for row in rows}
    finally:
        engine.dispose()


def bootstrap(conn: Connection, role: Role, token: str, name: str | None = None) -> bool:
    """Make `token` the token of the built-in principal `name` (default: named after `role`; created
    if missing). A revoked built-in principal stays revoked, token and all; returns False for one."""
    name = name or role
    digest = hash_token(token)
    holder = conn.execute(select(Principal.id, Principal.name).where(Principal.token_sha256 == digest)).first()
    if holder is not None and holder.name != name:
        raise Conflict(f"the {name} bootstrap token is already the token of '{holder.name}'")
    existing = conn.execute(select(Principal.id, Principal.revoked_at).where(Principal.name == name)).first()
    if existing is None:
        conn.execute(insert(Principal).values(name=name, role=role, token_sha256=digest, created_at=time.time()))
    elif existing.revoked_at is not None:
        return False
    else:
        conn.execute(update(Principal).where(Principal.id == existing.id).values(role=role, token_sha256=digest))
    return True


def _read(row: Row[Any]) -> LabelerRead:
    return LabelerRead(
        id=row.id,
        name=row.name,
        role=row.role,
        created_at=row.created_at,
        revoked=row.revoked_at is not None,
        runs=row.runs,
    )


def _scope(conn: Connection, runs: list[int] | None) -> list[int] | None:
    """A labeler's runs, sorted and checked to exist (None: every run)."""
    scope = None if runs is None else sorted(set(runs))
    if scope:
        known = set(conn.execute(select(Run.id).where(Run.id.in_(scope))).scalars())
        unknown = [str(r) for r in scope if r not in known]
        if unknown:
            raise NotFound(f"no run {', '.join(unknown)}: a labeler's runs must exist")
    return scope


def create_principal(conn: Connection, name: str, role: Role, runs: list[int] | None = None) -> tuple[LabelerRead, str]:
    holder = conn.execute(select(Principal.revoked_at).where(Principal.name == name)).first()
    if holder is not None:
        revoked = " by a revoked principal (revoking is final)" if holder.revoked_at is not None else ""
        raise Conflict(f"name '{name}' is taken{revoked}; choose another name")
    token = new_token()
    scope = _scope(conn, runs)
    conn.execute(
        insert(Principal).values(
            name=name, role=role, token_sha256=hash_token(token), created_at=time.time(), runs=scope
        )
    )
    row = conn.execute(select(Principal).where(Principal.name == name)).one()
    return _read(row), token


def set_runs(conn: Connection, principal_id: int, runs: list[int] | None) -> LabelerRead:
    """Limit a labeler to `runs` from now on (None: every run)."""
    row = conn.execute(select(Principal).where(Principal.id == principal_id)).first()
    if row is None:
        raise NotFound(f"no principal {principal_id}")
    if row.role != "labeler":
        article = "an" if row.role == "operator" else "a"
        raise Invalid(f"only a labeler token can be limited to runs, not {article} {row.role} token ('{row.name}')")
    if row.revoked_at is not None:
        raise Conflict(f"'{row.name}' is revoked: its token is valid for no run, and revoking is final")
    conn.execute(update(Principal).where(Principal.id == principal_id).values(runs=_scope(conn, runs)))
    return _read(conn.execute(select(Principal).where(Principal.id == principal_id)).one())


def list_principals(conn: Connection) -> list[LabelerRead]:
    return [_read(r) for r in conn.execute(select(Principal).order_by(Principal.id))]


def _active_operators(conn: Connection) -> int:
    rows = conn.execute(select(Principal.id).where(Principal.role == "operator", Principal.revoked_at.is_(None)))
    return len(rows.all())


def may_still_see(conn: Connection, principal_id: int, run_id: int) -> bool:
    """The principal exists, is not revoked, and its scope still holds `run_id` (an open stream of
    the run asks, now and then: a change made by another process reaches it so)."""
    found = select(Principal.runs).where(Principal.id == principal_id, Principal.revoked_at.is_(None))
    row = conn.execute(found).first()
    return row is not None and (row.runs is None or run_id in row.runs)


def revoke(conn: Connection, principal_id: int) -> LabelerRead:
    row = conn.execute(select(Principal).where(Principal.id == principal_id)).first()
    if row is None:
        raise NotFound(f"no principal {principal_id}")
    if row.revoked_at is None:
        if row.role == "operator" and _active_operators(conn) <= 1:
            raise Conflict(
                f"'{row.name}' is the last operator: nobody could manage principals after it; "
                "create another operator first"
            )
        conn.execute(update(Principal).where(Principal.id == principal_id).values(revoked_at=time.time()))
    return _read(conn.execute(select(Principal).where(Principal.id == principal_id)).one())
