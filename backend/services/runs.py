"""Runs: created by a trainer, status reported by the trainer, control (run / pause / stop) and the
feedback timeout policy and the labeler quality control (redundancy, gold rate) set by an operator.
Every change but the last goes on the run's stream (the trainer does not need it)."""

from __future__ import annotations

import time
from typing import Any

from sqlalchemy import Connection, case, func, insert, select, update
from sqlalchemy.exc import IntegrityError

from backend.models import Query, Run
from backend.services import events
from backend.services.auth import Caller
from backend.services.errors import Conflict, Invalid, NotFound
from collie.schemas import (
    FINISHED,
    Control,
    ControlChanged,
    FeedbackPolicy,
    PolicyChanged,
    QualitySettings,
    QueueCounts,
    RunCreate,
    RunExtend,
    RunInstructions,
    RunRead,
    StatusChanged,
    StatusUpdate,
)
from collie.tasks import get_task, to_definition

_CONTROL_OF_ACTION: dict[str, Control] = {"pause": "pause", "resume": "run", "stop": "stop"}


def stored_definition(spec: RunCreate) -> dict[str, Any] | None:
    """The rule the run keeps: the one posted, else the built-in task of that name (package code,
    not a user's file); None for an instruction-only run. A name no built-in has for the env is
    refused (422): a run without a rule or an instruction gives labelers nothing to judge by."""
    if spec.task_definition is not None:
        return spec.task_definition.to_json()
    if spec.instruction is not None:
        return None
    seed = spec.config.get("seed")
    try:
        task = get_task(spec.task, spec.env, layout_seed=seed if isinstance(seed, int) else None)
        return to_definition(task, source="builtin").to_json()
    except ValueError as exc:
        raise Invalid(f"{exc}: post the run's task_definition, or an instruction") from None


def create(conn: Connection, caller: Caller, spec: RunCreate) -> tuple[RunRead, bool]:
    """The run made, and whether it was made before: a repeat of the caller's client_request_id
    answers the run the first made (a different run under the same id is refused, 409)."""
    made = _made_before(conn, caller, spec)
    if made is not None:
        return made, True
    now = time.time()
    try:
        with conn.begin_nested():  # PostgreSQL: a repeat racing the first's insert loses on the unique index
            run_id = _insert(conn, caller, spec, now)
    except IntegrityError:
        if (made := _made_before(conn, caller, spec)) is None:
            raise
        return made, True
    events.append(conn, run_id, StatusChanged(status="training", epoch=0), now)
    return get(conn, run_id), False


def _made_before(conn: Connection, caller: Caller, spec: RunCreate) -> RunRead | None:
    """The run an earlier create of the caller's with this client_request_id made (None for none,
    or no id); Conflict if it is another run than `spec` describes, rule included."""
    if spec.client_request_id is None:
        return None
    columns = (Run.id, Run.env, Run.task, Run.method, Run.config, Run.task_definition, Run.instruction)
    made = conn.execute(
        select(*columns).where(Run.created_by == caller.id, Run.client_request_id == spec.client_request_id)
    ).first()
    if made is None:
        return None
    asked = (spec.env, spec.task, spec.method, spec.config, stored_definition(spec), spec.instruction)
    if (made.env, made.task, made.method, made.config, made.task_definition, made.instruction) != asked:
        raise Conflict(f"client_request_id '{spec.client_request_id}' was already used for another run (run {made.id})")
    return get(conn, made.id)


def _insert(conn: Connection, caller: Caller, spec: RunCreate, now: float) -> int:
    return conn.execute(
        insert(Run)
        .values(
            env=spec.env,
            task=spec.task,
            method=spec.method,
            config=spec.config,
            dims=spec.dims.model_dump(),
            status="training",
            control="run",
            epoch=0,
            n_labels=0,
            n_total=spec.n_total,
            epochs_total=spec.epochs_total,
            feedback_timeout_s=spec.feedback_timeout_s,
            redundancy=spec.redundancy,
            gold_rate=spec.gold_rate,
            task_definition=stored_definition(spec),
            instruction=spec.instruction,
            last_event_id=0,
            created_by=caller.id,
            client_request_id=spec.client_request_id,
            created_at=now,
            updated_at=now,
        )
        .returning(Run.id)
    ).scalar_one()


