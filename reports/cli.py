"""``talus report session|progress|calibration``: PDF reports.

Each command writes one PDF and prints one JSON line (``{"out", "pages", ...}``); bad input
prints ``{"error": "..."}`` naming what was wrong, writes nothing and exits 2. An existing
output is refused unless ``--force``.
"""
from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

EXIT_ERROR = 2


def _emit(obj: dict[str, Any]) -> None:
    sys.stdout.write(json.dumps(obj) + "\n")
    sys.stdout.flush()


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", default=None, help="PDF to write (default: the input's name, .pdf)")
    p.add_argument("--force", action="store_true", help="replace an existing output")
    p.add_argument("--settings", default=None,
                   help="report settings YAML (clinic name, logo, page size); default "
                        "$TALUS_REPORT_SETTINGS or ~/.config/talus/reports.yaml")
    p.add_argument("--page-size", choices=("A4", "Letter"), default=None,
                   help="paper size (default: the settings')")
    p.add_argument("--generated-at", default=None, metavar="ISO8601",
                   help="generation time printed in the report (default: now); a rerun with "
                        "the same value gives the same PDF")


def register(commands: argparse._SubParsersAction) -> None:
    """Add ``session``, ``progress`` and ``calibration`` to the ``report`` group."""
    p = commands.add_parser(
        "session", help="session report from a recording",
        description="Session report: outcome, results against the patient's limits, plots "
                    "(force, ankle angles, sliders), stops, pre-flight vs actual, and the "
                    "recording's sha256. Reads the recording in one streaming pass.")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--recording", help="the session's .mcap recording")
    src.add_argument("--session", help="session id in the clinical database")
    p.add_argument("--identify", action="store_true",
                   help="print the patient's identifying data (needs --session and a user "
                        "whose role may read it)")
    p.add_argument("--robot", default=None,
                   help="robot description YAML the session ran with (default: nominal)")
    _record_options(p)
    _common(p)
    p.set_defaults(func=cmd_session)

    p = commands.add_parser(
        "progress", help="a patient's progress over sessions",
        description="Progress report: ROM reached per session and direction against the "
                    "prescribed range, force-tracking error and peak force per session, "
                    "adherence, trend lines, the sessions table.")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--input", help="progress input JSON (reports.progress.ProgressInput)")
    src.add_argument("--patient", help="patient code in the clinical database")
    p.add_argument("--from", dest="date_from", default=None, help="first date (YYYY-MM-DD)")
    p.add_argument("--to", dest="date_to", default=None, help="last date (YYYY-MM-DD)")
    _record_options(p)
    _common(p)
    p.set_defaults(func=cmd_progress)

    p = commands.add_parser(
        "calibration", help="force-plate calibration certificate",
        description="Calibration certificate from a calibration record JSON (schema_version "
                    "1): plate, reference sensor, registration, plan, metrics against "
                    "thresholds with PASS/FAIL, COP error maps, matrix, uncertainty (k = 2), "
                    "exports with their hashes.")
    p.add_argument("--record", required=True, help="calibration record JSON")
    _common(p)
    p.set_defaults(func=cmd_calibration)


def _clock(args: argparse.Namespace) -> Callable[[], datetime]:
    from reports.document import utc_now
    from rt.errors import InputError

    if args.generated_at is None:
        return utc_now
    try:
        t = datetime.fromisoformat(args.generated_at)
    except ValueError as exc:
        raise InputError(f"--generated-at {args.generated_at!r}: not an ISO 8601 time") from exc
    if t.tzinfo is None:
        t = t.replace(tzinfo=UTC)
    return lambda: t


def _settings(args: argparse.Namespace) -> Any:
    from reports.settings import PageSize, load_settings

    s = load_settings(args.settings)
    if args.page_size:
        s = s.model_copy(update={"page_size": PageSize(args.page_size)})
    return s


def _out(args: argparse.Namespace, source: str) -> Path:
    return Path(args.out) if args.out else Path(source).with_suffix(".pdf")


def _guard(run: Callable[[argparse.Namespace], dict[str, Any]]
           ) -> Callable[[argparse.Namespace], int]:
    def wrapped(args: argparse.Namespace) -> int:
        from rt.errors import TalusError

        try:
            _emit(run(args))
        except TalusError as exc:
            _emit({"error": str(exc)})
            return EXIT_ERROR
        return 0
    wrapped.__doc__ = run.__doc__
    return wrapped


def _record_options(p: argparse.ArgumentParser) -> None:
    import os

    p.add_argument("--db", default=None,
                   help="clinical record URL (default: TALUS_DATABASE_URL, else the user data "
                        "directory's SQLite file)")
    p.add_argument("--user", default=os.environ.get("TALUS_USER"),
                   help="clinical record user (password: prompt or TALUS_PASSWORD)")


def _with_record(args: argparse.Namespace, use: Callable[[Any, Any], Any]) -> Any:
    """Log in to the clinical record and call ``use(record, actor)``."""
    from patients.cli_common import login
    from patients.service import ClinicalRecord

    with ClinicalRecord.open(args.db) as record:
        return use(record, login(record, args))


@_guard
def cmd_session(args: argparse.Namespace) -> dict[str, Any]:
    """``talus report session --recording X.mcap [--out R.pdf]``."""
    from reports.session_data import session_input_from_recording
    from reports.session_report import render_session_report
    from rt.errors import InputError

    if args.identify and args.session is None:
        raise InputError("--identify needs --session and a user whose role may read the "
                         "patient's identifying data; a recording holds only the pseudonym")
    robot = None
    if args.robot:
        from rt.model import RobotModel
        robot = RobotModel.load(args.robot)
    settings = _settings(args)
    if args.session is not None and args.out is None:
        raise InputError("--session needs --out (where to write the report)")
    out = _out(args, args.recording or args.session)
    if out.exists() and not args.force:
        raise InputError(f"{out}: already exists (use --force to replace it)")
    if args.session is not None:
        from reports.from_record import session_input

        inp = _with_record(args, lambda record, actor: session_input(
            record, actor, args.session, robot, identify=args.identify))
    else:
        inp = session_input_from_recording(args.recording, robot)
    pages = render_session_report(inp, out, settings, _clock(args), force=args.force)
    return {"out": str(out), "pages": pages, "notes": inp.notes}


@_guard
def cmd_progress(args: argparse.Namespace) -> dict[str, Any]:
    """``talus report progress --input progress.json [--from D --to D] [--out R.pdf]``."""
    from reports.progress import load_progress_input, render_progress_report

    if args.patient is not None:
        import datetime as dt

        from reports.from_record import progress_input
        from rt.errors import InputError

        if args.out is None:
            raise InputError("--patient needs --out (where to write the report)")

        def day(s: str | None) -> dt.date | None:
            try:
                return None if s is None else dt.date.fromisoformat(s)
            except ValueError:
                raise InputError(f"not a date (YYYY-MM-DD): {s!r}") from None
        since, until = day(args.date_from), day(args.date_to)
        inp = _with_record(args, lambda record, actor: progress_input(
            record, actor, args.patient, since, until))
        out = _out(args, args.patient)
    else:
        inp = load_progress_input(args.input)
        out = _out(args, args.input)
    pages = render_progress_report(inp, out, _settings(args), _clock(args),
                                   date_from=args.date_from, date_to=args.date_to,
                                   force=args.force)
    return {"out": str(out), "pages": pages}


@_guard
def cmd_calibration(args: argparse.Namespace) -> dict[str, Any]:
    """``talus report calibration --record CAL.json [--out C.pdf]``."""
    from reports.certificate import load_calibration_record, render_certificate

    record = load_calibration_record(args.record)
    out = _out(args, args.record)
    pages = render_certificate(record, out, _settings(args), _clock(args), force=args.force)
    return {"out": str(out), "pages": pages, "pass": record.verdict.pass_}
