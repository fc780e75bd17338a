"""``talus db``: create/upgrade the clinical database, back it up, restore it, the demo clinic."""
from __future__ import annotations

import argparse
from pathlib import Path

from patients.cli_common import add_common, command, emit, login


def register(commands: argparse._SubParsersAction) -> None:
    p = commands.add_parser("upgrade", help="create the database or migrate it to this talus's "
                                            "schema (take a backup first)")
    add_common(p, user=False)
    p.add_argument("--revision", default="head", help="target schema revision (default head)")
    p.set_defaults(func=_upgrade)

    p = commands.add_parser("backup", help="consistent copy of a live SQLite database (admin)")
    add_common(p)
    p.add_argument("--out", required=True, help="backup file to write")
    p.add_argument("--force", action="store_true", help="replace an existing --out")
    p.set_defaults(func=_backup)

    p = commands.add_parser("restore", help="replace an SQLite database by a backup (admin)")
    add_common(p)
    p.add_argument("backup", help="backup file written by `talus db backup`")
    p.add_argument("--force", action="store_true",
                   help="needed when the database exists: its content is replaced")
    p.set_defaults(func=_restore)

    p = commands.add_parser("demo", help="the demo clinic: one admin, one clinician, one "
                                         "patient (idempotent; password: $TALUS_PASSWORD or a "
                                         "random one in a 0600 file next to the database)")
    add_common(p, user=False)
    p.set_defaults(func=_demo)


@command
def _upgrade(args: argparse.Namespace) -> int:
    from patients import db
    url = db.resolve_url(args.db)
    engine = db.create_engine(url, create=True)
    try:
        before = db.current_revision(engine)
        db.upgrade(engine, args.revision)
        after = db.current_revision(engine)
    finally:
        engine.dispose()
    emit(args, {"database": db.describe(url), "from": before, "to": after},
         f"{db.describe(url)}: schema {before or '(empty)'} -> {after}")
    return 0


def _sqlite_path(args: argparse.Namespace, action: str) -> Path:
    from patients import backup, db
    from patients.errors import InputError
    url = db.resolve_url(args.db)
    path = db.sqlite_file(url)
    if path is None:
        raise InputError(f"talus db {action} works on SQLite files. "
                         + backup.pg_hint(db.describe(url)))
    return path


@command
def _backup(args: argparse.Namespace) -> int:
    from patients import backup
    path = _sqlite_path(args, "backup")
    out = Path(args.out)
    if out.resolve() == path.resolve():
        from patients.errors import InputError
        raise InputError("--out is the database itself")
    with _open(args) as record:
        actor = login(record, args)
        # Audited (and the right checked) before the copy, so the backup holds its own entry.
        record.note_database_action(actor, "db.backup", {"out": str(out)})
        size = backup.backup(path, out, force=args.force)
    emit(args, {"database": str(path), "backup": str(out), "bytes": size},
         f"backed up {path} to {out} ({size} bytes)")
    return 0


@command
def _restore(args: argparse.Namespace) -> int:
    from patients import backup
    from patients.errors import InputError
    path = _sqlite_path(args, "restore")
    source = Path(args.backup)
    backup.check_backup(source)
    if path.exists():
        if not args.force:
            raise InputError(f"{path} exists: restoring replaces all of it; add --force")
        with _open(args) as record:
            if record.has_users():
                actor = login(record, args)
                record.note_database_action(actor, "db.restore", {"from": str(source)})
    backup.restore(source, path)
    emit(args, {"database": str(path), "restored_from": str(source)},
         f"restored {path} from {source}")
    return 0


def _open(args: argparse.Namespace):  # type: ignore[no-untyped-def]
    from patients.cli_common import open_record
    return open_record(args)


@command
def _demo(args: argparse.Namespace) -> int:
    from patients.cli_common import open_record
    from patients.demo import ensure_demo
    with open_record(args, create=True) as record:
        info = ensure_demo(record)
    emit(args, info, lambda i: (
        f"demo clinic in {i['database']}: clinician {i['clinician']}, patient {i['patient']}"
        f" (admin {i['admin']}); password {i['password']}"
        + (f"; created {', '.join(i['created'])}" if i["created"] else "; already there")))
    return 0
