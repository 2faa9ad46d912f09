"""Run control by an operator: pause, resume, stop. The trainer polls it and reports its status."""

from __future__ import annotations

from fastapi import APIRouter

from backend.routes.deps import DB, OperatorCaller, RunId
from backend.services import runs
from collie.schemas import RunRead

router = APIRouter(prefix="/runs/{run_id}", tags=["control"])


@router.post("/pause")
async def pause(run_id: RunId, _: OperatorCaller, db: DB) -> RunRead:
    with db.write() as conn:
        return runs.set_control(conn, run_id, "pause")


@router.post("/resume")
async def resume(run_id: RunId, _: OperatorCaller, db: DB) -> RunRead:
    with db.write() as conn:
        return runs.set_control(conn, run_id, "resume")


@router.post("/stop")
async def stop(run_id: RunId, _: OperatorCaller, db: DB) -> RunRead:
    with db.write() as conn:
        return runs.set_control(conn, run_id, "stop")
