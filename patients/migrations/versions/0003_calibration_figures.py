"""calibrations: the headline figures, the reference sensor's serial and the certificate's
digest as columns (queryable without opening the stored record), backfilled from the records.

Revision ID: 0003_calibration
Revises: 0002
Create Date: 2026-11-25

Another migration (the patients' ankle fields) also follows 0002: at merge, one of the two
revises the other so the chain stays linear.
"""
from __future__ import annotations

import json
from typing import Any

import sqlalchemy as sa
from alembic import op

revision = "0003_calibration"
down_revision = "0002"
branch_labels = None
depends_on = None


def figures(record: Any) -> dict[str, Any]:
    """The columns' values from a stored record: the same rule as
    ``patients.service.calibration_figures``, frozen here as this revision applied it."""
    record = record if isinstance(record, dict) else json.loads(record)
    return _figures(record)


def _figures(record: dict[str, Any]) -> dict[str, Any]:
    """The record's headline columns: the reference sensor's serial, and on held-out points
    after the fit (``nonlinear`` when present, else ``linear``) the COP error RMS and max (mm)
    and the worst of Fx, Fy, Fz (% FS). Absent or malformed entries give None."""
    def number(x: Any) -> float | None:
        return float(x) if isinstance(x, (int, float)) and not isinstance(x, bool) else None

    ref = record.get("reference_sensor")
    raw = record.get("metrics")
    metrics: dict[str, Any] = raw if isinstance(raw, dict) else {}
    stage = next((s for s in ("nonlinear", "linear") if isinstance(metrics.get(s), dict)), None)
    m: dict[str, Any] = metrics[stage] if stage else {}
    axes = m.get("force_pct_fs")
    forces = [number(x) for x in axes[:3]] if isinstance(axes, list) else []
    forces_ok = [x for x in forces if x is not None]
    serial = ref.get("serial") if isinstance(ref, dict) else None
    return {"reference_serial": None if serial is None else str(serial)[:100],
            "cop_rms_mm": number(m.get("cop_rms_mm")), "cop_max_mm": number(m.get("cop_max_mm")),
            "force_pct_fs": max(forces_ok) if forces_ok else None, "figures_stage": stage}


def upgrade() -> None:
    with op.batch_alter_table("calibrations", schema=None) as batch_op:
        batch_op.add_column(sa.Column("reference_serial", sa.String(length=100), nullable=True))
        batch_op.add_column(sa.Column("cop_rms_mm", sa.Float(), nullable=True))
        batch_op.add_column(sa.Column("cop_max_mm", sa.Float(), nullable=True))
        batch_op.add_column(sa.Column("force_pct_fs", sa.Float(), nullable=True))
        batch_op.add_column(sa.Column("figures_stage", sa.String(length=20), nullable=True))
        batch_op.add_column(sa.Column("certificate_sha256", sa.String(length=64), nullable=True))
    bind = op.get_bind()
    table = sa.table("calibrations", sa.column("id", sa.Integer), sa.column("record", sa.JSON),
                     sa.column("reference_serial", sa.String), sa.column("cop_rms_mm", sa.Float),
                     sa.column("cop_max_mm", sa.Float), sa.column("force_pct_fs", sa.Float),
                     sa.column("figures_stage", sa.String))
    for row_id, record in bind.execute(sa.select(table.c.id, table.c.record)).all():
        bind.execute(table.update().where(table.c.id == row_id).values(**figures(record)))


def downgrade() -> None:
    with op.batch_alter_table("calibrations", schema=None) as batch_op:
        for name in ("certificate_sha256", "figures_stage", "force_pct_fs", "cop_max_mm",
                     "cop_rms_mm", "reference_serial"):
            batch_op.drop_column(name)
