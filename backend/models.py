"""Tables. Label events and stream events are append-only; a query row caches its current status,
lease and effective label (the rule lives in services/labels.py and can always be replayed from the
events). Times are UTC seconds since the epoch (REAL): cheap to compare for lease expiry."""

from __future__ import annotations

from typing import Any

from sqlalchemy import JSON, Float, ForeignKey, Index, Integer, String, Text, UniqueConstraint
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column


class Base(DeclarativeBase):
    pass


class Principal(Base):
    """Anyone holding a token: operators, trainers and labelers (humans or the oracle teacher). A
    revoked principal stays revoked (revoked_at is never cleared)."""

    __tablename__ = "principals"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(64), unique=True)
    role: Mapped[str] = mapped_column(String(16))
    token_sha256: Mapped[str] = mapped_column(String(64), unique=True)
    created_at: Mapped[float] = mapped_column(Float)
    revoked_at: Mapped[float | None] = mapped_column(Float, nullable=True)
    runs: Mapped[list[int] | None] = mapped_column(JSON, nullable=True)  # a labeler limited to these runs


class Run(Base):
    __tablename__ = "runs"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    env: Mapped[str] = mapped_column(String(64))
    task: Mapped[str] = mapped_column(String(64))
    method: Mapped[str] = mapped_column(String(64))
    config: Mapped[dict[str, Any]] = mapped_column(JSON)
    dims: Mapped[dict[str, Any]] = mapped_column(JSON)
    status: Mapped[str] = mapped_column(String(32))
    control: Mapped[str] = mapped_column(String(16))
    epoch: Mapped[int] = mapped_column(Integer)
    n_labels: Mapped[int] = mapped_column(Integer)
    n_total: Mapped[int | None] = mapped_column(Integer, nullable=True)
    epochs_total: Mapped[int | None] = mapped_column(Integer, nullable=True)
    feedback_timeout_s: Mapped[float | None] = mapped_column(Float, nullable=True)  # None: wait for every label
    redundancy: Mapped[int] = mapped_column(Integer, default=1, server_default="1")  # labels per query (r)
    gold_rate: Mapped[float] = mapped_column(Float, default=0.0, server_default="0")  # share of a labeler's queue
    # the run's rule (collie.task_schemas.TaskDefinition JSON), or a person's instruction for a run without one
    task_definition: Mapped[dict[str, Any] | None] = mapped_column(JSON, nullable=True)
    instruction: Mapped[str | None] = mapped_column(Text, nullable=True)
    instructions: Mapped[str] = mapped_column(Text, default="", server_default="")  # an operator's, for labelers
    last_event_id: Mapped[int] = mapped_column(Integer)
    created_by: Mapped[int] = mapped_column(ForeignKey("principals.id"))
    created_at: Mapped[float] = mapped_column(Float)
    updated_at: Mapped[float] = mapped_column(Float)
    trainer_seen_at: Mapped[float | None] = mapped_column(Float, nullable=True)  # its trainer's last call
    # the creating trainer's id for the creation: a repeat answers this run (services/runs.py)
    client_request_id: Mapped[str | None] = mapped_column(String(128), nullable=True)

    # an index, not a table constraint: SQLite adds it without rebuilding `runs`, which the rows
    # pointing at runs (queries, metrics, …) would refuse under foreign keys
    __table_args__ = (Index("uq_runs_request", "created_by", "client_request_id", unique=True),)


class Query(Base):
    """One segment offered for labelling (its bulky frames live in QueryData, so the frequent small
    updates of status and lease rewrite one short row)."""

    __tablename__ = "queries"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id"))
    query_id: Mapped[str] = mapped_column(String(64))
    session: Mapped[int] = mapped_column(Integer)
    epoch: Mapped[int] = mapped_column(Integer)
    start: Mapped[int] = mapped_column(Integer)
    score: Mapped[float] = mapped_column(Float)
    status: Mapped[str] = mapped_column(String(16))
    lease_owner_id: Mapped[int | None] = mapped_column(ForeignKey("principals.id"), nullable=True)
    lease_expires_at: Mapped[float | None] = mapped_column(Float, nullable=True)
    # the labeler's tab the lease is for (null: a claim made without one); only it may label the query
    lease_tab: Mapped[str | None] = mapped_column(String(64), nullable=True)
    label: Mapped[int | None] = mapped_column(Integer, nullable=True)
    label_event_id: Mapped[int | None] = mapped_column(Integer, nullable=True)
    created_at: Mapped[float] = mapped_column(Float)
    # A gold copy (services/gold.py): the query it re-serves and the task rule's answer. Gold rows
    # are one labeler's, never claimable by others, never on the trainer's stream or pages.
    gold_of: Mapped[int | None] = mapped_column(ForeignKey("queries.id"), nullable=True)
    gold_answer: Mapped[int | None] = mapped_column(Integer, nullable=True)

    __table_args__ = (
        UniqueConstraint("run_id", "query_id", name="uq_queries_run_query"),
        Index("ix_queries_claim", "run_id", "status", "session", "id"),
        Index("ix_queries_lease", "run_id", "status", "lease_expires_at"),
    )


