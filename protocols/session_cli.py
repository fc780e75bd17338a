"""``talus session run``: one clinical session on the twin, end to end."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from rt.cli_args import finite_float


def register(commands: argparse._SubParsersAction) -> None:
    p = commands.add_parser(
        "run", help="pre-flight, run, record and summarize a protocol",
        description="Checks the protocol against the robot's and the patient's limits, runs it "
                    "on the twin as fast as possible (pre-flight; refused with the reason if a "
                    "limit would break), then runs it for real on the backend (the twin, in "
                    "real time), records it to MCAP and prints a summary.")
    p.add_argument("--protocol", required=True, help="protocol YAML (see protocols/library)")
    p.add_argument("--backend", choices=("sim",), default="sim")
    p.add_argument("--record", default=None,
                   help="MCAP file to write (refused if it exists or is one of the inputs)")
    p.add_argument("--force", action="store_true",
                   help="replace an existing --record file, once the new recording is complete")
    p.add_argument("--patient-weight", type=finite_float(10.0, 300.0, unit="kg"), default=None,
                   help="kg (gait replay)")
    p.add_argument("--env", default=None,
                   help="what the platform touches (default: the patient's foot, unloaded at "
                        "the protocol's start pose); e.g. plate:0.74")
    p.add_argument("--fast", action="store_true",
                   help="run the twin as fast as possible instead of in real time")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.set_defaults(func=_run)


def _run(args) -> int:
    from protocols.session import SessionSetup, progress_bar, run_session

    setup = SessionSetup(Path(args.protocol), patient_weight_kg=args.patient_weight,
                         environment=args.env)
    summary = run_session(setup, Path(args.record) if args.record else None,
                          realtime=not args.fast, force=args.force,
                          progress=None if args.json else progress_bar())
    if args.json:
        print(json.dumps(summary))
        return 0
    _print(summary)
    return 0


def _print(s: dict) -> None:
    w = sys.stdout.write
    w(f"session: {s['protocol']} ({s['kind']}) on the twin — "
      f"{'completed' if s['completed'] else 'stopped'}\n")
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
    if s["recording"]:
        w(f"  recording         {s['recording']['path']} (sha256 {s['recording']['sha256'][:16]}…)\n")
    pre = s["preflight"]
    w(f"  pre-flight peaks  actuator {pre['peak_actuator_force_n']:.0f} N, slider "
      f"{pre['peak_slider_speed_m_s'] * 1e3:.0f} mm/s\n")
