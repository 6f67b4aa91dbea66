"""Prolific end to end: a completion code per outcome, time-out changes that count from the change, the
uploaded Prolific submissions and a bonus rule per study, archived studies

Revision ID: 0008_prolific
Revises: 0007_accounts
Create Date: 2026-12-02 00:00:00
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = '0008_prolific'
down_revision: str | None = '0007_accounts'
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

OUTCOME_CODES = ('declined_consent_code', 'failed_quiz_code', 'failed_attention_code', 'timed_out_code',
                 'withdrew_code')


def upgrade() -> None:
    """Apply this migration."""
    with op.batch_alter_table('studies', schema=None) as batch_op:
        for name in OUTCOME_CODES:
            batch_op.add_column(sa.Column(name, sa.String(length=64), nullable=True))
        batch_op.add_column(sa.Column('timeout_changed_at', sa.DateTime(timezone=True), nullable=True))
        batch_op.add_column(sa.Column('prolific_submissions', sa.JSON(), nullable=True))
        batch_op.add_column(sa.Column('prolific_uploaded_at', sa.DateTime(timezone=True), nullable=True))
        batch_op.add_column(sa.Column('bonus_rule', sa.JSON(), nullable=True))
        batch_op.add_column(sa.Column('archived_at', sa.DateTime(timezone=True), nullable=True))
    # Participants screened out before this revision were shown the study's single screened-out code: store it
    # as the code they were given (the exports and the dashboard show it).
    op.execute(
        "UPDATE participants SET completion_code = "
        "(SELECT studies.screened_out_code FROM studies WHERE studies.id = participants.study_id) "
        "WHERE completion_code IS NULL AND end_reason IN ('declined_consent', 'comprehension', 'timeout')"
    )


def downgrade() -> None:
    """Revert this migration (the screened-out participants keep the code they were shown)."""
    with op.batch_alter_table('studies', schema=None) as batch_op:
        for name in ('archived_at', 'bonus_rule', 'prolific_uploaded_at', 'prolific_submissions',
                     'timeout_changed_at'):
            batch_op.drop_column(name)
        for name in reversed(OUTCOME_CODES):
            batch_op.drop_column(name)
