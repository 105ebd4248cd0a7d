"""mountpoints.correction_bound: a VRS mountpoint's streams carry the RTCM 4001 correction-error bound
(opt-in, default off; decisions 0280, 0281)

Revision ID: 0004
Revises: 0003
Create Date: 2026-12-04
"""
from alembic import op
import sqlalchemy as sa


revision = '0004'
down_revision = '0003'
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table('mountpoints', schema=None) as batch_op:
        batch_op.add_column(sa.Column('correction_bound', sa.Boolean(), server_default=sa.false(), nullable=False))


def downgrade() -> None:
    with op.batch_alter_table('mountpoints', schema=None) as batch_op:
        batch_op.drop_column('correction_bound')
