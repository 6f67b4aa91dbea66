"""a study's own objects: their names, shapes, colours, sizes and goal slots (empty: the dinner table)

Revision ID: 0013_study_objects
Revises: 0012_recordings
Create Date: 2026-12-04 12:00:00
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = '0013_study_objects'
down_revision: str | None = '0012_recordings'
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    """Apply this migration."""
    with op.batch_alter_table('studies', schema=None) as batch_op:
        batch_op.add_column(sa.Column('objects', sa.JSON(), nullable=True))


def downgrade() -> None:
    """Revert this migration."""
    with op.batch_alter_table('studies', schema=None) as batch_op:
        batch_op.drop_column('objects')
