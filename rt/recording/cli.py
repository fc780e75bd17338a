"""``talus record info|export``: look into a session recording, export a channel to CSV.

Each command prints one JSON line and exits 0; a file that is not a readable recording, or a
channel it does not have, prints ``{"error": "..."}`` and exits 2. Both work on complete and on
truncated (crashed-writer) recordings.
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
    p.add_argument("--out", required=True, help="CSV file to write")
    p.set_defaults(func=cmd_export)


def cmd_info(args: argparse.Namespace) -> int:
    """``talus record info FILE``."""
    from rt.errors import TalusError
    from rt.recording.reader import recording_info

    try:
        _emit(recording_info(args.file))
    except TalusError as exc:
        _emit({"error": str(exc)})
        return EXIT_ERROR
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    """``talus record export FILE --channel TOPIC --out OUT.csv``."""
    from rt.errors import TalusError
    from rt.recording.reader import export_csv

    try:
        _emit(export_csv(args.file, args.channel, args.out))
    except TalusError as exc:
        _emit({"error": str(exc)})
        return EXIT_ERROR
    except OSError as exc:
        _emit({"error": f"{args.out}: cannot write: {exc.strerror or exc}"})
        return EXIT_ERROR
    return 0
