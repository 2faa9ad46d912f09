"""Evaluation metrics and rollouts the trainer posts for the live views. Reads are bounded (newest
`limit`); each post is announced on the stream by id only, so the stream stays small."""

from __future__ import annotations

import time
from typing import Any

from sqlalchemy import Connection, delete, insert, select

from backend.models import Metrics, Rollouts
from backend.services import events, runs
from backend.services.errors import Invalid
from collie.schemas import EnvDims, MetricsIn, MetricsPosted, MetricsRead, RolloutsIn, RolloutsPosted, RolloutsRead


def post_metrics(conn: Connection, run_id: int, body: MetricsIn) -> MetricsRead:
    """An evaluation's metrics. Those of its epoch and later ones the run posted before go: a trainer
    restarted from its checkpoint evaluates them again (and drops them from its metrics.jsonl too),
    so the curves never show an epoch twice."""
    runs.row(conn, run_id)
    now = time.time()
    conn.execute(delete(Metrics).where(Metrics.run_id == run_id, Metrics.epoch >= body.epoch))
    row_id = conn.execute(
        insert(Metrics)
        .values(run_id=run_id, epoch=body.epoch, values=body.values, created_at=now)
        .returning(Metrics.id)
    ).scalar_one()
    events.append(conn, run_id, MetricsPosted(id=row_id, epoch=body.epoch, values=body.values), now)
    return MetricsRead(id=row_id, run_id=run_id, epoch=body.epoch, values=body.values, created_at=now)


def list_metrics(conn: Connection, run_id: int, after_epoch: int | None, limit: int) -> list[MetricsRead]:
    runs.row(conn, run_id)
    stmt = select(Metrics).where(Metrics.run_id == run_id)
    if after_epoch is not None:
        stmt = stmt.where(Metrics.epoch > after_epoch)
    rows = conn.execute(stmt.order_by(Metrics.id.desc()).limit(limit)).all()
    return [MetricsRead.model_validate(r, from_attributes=True) for r in reversed(rows)]


def post_rollouts(conn: Connection, run_id: int, body: RolloutsIn) -> RolloutsRead:
    """A rollout's states must be the run's env's (the labeling UI's watch mode replays them)."""
    nq = EnvDims.model_validate(runs.row(conn, run_id).dims).nq
    wrong = [
        f"rollout {i}: qpos width {len(r.qpos[0])}"
        for i, r in enumerate(body.rollouts)
        if r.qpos and len(r.qpos[0]) != nq
    ]
    if wrong:
        raise Invalid(f"rollouts do not match the run's env (nq {nq}): " + "; ".join(wrong[:5]))
    now = time.time()
    data = [r.model_dump() for r in body.rollouts]
    row_id = conn.execute(
        insert(Rollouts).values(run_id=run_id, epoch=body.epoch, rollouts=data, created_at=now).returning(Rollouts.id)
    ).scalar_one()
    events.append(conn, run_id, RolloutsPosted(id=row_id, epoch=body.epoch, n=len(data)), now)
    return RolloutsRead(id=row_id, run_id=run_id, epoch=body.epoch, rollouts=body.rollouts, created_at=now)


def list_rollouts(conn: Connection, run_id: int, limit: int, states: bool = True) -> list[RolloutsRead]:
    """The newest `limit` evaluations, oldest first; without their simulator states unless `states`
    (the plots do not draw them; the labeling UI's watch mode replays them)."""
    runs.row(conn, run_id)
    rows = conn.execute(
        select(Rollouts).where(Rollouts.run_id == run_id).order_by(Rollouts.id.desc()).limit(limit)
    ).all()
    return [read_rollouts(r, states) for r in reversed(rows)]


def read_rollouts(row: Any, states: bool) -> RolloutsRead:  # a Rollouts row
    paths = row.rollouts if states else [{k: v for k, v in r.items() if k != "qpos"} for r in row.rollouts]
    return RolloutsRead(id=row.id, run_id=row.run_id, epoch=row.epoch, rollouts=paths, created_at=row.created_at)
