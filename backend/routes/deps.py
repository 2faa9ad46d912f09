"""What every route needs: the database, the settings, and the caller (token → role)."""

from __future__ import annotations

import gc
import threading
from collections.abc import Awaitable, Callable, Iterator
from contextlib import contextmanager
from typing import Annotated, Any, TypeVar

import anyio
from fastapi import Depends, HTTPException, Path, Query, Request
from fastapi.exceptions import RequestValidationError
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from pydantic import BaseModel, ValidationError
from sqlalchemy import select

from backend.db import Database
from backend.models import Run
from backend.services.auth import Caller, TokenCache
from backend.services.errors import RunOutOfScope
from backend.services.events import EventHub
from backend.settings import Settings
from collie.schemas import MAX_INT, MAX_LEASE_S, PART_HEADER, Role

bearer = HTTPBearer(auto_error=False, description="a role token: operator, trainer or labeler")

ANY: tuple[Role, ...] = ("operator", "trainer", "labeler")
TRAINER: tuple[Role, ...] = ("trainer",)
LABELER: tuple[Role, ...] = ("labeler",)
OPERATOR: tuple[Role, ...] = ()


def json_body(model: type[BaseModel]) -> dict[str, Any]:
    """OpenAPI for a route that reads its body itself (see parse_body); main.py adds the schema."""
    schema = {"$ref": f"#/components/schemas/{model.__name__}"}
    return {"requestBody": {"required": True, "content": {"application/json": {"schema": schema}}}}


M = TypeVar("M", bound=BaseModel)

OFF_LOOP_BYTES = 256 * 1024  # bodies larger than this are validated in a worker thread
_gc_lock = threading.Lock()
_gc_pauses = 0
_gc_was_enabled = False


@contextmanager
def _gc_paused() -> Iterator[None]:
    """A big body is millions of new float and list objects: the cycle collector would run over
    them again and again while they are built (and free nothing). Paused while any parse runs."""
    global _gc_pauses, _gc_was_enabled
    with _gc_lock:
        if _gc_pauses == 0:
            _gc_was_enabled = gc.isenabled()
            gc.disable()
        _gc_pauses += 1
    try:
        yield
    finally:
        with _gc_lock:
            _gc_pauses -= 1
            if _gc_pauses == 0 and _gc_was_enabled:
                gc.enable()


def _validate(model: type[M], raw: bytes | bytearray) -> M:
    with _gc_paused():
        try:
            return model.model_validate_json(raw)
        except ValidationError as exc:
            errors = [{**e, "loc": ("body", *e["loc"])} for e in exc.errors(include_url=False)]
            raise RequestValidationError(errors) from None


async def read_body(request: Request) -> bytearray:
    """The body in one buffer grown as it arrives: no list of chunks joined into a second copy, and
    nothing reserved from Content-Length, which a client that never sends the body could name to
    hold that much memory per connection (BodyLimit caps both the header and what arrives)."""
    buffer = bytearray()
    async for chunk in request.stream():
        buffer += chunk
    return buffer


async def parse_body(request: Request, model: type[M]) -> M:
    """Validate the raw JSON body in one pass (pydantic's parser, about twice as fast as FastAPI's
    json.loads followed by validation). Called inside a route, so only after its dependencies
    authenticated and authorised the caller; a large body is validated off the event loop, so
    it stalls no other request."""
    raw = await read_body(request)
    if len(raw) <= OFF_LOOP_BYTES:
        return _validate(model, raw)
    return await anyio.to_thread.run_sync(_validate, model, raw)


# Dependencies are coroutines on purpose: FastAPI runs plain functions in a worker thread.
async def get_db(request: Request) -> Database:
    return request.app.state.db


async def get_settings(request: Request) -> Settings:
    return request.app.state.settings


async def get_hub(request: Request) -> EventHub:
    return request.app.state.hub


