"""runs.client_request_id: the creating trainer's id for the creation, unique per creator, so a
trainer that lost the answer to POST /runs (it died, or the service restarted) sends it again
and gets the run the first made, not a second one beside it.

Revision ID: 0012
Revises: 0011
Create Date: 2026-12-08 03:00:00.000000
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0012"
down_revision = "0011"
branch_labels = None
depends_on = None


def upgrade() -> None:
    # a column and a unique index: neither rebuilds `runs` on SQLite (a table constraint would, and
    # dropping the old table is refused under foreign keys while queries or metrics point at it)
    with op.batch_alter_table("runs", schema=None) as batch_op:
        batch_op.add_column(sa.Column("client_request_id", sa.String(length=128), nullable=True))
    op.create_index("uq_runs_request", "runs", ["created_by", "client_request_id"], unique=True)


def downgrade() -> None:
    op.drop_index("uq_runs_request", table_name="runs")
    with op.batch_alter_table("runs", schema=None) as batch_op:
        batch_op.drop_column("client_request_id")
