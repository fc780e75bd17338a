"""``talus session run``: one clinical session, run by the RT process, from the command line.

The command is a client of the RT process at ``--endpoint``: it takes control of the robot,
sends the protocol (validated here first, so errors name the file and the line), keeps its
heartbeat going while the RT process pre-flights, runs and records the session, shows the
progress, and prints the summary. When no RT process answers there, it starts one on the twin
as a child process (stopped afterwards), so a fresh machine needs nothing else.

With ``--user`` the session is the clinical record's (``patients``): the user logs in, the
patient's limits in force and body mass come from the record, and the session is stored with
its outcome, summary and recording. It lives here, at the entry point, because it composes
the protocols and the clinical record.
"""
from __future__ import annotations

import argparse
import json
from typing import Any

from rt.errors import InputError
from rt.ipc.messages import DEFAULT_ENDPOINT

#: How long the CLI waits for an RT process to answer before starting its own (s).
PROBE_TIMEOUT_S = 0.5


def register(commands: argparse._SubParsersAction) -> None:
    p = commands.add_parser(
        "run", help="pre-flight, run, record and summarize a protocol in the RT process",
        description="Sends the protocol to the RT process at --endpoint (or to an embedded one "
                    "on the twin when none answers): it checks the protocol against the "
                    "robot's and the patient's limits, runs it on the twin as fast as possible "
                    "(pre-flight; refused with the reason if a limit would break), runs it for "
                    "real, records it to MCAP in a file it names, and answers with a summary.")
    p.add_argument("--protocol", required=True, help="protocol YAML (see protocols/library)")
    p.add_argument("--endpoint", default=DEFAULT_ENDPOINT,
                   help="the RT process's request address (default %(default)s)")
    p.add_argument("--patient", default="twin-demo",
                   help="the patient's pseudonymous code (default %(default)s)")
    p.add_argument("--patient-weight", type=float, default=None, help="kg (gait replay)")
    p.add_argument("--record-dir", default=None,
                   help="directory for the recording (default: the RT process's recordings "
                        "directory); the RT process names the file, never overwriting one")
    p.add_argument("--robot", default=None,
                   help="robot description YAML for an embedded RT process (default: nominal)")
    p.add_argument("--fast", action="store_true",
                   help="an embedded RT process runs the twin as fast as possible instead of in "
                        "real time")
    p.add_argument("--user", default=None,
                   help="clinical record user (password: prompt or TALUS_PASSWORD): the "
                        "patient's limits and body mass come from the record, and the session "
                        "is stored there")
    p.add_argument("--db", default=None,
                   help="clinical record URL (default: TALUS_DATABASE_URL, else the user data "
                        "directory's SQLite file)")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from protocols.rt_session import protocol_document
    from protocols.session_client import print_summary, progress_bar, run_remote
    from rt.errors import TalusError
    from rt.ipc.embedded import rt_process

    try:
        document = protocol_document(args.protocol)
        record = {"dir": str(_absolute(args.record_dir))} if args.record_dir else {}
        progress = None if args.json else progress_bar()
        with rt_process(args.endpoint, probe_timeout_s=PROBE_TIMEOUT_S, robot=args.robot,
                        fast=args.fast) as endpoint:
            if args.user is None:
                patient: dict[str, Any] = {"id": args.patient}
                if args.patient_weight is not None:
                    patient["weight_kg"] = args.patient_weight
                summary = run_remote(endpoint, document, patient, record, progress)
            else:
                summary = _run_for_patient(args, endpoint, document, record, progress)
    except TalusError as exc:
        print(json.dumps({"error": str(exc)}))
        return 2
    if args.json:
        print(json.dumps(summary))
        return 0
    print_summary(summary)
    return 0


def _run_for_patient(args: argparse.Namespace, endpoint: str, document: dict[str, Any],
                     record: dict[str, Any], progress) -> dict[str, Any]:
    """The session of a patient of the clinical record, stored there (the summary gets the
    stored session's id as ``stored_session``)."""
    from pathlib import Path

    from patients.cli_common import login
    from patients.service import ClinicalRecord
    from patients.session_record import rt_patient, run_for_patient
    from protocols.session_client import run_remote

    if args.patient_weight is not None:
        raise InputError("--patient-weight comes from the clinical record with --user "
                         "(the patient's body mass)")
    with ClinicalRecord.open(args.db) as clinical:
        actor = login(clinical, args)
        box: dict[str, Any] = {}

        def runner(started: dict[str, Any], _recording: Any) -> dict[str, Any]:
            box["summary"] = run_remote(endpoint, document, rt_patient(started), record,
                                        progress)
            return box["summary"]
        stored = run_for_patient(clinical, actor, args.patient, Path(args.protocol), None,
                                 runner)
    summary = box["summary"]
    summary["stored_session"] = stored.get("uid")
    return summary


def _absolute(path: str) -> str:
    from pathlib import Path

    return str(Path(path).resolve())