def authenticate(request: Request, token: str | None) -> Caller:
    cache: TokenCache = request.app.state.tokens
    caller = cache.resolve(request.app.state.db, token) if token else None
    if caller is None:
        detail = "missing bearer token" if not token else "unknown or revoked token"
        raise HTTPException(401, detail, headers={"WWW-Authenticate": "Bearer"})
    return caller


def path_run_id(request: Request) -> int | None:
    """The run in the path, if any. Only plain ASCII digits name a run: the route's int would also
    read "+1", "1.0", " 1" or "1_0" (run 10), and a scope checked on anything but the id the route
    acts on is no check. Any other form is refused here, before the route (422)."""
    if "run_id" not in request.path_params:
        return None
    raw = str(request.path_params["run_id"])
    # the length first: int() refuses more than 4300 digits (a ValueError, a 500)
    if not (raw.isascii() and raw.isdigit()) or len(raw) > len(str(MAX_INT)) or not 1 <= int(raw) <= MAX_INT:
        msg = f"not a run's number: {raw!r} (digits 0-9 only, 1 to {MAX_INT})"
        raise RequestValidationError([{"type": "run_id", "loc": ("path", "run_id"), "msg": msg, "input": raw}])
    return int(raw)


def check_scope(request: Request, caller: Caller, roles: tuple[Role, ...]) -> None:
    """The run in the path must be in the caller's scope: a labeler limited to runs sees only
    those; on a trainer's own routes (sessions, status, telemetry, …) a trainer acts only on the
    runs it created. An unknown run is left to the route (404); a malformed id is refused (422)."""
    run_id = path_run_id(request)
    if run_id is None:
        return
    if caller.role == "operator":
        return
    if not caller.may_see(run_id):
        raise RunOutOfScope(run_id, "other_runs", f"this token is limited to other runs than run {run_id}")
    if caller.role == "trainer" and roles == TRAINER:
        db: Database = request.app.state.db
        with db.read() as conn:
            creator = conn.execute(select(Run.created_by).where(Run.id == run_id)).scalar()
        if creator is not None and creator != caller.id:
            raise RunOutOfScope(run_id, "other_trainer", f"run {run_id} was created by another trainer")


def note_trainer_contact(request: Request, caller: Caller) -> None:
    """A call from a run's trainer process (its event poll, status, sessions; an operator's token
    may drive it) says the trainer is alive: runs.trainer_seen_at, for the dashboard."""
    run_id = path_run_id(request)
    if run_id is not None and request.headers.get(PART_HEADER) == "trainer" and caller.role in ("trainer", "operator"):
        request.app.state.trainer_contact.heard(request.app.state.db, run_id, caller)


def allow(*roles: Role) -> Callable[..., Awaitable[Caller]]:
    """Dependency: the caller, if their role is one of `roles` (operators may do everything) and the
    run in the path is in their scope."""

    async def dependency(
        request: Request, credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(bearer)]
    ) -> Caller:
        caller = authenticate(request, credentials.credentials if credentials else None)
        if caller.role != "operator" and caller.role not in roles:
            raise HTTPException(403, f"a {caller.role} token may not do this")
        check_scope(request, caller, roles)
        note_trainer_contact(request, caller)
        return caller

    return dependency


RunId = Annotated[int, Path(ge=1, le=MAX_INT)]
PrincipalId = Annotated[int, Path(ge=1, le=MAX_INT)]
DB = Annotated[Database, Depends(get_db)]
SettingsDep = Annotated[Settings, Depends(get_settings)]
Hub = Annotated[EventHub, Depends(get_hub)]
AnyCaller = Annotated[Caller, Depends(allow(*ANY))]
TrainerCaller = Annotated[Caller, Depends(allow(*TRAINER))]
LabelerCaller = Annotated[Caller, Depends(allow(*LABELER))]
OperatorCaller = Annotated[Caller, Depends(allow(*OPERATOR))]
# A claim's lease length, asked for by the client (the labeling UI renews its own every lease/3);
# none: the service's setting.
LeaseS = Annotated[
    float | None, Query(gt=0, le=MAX_LEASE_S, allow_inf_nan=False, description="lease length; default: settings")
]
