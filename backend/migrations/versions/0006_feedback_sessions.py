"""feedback_sessions: one row per (run, session position), unique, so a session is posted once and a
resumed trainer gets the stored one back. Filled from the queries already stored.

Revision ID: 0006
Revises: 0005
Create Date: 2026-12-01 10:00:00.000000
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0006"
down_revision = "0005"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "feedback_sessions",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("run_id", sa.Integer(), nullable=False),
        sa.Column("session", sa.Integer(), nullable=False),
        sa.Column("epoch", sa.Integer(), nullable=False),
        sa.Column("created_at", sa.Float(), nullable=False),
        sa.ForeignKeyConstraint(["run_id"], ["runs.id"]),
        sa.PrimaryKeyConstraint("id"),
        sa.UniqueConstraint("run_id", "session", name="uq_feedback_sessions_run_session"),
    )
    op.execute(
        "INSERT INTO feedback_sessions (run_id, session, epoch, created_at) "
        "SELECT run_id, session, MIN(epoch), MIN(created_at) FROM queries GROUP BY run_id, session"
    )


def downgrade() -> None:
    op.drop_table("feedback_sessions")
