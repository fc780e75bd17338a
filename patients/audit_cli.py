"""``talus audit``: verify the hash chain (exit 1 when broken), export it (admin)."""
from __future__ import annotations

import argparse
import json

from patients.cli_common import add_common, command, emit, login, open_record, write_new_file

EXIT_BROKEN = 1


def register(commands: argparse._SubParsersAction) -> None:
    p = commands.add_parser("verify", help="check the audit log's hash chain; exit code 1 if "
                                           "an entry was edited, inserted or deleted")
    add_common(p)
    p.add_argument("--anchor", default=None,
                   help="SEQ:HASH printed by an earlier verify and kept outside the database: "
                        "that entry must still be in the chain")
    p.set_defaults(func=_verify)

    p = commands.add_parser("export", help="the audit log as JSON lines")
    add_common(p)
    p.add_argument("--out", default=None, help="file to write (default: stdout)")
    p.add_argument("--force", action="store_true", help="replace an existing --out")
    p.set_defaults(func=_export)


@command
def _verify(args: argparse.Namespace) -> int:
    with open_record(args) as record:
        result = record.verify_audit(login(record, args), args.anchor)
    emit(args, result.as_dict(), lambda r: (
        f"audit log intact: {r['entries']} entries; head {r['head']} (note it outside the "
        "database to check later with --anchor)" if r["ok"] else
        f"AUDIT LOG BROKEN ({r['entries']} entries):\n  " + "\n  ".join(r["problems"])))
    return 0 if result.ok else EXIT_BROKEN


@command
def _export(args: argparse.Namespace) -> int:
    with open_record(args) as record:
        entries = record.export_audit(login(record, args))
    text = "".join(json.dumps(e, ensure_ascii=False) + "\n" for e in entries)
    if args.out is None:
        print(text, end="")
        return 0
    write_new_file(args.out, text, args.force)
    emit(args, {"out": args.out, "entries": len(entries)},
         f"{len(entries)} audit entries written to {args.out}")
    return 0
