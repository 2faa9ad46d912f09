"""Labeler quality control of a run, set by an operator: redundancy (labels from distinct labelers
per query) and the gold rate (share of each labeler's segments that are gold)."""

from __future__ import annotations

from fastapi import APIRouter

from backend.routes.deps import DB, OperatorCaller, RunId
from backend.services import runs
from collie.schemas import QualitySettings, RunRead

router = APIRouter(prefix="/runs/{run_id}", tags=["control"])


@router.put("/quality")
async def set_quality(run_id: RunId, body: QualitySettings, _: OperatorCaller, db: DB) -> RunRead:
    with db.write() as conn:
        return runs.set_quality(conn, run_id, body)
