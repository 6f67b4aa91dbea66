"""hardening: a random uid per participant (names their recordings) and the digest of their browser's secret

Revision ID: 0002_hardening
Revises: 0001
Create Date: 2026-12-01 14:45:00
"""

from __future__ import annotations

import secrets
from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = '0002_hardening'
down_revision: str | None = '0001'
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    """Add participants.uid (filled with fresh random values, then unique and required) and browser_digest."""
    with op.batch_alter_table('participants', schema=None) as batch_op:
        batch_op.add_column(sa.Column('uid', sa.String(length=32), nullable=True))
        batch_op.add_column(sa.Column('browser_digest', sa.String(length=64), nullable=True))
    connection = op.get_bind()
    for (participant_id,) in connection.execute(sa.text("SELECT id FROM participants")).all():
        connection.execute(sa.text("UPDATE participants SET uid = :uid WHERE id = :id"),
                           {"uid": secrets.token_hex(16), "id": participant_id})
    with op.batch_alter_table('participants', schema=None) as batch_op:
        batch_op.alter_column('uid', existing_type=sa.String(length=32), nullable=False)
        batch_op.create_unique_constraint(batch_op.f('uq_participants_uid'), ['uid'])


def downgrade() -> None:
    """Drop both columns."""
    with op.batch_alter_table('participants', schema=None) as batch_op:
        batch_op.drop_constraint(batch_op.f('uq_participants_uid'), type_='unique')
        batch_op.drop_column('browser_digest')
        batch_op.drop_column('uid')
