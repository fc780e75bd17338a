"""patient_ankle_setups: where each patient's ankle joint centre sits on the platform (issue 17)

Revision ID: 0004
Revises: 0003_calibration
Create Date: 2026-11-25 (written by hand from patients.models.PatientAnkleRow; migrations never
import patients.models)
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0003_calibration"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "patient_ankle_setups",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("patient_id", sa.Integer(), nullable=False),
        sa.Column("side", sa.String(length=8), nullable=False),
        sa.Column("height_above_sole_m", sa.Float(), nullable=False),
        sa.Column("offset_x_m", sa.Float(), nullable=False),
        sa.Column("offset_y_m", sa.Float(), nullable=False),
        sa.Column("sole_above_sensor_m", sa.Float(), nullable=False),
        sa.Column("source", sa.String(length=16), nullable=False),
        sa.Column("set_by", sa.String(length=64), nullable=False),
        sa.Column("set_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("reason", sa.Text(), nullable=True),
        sa.ForeignKeyConstraint(["patient_id"], ["patients.id"], ondelete="CASCADE"),
        sa.PrimaryKeyConstraint("id"),
    )
    with op.batch_alter_table("patient_ankle_setups", schema=None) as batch_op:
        batch_op.create_index(batch_op.f("ix_patient_ankle_setups_patient_id"), ["patient_id"],
                              unique=False)


def downgrade() -> None:
    with op.batch_alter_table("patient_ankle_setups", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_patient_ankle_setups_patient_id"))
    op.drop_table("patient_ankle_setups")
