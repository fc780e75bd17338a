"""``talus session run``: one clinical session, run by the RT process, from the command line.

The command is a client of the RT process at ``--endpoint``: it takes control of the robot,
sends the protocol (validated here first, so errors name the file and the line), keeps its
heartbeat going while the RT process pre-flights, runs and records the session, shows the
progress, and prints the summary. When no RT process answers there, it starts one on the twin
as a child process (stopped afterwards), so a fresh machine needs nothing else.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

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
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from protocols.rt_session import protocol_document
    from rt.errors import TalusError
    from rt.ipc.embedded import rt_process

    try:
        document = protocol_document(args.protocol)
        patient: dict[str, Any] = {"id": args.patient}
        if args.patient_weight is not None:
            patient["weight_kg"] = args.patient_weight
        record = {"dir": str(_absolute(args.record_dir))} if args.record_dir else {}
        with rt_process(args.endpoint, probe_timeout_s=PROBE_TIMEOUT_S, robot=args.robot,
                        fast=args.fast) as endpoint:
            summary = run_remote(endpoint, document, patient, record,
                                 None if args.json else progress_bar())
    except TalusError as exc:
        print(json.dumps({"error": str(exc)}))
        return 2
    if args.json:
        print(json.dumps(summary))
        return 0
    _print(summary)
    return 0


def _absolute(path: str) -> str:
    from pathlib import Path

    return str(Path(path).resolve())


def run_remote(endpoint: str, document: dict[str, Any], patient: dict[str, Any],
               record: dict[str, Any], progress=None, poll_s: float = 0.2) -> dict[str, Any]:
    """Run one session in the RT process at ``endpoint``; returns its summary."""
    from rt.errors import InputError
    from rt.ipc.client import RtClient, default_client_id

    with RtClient(endpoint, client_id=default_client_id("session"), timeout_s=2.0) as client:
        client.control_acquire(f"talus session run ({patient['id']})")
        client.start_heartbeat(0.05)
        try:
            started = client.session_start(document, patient, record)
            sid = started["session_id"]
            while True:
                st = client.session_status()
                if st["session"] == sid:
                    if progress is not None:
                        progress(float(st["progress"]))
                    time.sleep(poll_s)
                    continue
                last = st.get("last_summary")
                if last is None or last.get("session_id") != sid:
                    raise InputError(f"session {sid} ended without a summary")
                if progress is not None:
                    progress(1.0)
                return last
        finally:
            client.stop_heartbeat()
            try:
                client.control_release()
            except InputError:
                pass       # the session is still stopping: control lapses with the heartbeat


def progress_bar(stream=sys.stderr):
    def show(fraction: float) -> None:
        n = int(fraction * 40)
        stream.write(f"\r[{'#' * n}{'.' * (40 - n)}] {fraction * 100:5.1f} %")
        stream.flush()
        if fraction >= 1.0:
            stream.write("\n")
    return show


def _print(s: dict) -> None:
    w = sys.stdout.write
    where = f"RT process pid {s['rt']['pid']}" if s.get("rt") else "the twin"
    w(f"session: {s['protocol']} ({s['kind']}) by {where} on the twin — {s['outcome']}\n")
    if s["rms_error_pct"] is not None:
        w(f"  force RMS error   {s['rms_error_pct']:.2f} % of {s['rms_error_basis']}\n")
    if s["peak_force_n"] is not None:
        w(f"  peak force        {s['peak_force_n']:.1f} N\n")
    for axis, rng in s["rom_deg"].items():
        if rng:
            w(f"  {axis:5s} reached    {rng[0]:+.1f} .. {rng[1]:+.1f} deg\n")
    w(f"  stops             {len(s['stops'])}"
      + "".join(f"\n    t={x['t']} s {x['reaction']}: {x['cause']} ({x['message']})"
                for x in s["stops"]) + "\n")
    if s.get("recording"):
        w(f"  recording         {s['recording']['path']} (sha256 "
          f"{s['recording']['sha256'][:16]}…)\n")
    pre = s["preflight"]
    w(f"  pre-flight peaks  actuator {pre['peak_actuator_force_n']:.0f} N, slider "
      f"{pre['peak_slider_speed_m_s'] * 1e3:.0f} mm/s\n")
