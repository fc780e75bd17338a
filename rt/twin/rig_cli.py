"""``talus twin rig``: run the twin as a separate rig process over shared memory.

``register_rig_command(commands)`` adds the command to the ``talus twin`` group. Until that is
hooked into ``rt/twin/cli.py`` the same command runs as ``python -m rt.twin.rig_cli rig ...``.

Output (JSON lines on stdout): ``{"rig": {"shm", "pid", ...}}`` once the segment is ready,
``{"stopped": {...summary...}}`` at exit; errors are one ``{"error": "..."}`` line and exit
code 2. SIGTERM and SIGINT stop the rig at the next period; the segment is unlinked.
"""
from __future__ import annotations

import argparse
import json
import signal
import sys
import threading
from typing import Any

from rt.model.robot_option import add_robot_option

EXIT_ERROR = 2


def _emit(obj: dict[str, Any]) -> None:
    sys.stdout.write(json.dumps(obj) + "\n")
    sys.stdout.flush()


def register_rig_command(commands: argparse._SubParsersAction) -> None:
    """Add ``rig`` to a subcommand group (``talus twin``)."""
    p = commands.add_parser(
        "rig", help="run the twin as a separate rig process over shared memory",
        description="Run the digital twin in real time as the rig's hardware: the RT process "
                    "attaches to the shared memory --shm NAME with the 'twin_shm' backends. "
                    "Emulates the amplifier watchdog: unless the RT process feeds it at least "
                    "every --watchdog-ms, the drives drop to 0 V and stay off until re-armed.")
    p.add_argument("--shm", required=True, help="shared-memory name (appears as /dev/shm/NAME)")
    p.add_argument("--env", default="free",
                   help="free | payload:KG[@S] | plate[:HEIGHT_M] | ankle (default free)")
    p.add_argument("--seed", type=int, default=0, help="sensor noise seed (default 0)")
    p.add_argument("--seconds", type=float, default=None,
                   help="stop after this many seconds (default: until SIGTERM/SIGINT)")
    p.add_argument("--watchdog-ms", type=float, default=20.0,
                   help="amplifier watchdog timeout, ms (default 20)")
    p.add_argument("--rate", type=float, default=1000.0, help="rig rate, Hz (default 1000)")
    add_robot_option(p)
    p.add_argument("--fifo", type=int, default=None, metavar="PRIORITY",
                   help="try SCHED_FIFO at this priority (default: normal scheduling)")
    p.set_defaults(func=cmd_rig)


def cmd_rig(args: argparse.Namespace) -> int:
    """Run the rig until ``--seconds``, SIGTERM or SIGINT; print ready and summary lines."""
    from rt.errors import TalusError
    from rt.model.description import load_description
    from rt.twin.rig import RigProcess

    if args.seconds is not None and not args.seconds > 0.0:
        _emit({"error": f"--seconds must be positive, got {args.seconds}"})
        return EXIT_ERROR
    stop_requested = False
    rig: RigProcess | None = None

    def _stop(signum: int, frame: object) -> None:
        nonlocal stop_requested
        stop_requested = True
        if rig is not None:
            rig.request_stop()

    # Handlers first: a SIGTERM during the ≈ 1 s start-up must still unlink the segment.
    previous: dict[int, Any] = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGTERM, signal.SIGINT):
            previous[sig] = signal.signal(sig, _stop)
    try:
        try:
            rig = RigProcess(args.shm, args.env, args.seed, rate_hz=args.rate,
                             watchdog_timeout_s=args.watchdog_ms * 1e-3,
                             description=load_description(args.robot))
        except TalusError as exc:
            _emit({"error": str(exc)})
            return EXIT_ERROR
        try:
            if stop_requested:
                rig.request_stop()

            def ready(r: RigProcess) -> None:
                _emit({"rig": {"shm": r.name, "pid": int(r.seg.header.rig_pid[0]),
                               "rate_hz": r.rate_hz,
                               "watchdog_ms": r.watchdog_timeout_s * 1e3, "env": args.env}})

            summary = rig.run(seconds=args.seconds, fifo_priority=args.fifo, on_ready=ready)
        finally:
            rig.close()
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    _emit({"stopped": summary.as_dict()})
    return EXIT_ERROR if summary.error else 0


def main(argv: list[str] | None = None) -> int:
    """``python -m rt.twin.rig_cli rig ...`` (the same command before it joins ``talus twin``)."""
    parser = argparse.ArgumentParser(prog="talus twin")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    register_rig_command(commands)
    args = parser.parse_args(argv)
    return int(args.func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
