"""runs.trainer_seen_at: when the run's own trainer last called the service, so an operator sees a
run whose trainer died (it stays "waiting for labels" for good otherwise).

Revision ID: 0011
Revises: 0010
Create Date: 2026-12-06 02:00:00.000000
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0011"
down_revision = "0010"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("runs", schema=None) as batch_op:
        batch_op.add_column(sa.Column("trainer_seen_at", sa.Float(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("runs", schema=None) as batch_op:
        batch_op.drop_column("trainer_seen_at")
