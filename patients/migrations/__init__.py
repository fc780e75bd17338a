"""Alembic migrations of the clinical record (shipped with the package; see patients.db)."""
