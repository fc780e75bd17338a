"""``talus sessions``: the stored therapy sessions (pseudonymous)."""
from __future__ import annotations

import argparse
import datetime as dt
from typing import Any

from patients.cli_common import add_common, command, emit, login, open_record, table
from patients.errors import InputError


def register(commands: argparse._SubParsersAction) -> None:
    p = commands.add_parser("list", help="sessions, oldest first")
    add_common(p)
    p.add_argument("--patient", default=None, help="one patient's code")
    p.add_argument("--since", default=None, help="started on/after (YYYY-MM-DD or ISO time, UTC)")
    p.add_argument("--until", default=None, help="started before (YYYY-MM-DD or ISO time, UTC)")
    p.add_argument("--full", action="store_true", help="with summaries and limits snapshots")
    p.set_defaults(func=_list)

    p = commands.add_parser("show", help="one session: snapshots, outcome, summary, recording")
    add_common(p)
    p.add_argument("uid")
    p.set_defaults(func=_show)


def parse_time(text: str | None, flag: str) -> dt.datetime | None:
    """A date (midnight UTC) or an ISO time (UTC if it names no zone)."""
    if text is None:
        return None
    try:
        t = dt.datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        raise InputError(f"{flag} {text!r}: use YYYY-MM-DD or an ISO 8601 time") from None
    return t.replace(tzinfo=dt.timezone.utc) if t.tzinfo is None else t


@command
def _list(args: argparse.Namespace) -> int:
    since, until = parse_time(args.since, "--since"), parse_time(args.until, "--until")
    with open_record(args) as record:
        rows = record.list_sessions(login(record, args), args.patient, since, until, args.full)
    emit(args, rows, lambda r: table(r, ["uid", "patient", "clinician", "protocol_name",
                                         "started_at", "outcome", "stopped_by"]))
    return 0


@command
def _show(args: argparse.Namespace) -> int:
    with open_record(args) as record:
        s = record.get_session(login(record, args), args.uid)
    emit(args, s, _describe)
    return 0


def _describe(s: dict[str, Any]) -> str:
    keys = ("patient", "clinician", "protocol_name", "protocol_sha256", "started_at", "ended_at",
            "outcome", "stopped_by", "body_mass_kg", "recording_path", "recording_sha256")
    lines = [f"session {s['uid']}"] + [f"  {k:18s} {'-' if s[k] is None else s[k]}"
                                       for k in keys]
    lines.append("  limits snapshot    " + ", ".join(f"{k}={v}" for k, v in s["limits"].items()))
    if s["summary"]:
        lines.append("  summary            " + ", ".join(
            f"{k}={v}" for k, v in s["summary"].items() if not isinstance(v, (dict, list))))
    return "\n".join(lines)
