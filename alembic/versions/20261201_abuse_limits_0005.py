"""abuse limits: the number of places a study takes

Revision ID: 0005_abuse_limits
Revises: 0004_participant_ux
Create Date: 2026-12-01 23:40:00
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = '0005_abuse_limits'
down_revision: str | None = '0004_participant_ux'
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    """Apply this migration."""
    with op.batch_alter_table('studies', schema=None) as batch_op:
        batch_op.add_column(sa.Column('places', sa.Integer(), nullable=True))


def downgrade() -> None:
    """Revert this migration."""
    with op.batch_alter_table('studies', schema=None) as batch_op:
        batch_op.drop_column('places')
