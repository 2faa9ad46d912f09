"""runs.feedback_timeout_s: the operator's feedback timeout policy (null: wait for every label).

Revision ID: 0002
Revises: 0001
Create Date: 2026-11-22 01:40:00.000000
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("runs", schema=None) as batch_op:
        batch_op.add_column(sa.Column("feedback_timeout_s", sa.Float(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("runs", schema=None) as batch_op:
        batch_op.drop_column("feedback_timeout_s")
