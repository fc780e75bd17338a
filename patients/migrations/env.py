"""Alembic environment: always run on the connection patients.db hands over (online mode)."""
from __future__ import annotations

from alembic import context

from patients.models import Base

connection = context.config.attributes.get("connection")
if connection is None:
    raise RuntimeError("run migrations through `talus db upgrade` (patients.db.upgrade)")
context.configure(connection=connection, target_metadata=Base.metadata,
                  render_as_batch=True, compare_type=True)
with context.begin_transaction():
    context.run_migrations()
