"""Labeler quality control of a run, set by an operator: redundancy (labels from distinct labelers
per query) and the gold rate (share of each labeler's segments that are gold)."""

from __future__ import annotations

import time

from fastapi import APIRouter, Request

from backend.routes.deps import DB, OperatorCaller, RunId, json_body, parse_body
from backend.services import labels, runs
from collie.schemas import QualitySettings, RunRead

router = APIRouter(prefix="/runs/{run_id}", tags=["control"])


@router.put("/quality", openapi_extra=json_body(QualitySettings))
async def set_quality(run_id: RunId, request: Request, _: OperatorCaller, db: DB) -> RunRead:
    body = await parse_body(request, QualitySettings)  # read after the caller is checked
    with db.write() as conn:
        if body.redundancy is not None:
            labels.hold_unlabelled(conn, run_id)  # no label in flight decides on the r being replaced
        read = runs.set_quality(conn, run_id, body)
        if body.redundancy is not None and labels.count_reached(conn, run_id, time.time()):
            read = runs.get(conn, run_id)  # counts changed: queries that waited for more labels count now
        return read
