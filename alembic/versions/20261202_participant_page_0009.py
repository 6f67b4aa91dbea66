"""participant page: a study's structured consent form, links without a PROLIFIC_PID, quiz feedback, attention telemetry

Revision ID: 0009_participant_page
Revises: 0008_prolific
Create Date: 2026-12-01 23:50:00
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = '0009_participant_page'
down_revision: str | None = '0008_prolific'
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    """Apply this migration."""
    with op.batch_alter_table('studies', schema=None) as batch_op:
        batch_op.add_column(sa.Column('consent_form', sa.JSON(), server_default='{}', nullable=False))
        batch_op.add_column(sa.Column('allow_anonymous', sa.Boolean(), server_default=sa.false(), nullable=False))
        batch_op.add_column(sa.Column('quiz_feedback', sa.Boolean(), server_default=sa.true(), nullable=False))
    with op.batch_alter_table('participants', schema=None) as batch_op:
        batch_op.add_column(sa.Column('attention_signals', sa.JSON(), server_default='{}', nullable=False))


def downgrade() -> None:
    """Revert this migration."""
    with op.batch_alter_table('participants', schema=None) as batch_op:
        batch_op.drop_column('attention_signals')
    with op.batch_alter_table('studies', schema=None) as batch_op:
        batch_op.drop_column('quiz_feedback')
        batch_op.drop_column('allow_anonymous')
        batch_op.drop_column('consent_form')