def _counts(conn: Connection, run_ids: list[int] | None) -> dict[int, QueueCounts]:
    """Queue sizes per run; a leased query whose lease ran out counts as pending. Gold copies are
    no query of the run's (services/gold.py)."""
    expired = (Query.status == "leased") & (Query.lease_expires_at < time.time())
    stmt = (
        select(
            Query.run_id,
            func.sum(case(((Query.status == "pending") | expired, 1), else_=0)),
            func.sum(case(((Query.status == "leased") & ~expired, 1), else_=0)),
            func.sum(case((Query.status == "labelled", 1), else_=0)),
            func.sum(case((Query.status == "retired", 1), else_=0)),
        )
        .where(Query.gold_of.is_(None))
        .group_by(Query.run_id)
    )
    if run_ids is not None:
        stmt = stmt.where(Query.run_id.in_(run_ids))
    return {
        r[0]: QueueCounts(
            pending=int(r[1] or 0), leased=int(r[2] or 0), labelled=int(r[3] or 0), retired=int(r[4] or 0)
        )
        for r in conn.execute(stmt)
    }


def _read(row: Any, counts: QueueCounts) -> RunRead:
    return RunRead(
        id=row.id,
        env=row.env,
        task=row.task,
        method=row.method,
        config=row.config,
        dims=row.dims,
        status=row.status,
        control=row.control,
        epoch=row.epoch,
        n_labels=row.n_labels,
        n_total=row.n_total,
        epochs_total=row.epochs_total,
        last_event_id=row.last_event_id,
        queue=counts,
        created_at=row.created_at,
        updated_at=row.updated_at,
        feedback_timeout_s=row.feedback_timeout_s,
        redundancy=row.redundancy,
        gold_rate=row.gold_rate,
        task_definition=row.task_definition,
        instruction=row.instruction,
        instructions=row.instructions or "",
        trainer_seen_at=row.trainer_seen_at,
    )


def ended(run_id: int, status: str, control: str) -> str:
    """How an ended run is named in a refusal: one an operator stopped is said to be stopped (its
    status is "finished", as the trainer reports it), never finished."""
    stopped = control == "stop" and status != "failed"  # a run that failed while stopping failed
    return f"run {run_id} was stopped by an operator" if stopped else f"run {run_id} is {status}"


def row(conn: Connection, run_id: int) -> Any:
    found = conn.execute(select(Run).where(Run.id == run_id)).first()
    if found is None:
        raise NotFound(f"no run {run_id}")
    return found


# pg_advisory_xact_lock's first key for session posts ("coll"): a namespace apart from any other lock
POSTS_LOCK = 0x636F6C6C


def posting(conn: Connection, run_id: int) -> None:
    """Posts of feedback sessions to one run take turns until the transaction ends, so the budget's
    count stays true: an advisory lock on PostgreSQL, which, unlike a lock on the run's row, does not
    hold up the label submissions' updates of that row; SQLite's writers take turns already."""
    if conn.dialect.name == "postgresql":
        conn.execute(select(func.pg_advisory_xact_lock(POSTS_LOCK, run_id)))


def get(conn: Connection, run_id: int) -> RunRead:
    found = row(conn, run_id)
    return _read(found, _counts(conn, [run_id]).get(run_id, QueueCounts()))


def list_runs(
    conn: Connection, status: str | None, limit: int, offset: int, only: frozenset[int] | None = None
) -> list[RunRead]:
    """The newest runs (of `only`, for a caller limited to those)."""
    stmt = select(Run).order_by(Run.id.desc()).limit(limit).offset(offset)
    if status is not None:
        stmt = stmt.where(Run.status == status)
    if only is not None:
        stmt = stmt.where(Run.id.in_(sorted(only)))
    rows = conn.execute(stmt).all()
    counts = _counts(conn, [r.id for r in rows])
    return [_read(r, counts.get(r.id, QueueCounts())) for r in rows]


def set_status(conn: Connection, run_id: int, change: StatusUpdate) -> RunRead:
    current = row(conn, run_id)
    if current.status in FINISHED and change.status != current.status:
        raise Conflict(ended(run_id, current.status, current.control))
    epoch = current.epoch if change.epoch is None else change.epoch
    if (change.status, epoch) != (current.status, current.epoch) or change.message:
        now = time.time()
        conn.execute(update(Run).where(Run.id == run_id).values(status=change.status, epoch=epoch, updated_at=now))
        if change.status in FINISHED and current.status not in FINISHED:
            _end_leases(conn, run_id, now)
        events.append(
            conn, run_id, StatusChanged(status=change.status, epoch=epoch, message=change.message or None), now
        )
    return get(conn, run_id)


