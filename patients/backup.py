"""Backup and restore of an SQLite clinical record with SQLite's online backup API (a
consistent copy while other workstations keep working). PostgreSQL is backed up with its own
tools; ``pg_hint`` says how.
"""
from __future__ import annotations

import os
import sqlite3
import tempfile
from pathlib import Path

from patients.errors import InputError, RecordError


def pg_hint(url_without_password: str) -> str:
    return ("PostgreSQL databases are backed up with PostgreSQL's tools: "
            "`pg_dump --format=custom --file=talus.dump DBNAME` and restored with "
            "`pg_restore --clean --dbname=DBNAME talus.dump` (as the database owner; "
            f"database: {url_without_password})")


def backup(source: Path, target: Path, force: bool = False) -> int:
    """Copy the live database ``source`` to ``target`` (refused if it exists unless ``force``).

    Written to a temporary file next to ``target`` and renamed, so a failed backup never
    leaves half a file under the target's name. Returns the size in bytes.
    """
    if target.exists() and not force:
        raise InputError(f"{target} exists: choose another name, or --force to replace it")
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.", dir=target.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        src = sqlite3.connect(f"file:{source}?mode=ro", uri=True)
        dst = sqlite3.connect(tmp)
        try:
            src.backup(dst)
            # A backup is one self-contained file: no WAL beside it.
            dst.execute("PRAGMA journal_mode=DELETE")
        finally:
            dst.close()
            src.close()
        os.chmod(tmp, 0o600)
        os.replace(tmp, target)
    except sqlite3.Error as exc:
        raise RecordError(f"backup of {source} failed: {exc}") from None
    finally:
        tmp.unlink(missing_ok=True)
    return target.stat().st_size


def check_backup(path: Path) -> None:
    """Refuse a file that is not an intact talus SQLite database."""
    if not path.is_file():
        raise InputError(f"no backup file at {path}")
    try:
        con = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
        try:
            ok = con.execute("PRAGMA integrity_check").fetchone()[0]
            tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        finally:
            con.close()
    except sqlite3.DatabaseError as exc:
        raise InputError(f"{path} is not an SQLite database ({exc})") from None
    if ok != "ok":
        raise InputError(f"{path} fails SQLite's integrity check: {ok}")
    if not {"alembic_version", "patients", "audit_log"} <= tables:
        raise InputError(f"{path} is not a talus clinical record backup")


def restore(backup_file: Path, target: Path) -> None:
    """Replace the content of ``target`` by ``backup_file`` (both SQLite files).

    Uses the backup API into the live target, so connections elsewhere see either the old or
    the restored database, never a mix. The caller decides whether replacing is allowed.
    """
    check_backup(backup_file)
    target.parent.mkdir(parents=True, exist_ok=True)
    if not target.exists():
        target.touch(mode=0o600)
    try:
        src = sqlite3.connect(f"file:{backup_file}?mode=ro", uri=True)
        dst = sqlite3.connect(target, timeout=15)
        try:
            src.backup(dst)
            dst.execute("PRAGMA journal_mode=WAL")
        finally:
            dst.close()
            src.close()
    except sqlite3.Error as exc:
        raise RecordError(f"restore of {target} from {backup_file} failed: {exc}") from None