class FeedbackSession(Base):
    """One feedback session of a run, by its position in the trainer's schedule (0, 1, …): posted
    once; a trainer that replays that position after a restart gets this one back."""

    __tablename__ = "feedback_sessions"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id"))
    session: Mapped[int] = mapped_column(Integer)
    epoch: Mapped[int] = mapped_column(Integer)
    created_at: Mapped[float] = mapped_column(Float)
    # the posted query ids in order, some of which may be earlier sessions' (null: before 0010)
    query_ids: Mapped[list[str] | None] = mapped_column(JSON, nullable=True)

    __table_args__ = (UniqueConstraint("run_id", "session", name="uq_feedback_sessions_run_session"),)


class QueryData(Base):
    """A query's frames: the JSON of collie.schemas.QueryFrames, written once, and its extra."""

    __tablename__ = "query_data"
    query_pk: Mapped[int] = mapped_column(ForeignKey("queries.id"), primary_key=True)
    frames: Mapped[str] = mapped_column(Text)
    extra: Mapped[dict[str, Any]] = mapped_column(JSON)


class LabelEvent(Base):
    """Append-only: label (value 0/1/2), skip (not a label) or undo (withdraws the effective label)."""

    __tablename__ = "label_events"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id"))
    query_pk: Mapped[int] = mapped_column(ForeignKey("queries.id"))
    labeler_id: Mapped[int] = mapped_column(ForeignKey("principals.id"))
    kind: Mapped[str] = mapped_column(String(8))
    value: Mapped[int | None] = mapped_column(Integer, nullable=True)
    seconds: Mapped[float | None] = mapped_column(Float, nullable=True)
    client_request_id: Mapped[str] = mapped_column(String(128))
    revises_event_id: Mapped[int | None] = mapped_column(ForeignKey("label_events.id"), nullable=True)
    created_at: Mapped[float] = mapped_column(Float)
    # the redundancy r the query was under when this was recorded (null: recorded before 0009)
    redundancy: Mapped[int | None] = mapped_column(Integer, nullable=True)

    __table_args__ = (
        UniqueConstraint("labeler_id", "client_request_id", name="uq_label_events_request"),
        Index("ix_label_events_query", "query_pk", "id"),
        Index("ix_label_events_run", "run_id", "id"),
    )


class LabelVote(Base):
    """Each labeler's current label of a query (a cache of the label events, like Query.label): one
    row per (query, labeler), replaced by a revision, deleted by an undo. The effective label is the
    consensus of these once a run's redundancy is reached (services/consensus.py)."""

    __tablename__ = "label_votes"
    query_pk: Mapped[int] = mapped_column(ForeignKey("queries.id"), primary_key=True)
    labeler_id: Mapped[int] = mapped_column(ForeignKey("principals.id"), primary_key=True)
    value: Mapped[int] = mapped_column(Integer)
    event_id: Mapped[int] = mapped_column(ForeignKey("label_events.id"))


class StreamEvent(Base):
    """What a run's stream carries, in order; `seq` is the per-run id clients resume from."""

    __tablename__ = "stream_events"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id"))
    seq: Mapped[int] = mapped_column(Integer)
    kind: Mapped[str] = mapped_column(String(16))
    data: Mapped[dict[str, Any]] = mapped_column(JSON)
    created_at: Mapped[float] = mapped_column(Float)

    __table_args__ = (UniqueConstraint("run_id", "seq", name="uq_stream_events_run_seq"),)


class Metrics(Base):
    __tablename__ = "metrics"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id"), index=True)
    epoch: Mapped[int] = mapped_column(Integer)
    values: Mapped[dict[str, float]] = mapped_column(JSON)
    created_at: Mapped[float] = mapped_column(Float)


class Rollouts(Base):
    __tablename__ = "rollouts"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id"), index=True)
    epoch: Mapped[int] = mapped_column(Integer)
    rollouts: Mapped[list[dict[str, Any]]] = mapped_column(JSON)
    created_at: Mapped[float] = mapped_column(Float)