def _end_leases(conn: Connection, run_id: int, now: float) -> None:
    """A run that ended takes no label: what its labelers' tabs held goes back to the pool now (a
    gold copy is retired, as a released one is), not when each lease runs out (the queue said
    "leased: on a labeler's screen" of segments no screen could label any more)."""
    leased = (Query.run_id == run_id, Query.status == "leased")
    conn.execute(
        update(Query).where(*leased, Query.gold_of.is_not(None)).values(status="retired", lease_expires_at=None)
    )
    conn.execute(
        update(Query).where(*leased).values(status="pending", lease_owner_id=None, lease_tab=None, lease_expires_at=now)
    )


def extend(conn: Connection, run_id: int, body: RunExtend) -> RunRead:
    """More epochs for a run: a run that finished short of them reopens (its trainer resumed with a
    larger --epochs). A run an operator stopped, or one that failed, stays ended."""
    current = row(conn, run_id)
    if current.control == "stop":
        raise Conflict(f"run {run_id} was stopped by an operator: it is not extended")
    if current.status == "failed":
        raise Conflict(f"run {run_id} failed: it is not extended")
    if current.epochs_total is not None and body.epochs_total < current.epochs_total:
        raise Conflict(f"run {run_id} has {current.epochs_total} epochs: extending means more, not {body.epochs_total}")
    if body.epochs_total < (current.epoch or 0):
        raise Conflict(f"run {run_id} has done {current.epoch} epochs: extending means more, not {body.epochs_total}")
    reopens = current.status == "finished" and body.epochs_total > (current.epoch or 0)
    if body.epochs_total != current.epochs_total or reopens:
        now = time.time()
        status = "training" if reopens else current.status
        conn.execute(
            update(Run).where(Run.id == run_id).values(epochs_total=body.epochs_total, status=status, updated_at=now)
        )
        if reopens:
            message = f"extended to {body.epochs_total} epochs"
            events.append(conn, run_id, StatusChanged(status=status, epoch=current.epoch, message=message), now)
    return get(conn, run_id)


def set_control(conn: Connection, run_id: int, action: str) -> RunRead:
    """pause / resume / stop. Stopping is final; the trainer acknowledges by reporting its status."""
    current = row(conn, run_id)
    if current.status in FINISHED:
        raise Conflict(ended(run_id, current.status, current.control))
    wanted = _CONTROL_OF_ACTION[action]
    if current.control == "stop" and wanted != "stop":
        raise Conflict(f"run {run_id} is being stopped")
    if wanted != current.control:
        now = time.time()
        conn.execute(update(Run).where(Run.id == run_id).values(control=wanted, updated_at=now))
        events.append(conn, run_id, ControlChanged(control=wanted), now)
    return get(conn, run_id)


def set_instructions(conn: Connection, run_id: int, body: RunInstructions) -> RunRead:
    """An operator's instructions for the run's labelers (not on the stream: nothing the trainer
    reads; open tabs show them with their next segment)."""
    row(conn, run_id)
    conn.execute(update(Run).where(Run.id == run_id).values(instructions=body.text.strip(), updated_at=time.time()))
    return get(conn, run_id)


def set_feedback_policy(conn: Connection, run_id: int, policy: FeedbackPolicy) -> RunRead:
    """How long the trainer waits for a session's labels (None: for every label). The trainer reads
    the "policy" event and re-times the session it is waiting on from the session's start."""
    current = row(conn, run_id)
    if current.status in FINISHED:
        raise Conflict(ended(run_id, current.status, current.control))
    if current.control == "stop":
        raise Conflict(f"run {run_id} is being stopped")
    now = time.time()
    conn.execute(update(Run).where(Run.id == run_id).values(feedback_timeout_s=policy.timeout_s, updated_at=now))
    # always on the stream, also when the column already says so: a trainer restarted with another
    # --feedback-timeout on an existing run still hears the operator's word
    events.append(conn, run_id, PolicyChanged(timeout_s=policy.timeout_s), now)
    return get(conn, run_id)


def set_quality(conn: Connection, run_id: int, settings: QualitySettings) -> RunRead:
    current = row(conn, run_id)
    if current.status in FINISHED:
        raise Conflict(ended(run_id, current.status, current.control))
    given = settings.model_dump(exclude_none=True)  # a field left out keeps the run's value
    conn.execute(update(Run).where(Run.id == run_id).values(**given, updated_at=time.time()))
    return get(conn, run_id)
