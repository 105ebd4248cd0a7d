"""section_trains: the section register's trains per line section and direction (decision 0292)

Revision ID: 0003
Revises: 0002
Create Date: 2026-12-04
"""
from alembic import op
import sqlalchemy as sa


revision = '0003'
down_revision = '0002'
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table('section_trains',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('section_id', sa.Integer(), nullable=False),
    sa.Column('direction', sa.String(length=8), nullable=False),
    sa.Column('position', sa.Integer(), nullable=False),
    sa.Column('train_code', sa.String(length=32), nullable=False),
    sa.Column('track', sa.String(length=32), nullable=False),
    sa.Column('km', sa.Float(), nullable=False),
    sa.Column('speed_m_s', sa.Float(), nullable=False),
    sa.Column('length_m', sa.Float(), nullable=False),
    sa.Column('integrity', sa.String(length=16), nullable=False),
    sa.Column('correction_age_s', sa.Float(), nullable=True),
    sa.Column('along_pl_m', sa.Float(), nullable=True),
    sa.Column('cross_pl_m', sa.Float(), nullable=True),
    sa.Column('hpl_m', sa.Float(), nullable=True),
    sa.Column('report_time_s', sa.Float(), nullable=False),
    sa.Column('updated_at', sa.DateTime(timezone=True), nullable=False),
    sa.PrimaryKeyConstraint('id'),
    sa.UniqueConstraint('section_id', 'direction', 'position', name='uq_section_trains_place'),
    sa.UniqueConstraint('train_code')
    )


def downgrade() -> None:
    op.drop_table('section_trains')
