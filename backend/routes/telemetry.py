"""Evaluation metrics and rollouts: posted by the trainer, read by the live views (bounded)."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query, Request

from backend.routes.deps import DB, AnyCaller, RunId, TrainerCaller, json_body, parse_body
from backend.services import telemetry
from collie.schemas import MAX_INT, MetricsIn, MetricsRead, RolloutsIn, RolloutsRead

router = APIRouter(prefix="/runs/{run_id}", tags=["rollouts and metrics"])


@router.post("/metrics", status_code=201, openapi_extra=json_body(MetricsIn))
async def post_metrics(run_id: RunId, request: Request, _: TrainerCaller, db: DB) -> MetricsRead:
    body = await parse_body(request, MetricsIn)
    with db.write() as conn:
        return telemetry.post_metrics(conn, run_id, body)


@router.get("/metrics")
def list_metrics(
    run_id: RunId,
    _: AnyCaller,
    db: DB,
    after_epoch: Annotated[int | None, Query(ge=0, le=MAX_INT)] = None,
    limit: Annotated[int, Query(ge=1, le=10_000)] = 1000,
) -> list[MetricsRead]:
    with db.read() as conn:
        return telemetry.list_metrics(conn, run_id, after_epoch, limit)


@router.post("/rollouts", status_code=201, openapi_extra=json_body(RolloutsIn))
async def post_rollouts(run_id: RunId, request: Request, _: TrainerCaller, db: DB) -> RolloutsRead:
    """Read only once the caller is authorised (the body may be 16 MiB)."""
    body = await parse_body(request, RolloutsIn)
    with db.write() as conn:
        return telemetry.post_rollouts(conn, run_id, body)


@router.get("/rollouts")
def list_rollouts(
    run_id: RunId,
    _: AnyCaller,
    db: DB,
    limit: Annotated[int, Query(ge=1, le=50)] = 5,
    states: Annotated[bool, Query(description="include each rollout's qpos (for a 3D replay)")] = True,
) -> list[RolloutsRead]:
    with db.read() as conn:
        return telemetry.list_rollouts(conn, run_id, limit, states)
