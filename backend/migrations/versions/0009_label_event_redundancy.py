"""label_events.redundancy: the r each label was given under, so the effective labels replay
exactly after an operator changes a run's redundancy.

Revision ID: 0009
Revises: 0008
Create Date: 2026-12-05 04:00:00.000000
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0009"
down_revision = "0008"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("label_events", schema=None) as batch_op:
        batch_op.add_column(sa.Column("redundancy", sa.Integer(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("label_events", schema=None) as batch_op:
        batch_op.drop_column("redundancy")
