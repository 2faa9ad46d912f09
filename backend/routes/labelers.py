"""People and their tokens: an operator creates, lists and revokes principals of any role, and
sets the runs a labeler may work on."""

from __future__ import annotations

from fastapi import APIRouter, Request

from backend.routes.deps import DB, AnyCaller, OperatorCaller, PrincipalId, json_body, parse_body
from backend.services import auth, leases
from backend.services.auth import Caller
from collie.schemas import LabelerCreate, LabelerCreated, LabelerRead, LabelerScope, Me

router = APIRouter(tags=["labelers"])


@router.get("/me")
async def me(caller: AnyCaller) -> Me:
    """Who a token belongs to (the labeling UI greets its labeler with it)."""
    return Me(id=caller.id, name=caller.name, role=caller.role)


@router.post("/labelers", status_code=201, openapi_extra=json_body(LabelerCreate))
async def create_labeler(request: Request, _: OperatorCaller, db: DB) -> LabelerCreated:
    body = await parse_body(request, LabelerCreate)
    with db.write() as conn:
        read, token = auth.create_principal(conn, body.name, body.role, body.runs)
    return LabelerCreated(**read.model_dump(), token=token)


@router.get("/labelers")
def list_labelers(_: OperatorCaller, db: DB) -> list[LabelerRead]:
    with db.read() as conn:
        return auth.list_principals(conn)


@router.delete("/labelers/{labeler_id}")
async def revoke_labeler(labeler_id: PrincipalId, _: OperatorCaller, db: DB, request: Request) -> LabelerRead:
    """Revoke a principal's token: its open streams end and its claims go back to the pool now."""
    with db.write() as conn:
        read = auth.revoke(conn, labeler_id)
        leases.release_all_held_by(conn, Caller(read.id, read.name, read.role))
    request.app.state.tokens.clear()
    request.app.state.feed.end_streams_of(labeler_id)
    return read


@router.put("/labelers/{labeler_id}/runs", openapi_extra=json_body(LabelerScope))
async def set_labeler_runs(labeler_id: PrincipalId, _: OperatorCaller, db: DB, request: Request) -> LabelerRead:
    """Limit a labeler to runs from now on (null: every run); its streams of other runs end now."""
    body = await parse_body(request, LabelerScope)
    with db.write() as conn:
        read = auth.set_runs(conn, labeler_id, body.runs)
    request.app.state.tokens.clear()  # this process applies the new scope at once (others within the cache time)
    request.app.state.feed.end_streams_outside(labeler_id, read.runs)
    return read
