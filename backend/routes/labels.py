"""Labels: submit (or skip), undo, and read them back as events, effective labels or an export."""

from __future__ import annotations

from typing import Annotated, Literal

from fastapi import APIRouter, Query, Request, Response

from backend.routes.deps import (
    DB,
    AnyCaller,
    LabelerCaller,
    LeaseS,
    OperatorCaller,
    PrincipalId,
    RunId,
    SettingsDep,
    TrainerCaller,
    json_body,
    parse_body,
)
from backend.routes.responses import LABELLING, Responses
from backend.services import export, labels, leases
from backend.services.errors import ServiceError
from collie.schemas import (
    MAX_HOLD,
    MAX_INT,
    EffectiveLabel,
    LabelAck,
    LabelEventRead,
    LabelSubmit,
    MyLabel,
    UndoRequest,
    VotesDiscarded,
)

router = APIRouter(prefix="/runs/{run_id}", tags=["labels"])


def _ack_response(ack: LabelAck, next_claim: bytes | None = None) -> Response:
    # 201 for a new event, 200 for a repeated client_request_id. The next query is spliced in as
    # the claim endpoint would send it (already JSON).
    body = ack.model_dump_json(exclude={"next"}).encode()
    if next_claim is not None:
        body = body[:-1] + b',"next":' + next_claim + b"}"
    return Response(body, status_code=200 if ack.duplicate else 201, media_type="application/json")


_REPEAT: Responses = {200: {"description": "a repeat of an earlier client_request_id", "model": LabelAck}}


@router.post(
    "/labels",
    response_model=LabelAck,
    status_code=201,
    responses={**_REPEAT, **LABELLING},
    openapi_extra=json_body(LabelSubmit),
)
async def submit_label(
    run_id: RunId,
    request: Request,
    caller: LabelerCaller,
    db: DB,
    settings: SettingsDep,
    next: Annotated[bool, Query(description="also claim the next query (one round trip per label)")] = False,
    hold: Annotated[
        int, Query(ge=1, le=MAX_HOLD, description="with next: the held query to return (2: the one to preload)")
    ] = 1,
    lease_s: LeaseS = None,
) -> Response:
    """A label (0 bad, 1 neutral, 2 good) or "skip" for a query you hold (or labelled: a revision).
    A submission naming its `tab` is taken only from the tab holding the lease (409 NotHeld)."""
    body = await parse_body(request, LabelSubmit)
    with db.write() as conn:
        ack = labels.submit(conn, run_id, caller, body)
        if not next:
            return _ack_response(ack)
        try:  # in the same transaction: one commit per labeler round trip
            following = leases.claim(conn, run_id, caller, lease_s or settings.lease_s, hold, body.tab)
        except ServiceError:  # e.g. the run is being stopped: the label stands, there is no next
            following = None
    return _ack_response(ack, following)


@router.post("/undo", response_model=LabelAck, status_code=201, responses=_REPEAT, openapi_extra=json_body(UndoRequest))
async def undo(
    run_id: RunId, request: Request, caller: LabelerCaller, db: DB, settings: SettingsDep, lease_s: LeaseS = None
) -> Response:
    """Withdraw the effective label; your own comes back to you under a fresh lease to relabel."""
    body = await parse_body(request, UndoRequest)
    with db.write() as conn:
        return _ack_response(labels.undo(conn, run_id, caller, body, lease_s or settings.lease_s))


@router.post("/labelers/{labeler_id}/discard")
def discard_votes(run_id: RunId, labeler_id: PrincipalId, caller: OperatorCaller, db: DB) -> VotesDiscarded:
    """Withdraw every label one labeler gave in this run (the trainer is told of each effective label
    withdrawn; the queries go back to the pool for others)."""
    with db.write() as conn:
        return labels.discard_votes(conn, run_id, labeler_id, caller)


@router.get("/labels")
def list_label_events(
    run_id: RunId,
    caller: AnyCaller,
    db: DB,
    after: Annotated[int, Query(ge=0, le=MAX_INT)] = 0,
    limit: Annotated[int, Query(ge=1, le=10_000)] = 1000,
) -> list[LabelEventRead]:
    """The run's label events in order; a labeler gets their own only (another's vote, seen before
    theirs on a query that may still come to them, defeats redundancy's independent votes)."""
    mine = caller.id if caller.role == "labeler" else None
    with db.read() as conn:
        return labels.list_events(conn, run_id, after, limit, mine)


@router.get("/labels/mine")
def my_labels(run_id: RunId, caller: LabelerCaller, db: DB) -> list[MyLabel]:
    """The queries you labelled in the run, newest first (your latest label of each), for review."""
    with db.read() as conn:
        return labels.my_labels(conn, run_id, caller)


@router.get("/labels/effective")
def effective_labels(run_id: RunId, _: AnyCaller, db: DB) -> list[EffectiveLabel]:
    with db.read() as conn:
        return labels.effective_labels(conn, run_id)


@router.get(
    "/export",
    response_class=Response,
    responses={200: {"content": {"application/json": {}, "text/csv": {}}, "description": "the run's labels"}},
)
def export_labels(
    run_id: RunId, _: TrainerCaller, db: DB, format: Literal["json", "csv"] = "json", effective: bool = False
) -> Response:
    with db.read() as conn:
        text = export.render(export.rows(conn, run_id, effective), format, effective)
    media = "application/json" if format == "json" else "text/csv"
    filename = f"run-{run_id}-{'effective' if effective else 'events'}.{format}"
    return Response(text, media_type=media, headers={"Content-Disposition": f'attachment; filename="{filename}"'})
