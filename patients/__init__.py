"""talus: the clinical record (DESIGN.md section 9; docs/patients.md, docs/roles.md).

Patients by pseudonymous code, identifying data apart and erasable, limits history, plans,
sessions, calibrations, users with roles, a hash-chained audit log; SQLite by default,
PostgreSQL by URL. Everything goes through ``patients.service.ClinicalRecord``.
"""
