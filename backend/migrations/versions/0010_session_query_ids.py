"""feedback_sessions.query_ids: the ids a session was posted with, so a re-post of its position
answers the same list even when some ids belonged to earlier sessions.

Revision ID: 0010
Revises: 0009
Create Date: 2026-12-05 04:00:00.000000
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0010"
down_revision = "0009"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("feedback_sessions", schema=None) as batch_op:
        batch_op.add_column(sa.Column("query_ids", sa.JSON(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("feedback_sessions", schema=None) as batch_op:
        batch_op.drop_column("query_ids")
