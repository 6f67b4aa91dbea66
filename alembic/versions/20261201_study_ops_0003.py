"""study operations: study-level codes, task order, quiz, timeouts, participant flags, erasure audit

Revision ID: 0003_study_ops
Revises: 0002_hardening
Create Date: 2026-12-01 15:00:00
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = '0003_study_ops'
down_revision: str | None = '0002_hardening'
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    """Apply this migration."""
    with op.batch_alter_table('studies', schema=None) as batch_op:
        batch_op.add_column(sa.Column('completion_code', sa.String(length=64), nullable=True))
        batch_op.add_column(sa.Column('screened_out_code', sa.String(length=64), nullable=True))
        batch_op.add_column(sa.Column('task_order', sa.String(length=16), server_default='fixed', nullable=False))
        batch_op.add_column(sa.Column('quiz', sa.JSON(), server_default='[]', nullable=False))
        batch_op.add_column(sa.Column('quiz_max_attempts', sa.Integer(), server_default='2', nullable=False))
        batch_op.add_column(sa.Column('timeout_minutes', sa.Integer(), nullable=True))

    with op.batch_alter_table('participants', schema=None) as batch_op:
        batch_op.add_column(sa.Column('task_order', sa.JSON(), nullable=True))
        batch_op.add_column(sa.Column('quiz_failures', sa.Integer(), server_default='0', nullable=False))
        batch_op.add_column(sa.Column('attention_failed', sa.Boolean(), server_default=sa.false(), nullable=False))
        batch_op.add_column(sa.Column('end_reason', sa.String(length=32), nullable=True))

    op.create_table('erasures',
    sa.Column('id', sa.Integer(), autoincrement=True, nullable=False),
    sa.Column('study_id', sa.String(length=64), nullable=False),
    sa.Column('participant_id', sa.Integer(), nullable=False),
    sa.Column('erased_by', sa.String(length=64), nullable=False),
    sa.Column('reason', sa.String(length=32), nullable=False),
    sa.Column('pilot', sa.Boolean(), nullable=False),
    sa.Column('erased_at', sa.DateTime(timezone=True), nullable=False),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_erasures'))
    )
    with op.batch_alter_table('erasures', schema=None) as batch_op:
        batch_op.create_index(batch_op.f('ix_erasures_study_id'), ['study_id'], unique=False)


def downgrade() -> None:
    """Revert this migration."""
    with op.batch_alter_table('erasures', schema=None) as batch_op:
        batch_op.drop_index(batch_op.f('ix_erasures_study_id'))
    op.drop_table('erasures')
    with op.batch_alter_table('participants', schema=None) as batch_op:
        batch_op.drop_column('end_reason')
        batch_op.drop_column('attention_failed')
        batch_op.drop_column('quiz_failures')
        batch_op.drop_column('task_order')
    with op.batch_alter_table('studies', schema=None) as batch_op:
        batch_op.drop_column('timeout_minutes')
        batch_op.drop_column('quiz_max_attempts')
        batch_op.drop_column('quiz')
        batch_op.drop_column('task_order')
        batch_op.drop_column('screened_out_code')
        batch_op.drop_column('completion_code')
