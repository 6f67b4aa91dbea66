"""the noise-aware learner for a study: its assumed verdict-flip probability (0: the authors' learner)

Revision ID: 0011_learner_flip_rate
Revises: 0010_poll_versions
Create Date: 2026-12-02 04:00:00
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = '0011_learner_flip_rate'
down_revision: str | None = '0010_poll_versions'
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    """Apply this migration."""
    with op.batch_alter_table('studies', schema=None) as batch_op:
        batch_op.add_column(sa.Column('flip_rate', sa.Float(), server_default=sa.text('0.0'), nullable=False))


def downgrade() -> None:
    """Revert this migration."""
    with op.batch_alter_table('studies', schema=None) as batch_op:
        batch_op.drop_column('flip_rate')
