"""The ``talus`` command line.

Subcommand groups live next to what they drive (``rt/model/cli.py``, ``rt/twin/cli.py``,
``protocols/session_cli.py``); a group's modules are imported only when that group is used, so
``talus model ik`` never imports OpenCV or python-can. This module is the composition point:
it is the only place that knows every package (``rt`` imports nothing above itself).

JSON-lines commands read one JSON object per line on stdin and write one per line on stdout;
bad input gives ``{"error": "..."}`` on stdout and a non-zero exit code.
"""
from __future__ import annotations

import argparse
import importlib
import json
import sys

#: group name -> (modules, each with ``register(subparsers)``, help)
GROUPS: dict[str, tuple[tuple[str, ...], str]] = {
    "model": (("rt.model.cli",), "robot model: describe, ik, fk, dynamics (JSON lines)"),
    "twin": (("rt.twin.cli",), "digital twin: step it, serve its ATI sensor"),
    "ati": (("rt.ati.cli",), "ATI force/torque sensor client"),
    "bench": (("rt.benchmarks.cli", "protocols.bench_force"),
              "benchmarks: control loop timing, tracking and force experiments"),
    "faults": (("rt.safety.cli",), "safety: the fault matrix on the twin"),
    "session": (("talus.session_cli",),
                "run a protocol through the RT process: pre-flight, run, record, summary"),
    "rt": (("rt.ipc.cli", "talus.rt_serve"),
           "RT process: serve, status, control, stop, estop, reset (JSON)"),
    "record": (("rt.recording.cli",), "recordings: info, CSV export"),
    "gui": (("app.cli",), "the clinician GUI (talus gui [--screenshot DIR])"),
    "db": (("patients.db_cli",), "clinical database: upgrade, backup, restore, demo"),
    "users": (("patients.users_cli",), "users and roles: init, add, passwd, list"),
    "patients": (("patients.patients_cli",),
                 "patients: add, list, show, limits, forget, export"),
    "sessions": (("patients.sessions_cli",), "stored therapy sessions: list, show"),
    "audit": (("patients.audit_cli",), "audit log: verify, export"),
    "calibrations": (("patients.calibrations_cli",),
                     "stored force-plate calibrations: add, certify, list, show"),
    "report": (("reports.cli",), "PDF reports: session, progress, calibration certificate"),
    "calibrate": (("calibration.cli",),
                  "force-plate calibration: plan, run, fit, verify, export, demo"),
    "identify": (("rt.identification.cli",),
                 "dynamic identification: excite, estimate, write a description file"),
}
#: group -> the command run when the group is given only options (``talus gui --lang es``)
DEFAULT_COMMANDS: dict[str, str] = {"gui": "start"}


def build_parser(group: str | None = None) -> argparse.ArgumentParser:
    """The top parser; only ``group``'s module is imported (all when None, for --help)."""
    parser = argparse.ArgumentParser(
        prog="talus", description="talus: 3-PRS rehabilitation and force-plate calibration robot")
    groups = parser.add_subparsers(dest="group", metavar="GROUP", required=True)
    for name, (module_names, help_text) in GROUPS.items():
        group_parser = groups.add_parser(name, help=help_text)
        if group is None or group == name:
            commands = group_parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
            for module_name in module_names:
                importlib.import_module(module_name).register(commands)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    group = argv[0] if argv and argv[0] in GROUPS else None
    if group in DEFAULT_COMMANDS and (len(argv) == 1 or argv[1].startswith("-")
                                      and argv[1] not in ("-h", "--help")):
        argv = [group, DEFAULT_COMMANDS[group], *argv[1:]]
    args = build_parser(group).parse_args(argv)
    from rt.errors import TalusError

    try:
        return int(args.func(args) or 0)
    except TalusError as exc:
        # A command that did not report its own error: one line, exit code 2 (a bad --robot
        # file, a missing card), never a traceback.
        print(json.dumps({"error": str(exc)}), flush=True)
        return 2
    except BrokenPipeError:
        # The reader went away (e.g. `| head`): stop quietly, as Unix tools do.
        sys.stderr.close()
        return 0


if __name__ == "__main__":
    sys.exit(main())
