"""Runs: created by the trainer; read by everyone; status (and epoch) reported by the trainer."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query, Request, Response

from backend.routes.deps import DB, AnyCaller, RunId, TrainerCaller, json_body, parse_body
from backend.routes.responses import Responses
from backend.services import runs
from collie.schemas import MAX_INT, RunCreate, RunExtend, RunRead, RunStatus, StatusUpdate

router = APIRouter(prefix="/runs", tags=["runs"])


_REPEAT: Responses = {
    200: {"description": "a repeat of an earlier client_request_id: the run it made", "model": RunRead}
}


@router.post("", status_code=201, responses=_REPEAT, openapi_extra=json_body(RunCreate))
async def create_run(request: Request, response: Response, caller: TrainerCaller, db: DB) -> RunRead:
    body = await parse_body(request, RunCreate)
    with db.write() as conn:
        run, repeat = runs.create(conn, caller, body)
    if repeat:
        response.status_code = 200
    return run


@router.get("")
def list_runs(
    caller: AnyCaller,
    db: DB,
    status: RunStatus | None = None,
    limit: Annotated[int, Query(ge=1, le=1000)] = 100,
    offset: Annotated[int, Query(ge=0, le=MAX_INT)] = 0,
) -> list[RunRead]:
    with db.read() as conn:
        return runs.list_runs(conn, status, limit, offset, caller.runs)


@router.get("/{run_id}")
async def get_run(run_id: RunId, _: AnyCaller, db: DB) -> RunRead:
    with db.read() as conn:
        return runs.get(conn, run_id)


@router.put("/{run_id}/status", openapi_extra=json_body(StatusUpdate))
async def set_status(run_id: RunId, request: Request, _: TrainerCaller, db: DB) -> RunRead:
    body = await parse_body(request, StatusUpdate)
    with db.write() as conn:
        return runs.set_status(conn, run_id, body)


@router.post("/{run_id}/extend", openapi_extra=json_body(RunExtend))
async def extend(run_id: RunId, request: Request, _: TrainerCaller, db: DB) -> RunRead:
    body = await parse_body(request, RunExtend)
    with db.write() as conn:
        return runs.extend(conn, run_id, body)
