"""cheap polls: a version on each task session, so that a poll can tell "nothing new" from one small query

Revision ID: 0010_poll_versions
Revises: 0009_participant_page
Create Date: 2026-12-02 04:00:00
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = '0010_poll_versions'
down_revision: str | None = '0009_participant_page'
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    """Apply this migration."""
    with op.batch_alter_table('task_sessions', schema=None) as batch_op:
        batch_op.add_column(sa.Column('version', sa.Integer(), server_default='1', nullable=False))


def downgrade() -> None:
    """Revert this migration."""
    with op.batch_alter_table('task_sessions', schema=None) as batch_op:
        batch_op.drop_column('version')
