"""participant experience: the robot's playback speed as a study setting

Revision ID: 0004_participant_ux
Revises: 0003_study_ops
Create Date: 2026-12-01 15:00:00
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = '0004_participant_ux'
down_revision: str | None = '0003_study_ops'
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    """Apply this migration."""
    with op.batch_alter_table('studies', schema=None) as batch_op:
        batch_op.add_column(sa.Column('robot_speed', sa.Float(), server_default=sa.text('1.0'), nullable=False))


def downgrade() -> None:
    """Revert this migration."""
    with op.batch_alter_table('studies', schema=None) as batch_op:
        batch_op.drop_column('robot_speed')
