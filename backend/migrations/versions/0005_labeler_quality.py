"""Labeler quality control: runs.redundancy and runs.gold_rate, gold copies of queries
(queries.gold_of, queries.gold_answer) and label_votes (each labeler's current label of a query),
filled from the labels stored so far (one labeler per query before redundancy existed).

Revision ID: 0005
Revises: 0004
Create Date: 2026-12-01 10:00:00.000000
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0005"
down_revision = "0004"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("runs", schema=None) as batch_op:
        batch_op.add_column(sa.Column("redundancy", sa.Integer(), server_default="1", nullable=False))
        batch_op.add_column(sa.Column("gold_rate", sa.Float(), server_default="0", nullable=False))
    if op.get_bind().dialect.name == "sqlite":
        # ADD COLUMN … REFERENCES in place: a batch copy of `queries` would trip the foreign keys onto it
        op.execute("ALTER TABLE queries ADD COLUMN gold_of INTEGER REFERENCES queries (id)")
    else:
        op.add_column("queries", sa.Column("gold_of", sa.Integer(), sa.ForeignKey("queries.id"), nullable=True))
    op.add_column("queries", sa.Column("gold_answer", sa.Integer(), nullable=True))
    op.create_table(
        "label_votes",
        sa.Column("query_pk", sa.Integer(), nullable=False),
        sa.Column("labeler_id", sa.Integer(), nullable=False),
        sa.Column("value", sa.Integer(), nullable=False),
        sa.Column("event_id", sa.Integer(), nullable=False),
        sa.ForeignKeyConstraint(["event_id"], ["label_events.id"]),
        sa.ForeignKeyConstraint(["labeler_id"], ["principals.id"]),
        sa.ForeignKeyConstraint(["query_pk"], ["queries.id"]),
        sa.PrimaryKeyConstraint("query_pk", "labeler_id"),
    )
    op.execute(
        "INSERT INTO label_votes (query_pk, labeler_id, value, event_id) "
        "SELECT q.id, e.labeler_id, q.label, q.label_event_id FROM queries q "
        "JOIN label_events e ON e.id = q.label_event_id WHERE q.label IS NOT NULL"
    )


def downgrade() -> None:
    op.drop_table("label_votes")
    op.drop_column("queries", "gold_answer")
    op.drop_column("queries", "gold_of")  # SQLite ≥ 3.35 drops a column in place
    with op.batch_alter_table("runs", schema=None) as batch_op:
        batch_op.drop_column("gold_rate")
        batch_op.drop_column("redundancy")
