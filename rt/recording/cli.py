"""``talus record info|export``: look into a session recording, export a channel to CSV.

Each command prints one JSON line and exits 0; a file that is not a readable recording, or a
channel it does not have, prints ``{"error": "..."}`` and exits 2. Both work on complete and on
truncated (crashed-writer) recordings. A damaged recording (a chunk or section CRC fails) makes
``info`` print its report with ``"corrupt": true`` and exit 2, and ``export`` refuse unless
``--salvage``. ``export`` never overwrites (``--force``) and never writes over its input.
"""
from __future__ import annotations

import argparse
import json
import sys
from typing import Any

EXIT_ERROR = 2


def _emit(obj: dict[str, Any]) -> None:
    sys.stdout.write(json.dumps(obj) + "\n")
    sys.stdout.flush()


def register(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``info`` and ``export`` to the ``record`` group's subparsers."""
    p = commands.add_parser(
        "info", help="channels, message counts, duration, complete or truncated",
        description="Print a recording's channels, message counts per channel, duration (s), "
                    "chunks and whether it is complete or truncated, as one JSON line.")
    p.add_argument("file", help="the .mcap recording")
    p.set_defaults(func=cmd_info)

    p = commands.add_parser(
        "export", help="one channel to CSV",
        description="Write one channel to CSV (header; arrays flattened as q0,q1,q2; "
                    "log_time_ns first). Works on truncated recordings up to their last "
                    "complete chunk. Prints a JSON line with the row count.")
    p.add_argument("file", help="the .mcap recording")
    p.add_argument("--channel", default="/robot/state",
                   help="channel (topic) to export (default %(default)s)")
    p.add_argument("--out", required=True, help="CSV file to write (refused if it exists)")
    p.add_argument("--force", action="store_true",
                   help="replace an existing --out (only once the new CSV is complete)")
    p.add_argument("--salvage", action="store_true",
                   help="skip damaged chunks and export what is readable (listed in the "
                        "output line)")
    p.set_defaults(func=cmd_export)


def cmd_info(args: argparse.Namespace) -> int:
    """``talus record info FILE``."""
    from rt.recording.reader import recording_info

    info = recording_info(args.file)
    if info["corrupt"]:
        _emit({**info, "error": f"{args.file}: {info['problem']}"})
        return EXIT_ERROR
    _emit(info)
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    """``talus record export FILE --channel TOPIC --out OUT.csv``."""
    from rt.errors import InputError
    from rt.recording.reader import export_csv

    try:
        _emit(export_csv(args.file, args.channel, args.out, force=args.force,
                         salvage=args.salvage))
    except OSError as exc:
        raise InputError(f"{args.out}: cannot write: {exc.strerror or exc}") from None
    return 0
