"""Run control by an operator: pause, resume, stop, and the feedback timeout policy. The trainer
polls them (the run's event log) and reports its status."""

from __future__ import annotations

from fastapi import APIRouter, Request

from backend.routes.deps import DB, OperatorCaller, RunId, json_body, parse_body
from backend.services import runs
from collie.schemas import FeedbackPolicy, RunInstructions, RunRead

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


@router.put("/instructions", openapi_extra=json_body(RunInstructions))
async def instructions(run_id: RunId, request: Request, _: OperatorCaller, db: DB) -> RunRead:
    """Free-text instructions for the run's labelers, shown with the task in the labeling UI."""
    body = await parse_body(request, RunInstructions)
    with db.write() as conn:
        return runs.set_instructions(conn, run_id, body)


@router.post("/feedback-policy", openapi_extra=json_body(FeedbackPolicy))
async def feedback_policy(run_id: RunId, request: Request, _: OperatorCaller, db: DB) -> RunRead:
    """How long the trainer waits for a session's labels before it continues with what arrived
    (null: for every label); applies to the session it is waiting on now."""
    body = await parse_body(request, FeedbackPolicy)
    with db.write() as conn:
        return runs.set_feedback_policy(conn, run_id, body)
