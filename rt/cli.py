"""The ``talus`` command line.

Subcommand groups live next to what they drive (``rt/model/cli.py``, ``rt/twin/cli.py``,
``rt/ati/cli.py``); a group's module is imported only when that group is used, so
``talus model ik`` never imports OpenCV or python-can.

JSON-lines commands read one JSON object per line on stdin and write one per line on stdout;
bad input gives ``{"error": "..."}`` on stdout and a non-zero exit code.
"""
from __future__ import annotations

import argparse
import importlib
import sys

#: group name -> (module with ``register(subparsers)``, help)
GROUPS: dict[str, tuple[str, str]] = {
    "model": ("rt.model.cli", "robot model: describe, ik, fk, dynamics (JSON lines)"),
    "twin": ("rt.twin.cli", "digital twin: step it, serve its ATI sensor"),
    "ati": ("rt.ati.cli", "ATI force/torque sensor client"),
    "bench": ("rt.benchmarks.cli", "benchmarks: control loop timing, tracking experiments"),
    "faults": ("rt.safety.cli", "safety: the fault matrix on the twin"),
    "session": ("protocols.session_cli", "run a protocol: pre-flight, run, record, summary"),
    "rt": ("rt.ipc.cli", "RT process: status, stop, estop, reset (JSON)"),
    "record": ("rt.recording.cli", "recordings: info, CSV export"),
    "report": ("reports.cli", "PDF reports: session, progress, calibration certificate"),
}


def build_parser(group: str | None = None) -> argparse.ArgumentParser:
    """The top parser; only ``group``'s module is imported (all when None, for --help)."""
    parser = argparse.ArgumentParser(
        prog="talus", description="talus: 3-PRS rehabilitation and force-plate calibration robot")
    groups = parser.add_subparsers(dest="group", metavar="GROUP", required=True)
    for name, (module_name, help_text) in GROUPS.items():
        group_parser = groups.add_parser(name, help=help_text)
        if group is None or group == name:
            commands = group_parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
            importlib.import_module(module_name).register(commands)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    group = argv[0] if argv and argv[0] in GROUPS else None
    args = build_parser(group).parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except BrokenPipeError:
        # The reader went away (e.g. `| head`): stop quietly, as Unix tools do.
        sys.stderr.close()
        return 0


if __name__ == "__main__":
    sys.exit(main())
