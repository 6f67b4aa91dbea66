"""recordings kept in the database (TABLETEACH_RECORDING_STORE=database): file bytes by digest, and who has which

Revision ID: 0012_recordings
Revises: 0011_learner_flip_rate
Create Date: 2026-12-02 16:00:00
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = '0012_recordings'
down_revision: str | None = '0011_learner_flip_rate'
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    """Apply this migration."""
    op.create_table(
        'recording_blobs',
        sa.Column('digest', sa.String(length=64), nullable=False),
        sa.Column('size', sa.Integer(), nullable=False),
        sa.Column('data', sa.LargeBinary(), nullable=False),
        sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
        sa.PrimaryKeyConstraint('digest', name=op.f('pk_recording_blobs')),
    )
    op.create_table(
        'recording_files',
        sa.Column('name', sa.String(length=200), nullable=False),
        sa.Column('participant_uid', sa.String(length=32), nullable=False),
        sa.Column('digest', sa.String(length=64), nullable=False),
        sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(['digest'], ['recording_blobs.digest'],
                                name=op.f('fk_recording_files_digest_recording_blobs')),
        sa.PrimaryKeyConstraint('name', name=op.f('pk_recording_files')),
    )
    with op.batch_alter_table('recording_files', schema=None) as batch_op:
        batch_op.create_index(batch_op.f('ix_recording_files_digest'), ['digest'], unique=False)
        batch_op.create_index(batch_op.f('ix_recording_files_participant_uid'), ['participant_uid'], unique=False)


def downgrade() -> None:
    """Revert this migration."""
    with op.batch_alter_table('recording_files', schema=None) as batch_op:
        batch_op.drop_index(batch_op.f('ix_recording_files_participant_uid'))
        batch_op.drop_index(batch_op.f('ix_recording_files_digest'))
    op.drop_table('recording_files')
    op.drop_table('recording_blobs')
