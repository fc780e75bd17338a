"""``talus rt status|stop|estop|reset``: one request to a running RT server.

Each prints the reply's ``result`` as one JSON line and exits 0; a refused request or an
unreachable server prints ``{"error": "..."}`` and exits 2. (``talus rt serve`` is added to this
group by the RT process's own module.)
"""
from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from rt.cli_args import seconds
from rt.ipc.messages import DEFAULT_ENDPOINT

EXIT_ERROR = 2


def _emit(obj: dict[str, Any]) -> None:
    sys.stdout.write(json.dumps(obj) + "\n")
    sys.stdout.flush()


def _add_connection_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--endpoint", default=DEFAULT_ENDPOINT,
                        help="RT server request address (default %(default)s)")
    parser.add_argument("--timeout", type=seconds(hi=60.0), default=1.0,
                        help="longest wait for the reply, s (default %(default)s)")


def register(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``status``, ``stop``, ``estop``, ``reset`` to the ``rt`` group's subparsers."""
    specs = [
        ("status", "print the RT process's status"),
        ("stop", "soft stop: decelerate to hold, ramp force down"),
        ("estop", "hard stop: outputs to zero, drives disabled (latches until reset)"),
        ("reset", "reset latched faults"),
    ]
    for name, help_text in specs:
        p = commands.add_parser(name, help=help_text, description=help_text + ". Prints the "
                                "result as one JSON line; {\"error\": ...} and exit 2 if refused "
                                "or the server does not answer.")
        _add_connection_options(p)
        if name == "estop":
            p.add_argument("--source", choices=("cli", "keyboard", "gui"), default="cli",
                           help="reported source of the stop (default %(default)s)")
        p.set_defaults(func=cmd_request, rt_command=name)
    from rt.service_cli import register_serve

    register_serve(commands)


def cmd_request(args: argparse.Namespace) -> int:
    """Send ``args.rt_command`` and print the result (or the error) as one JSON line."""
    from rt.errors import TalusError
    from rt.ipc.client import RtClient, default_client_id

    cmd_args: dict[str, Any] = {"source": args.source} if args.rt_command == "estop" else {}
    try:
        with RtClient(args.endpoint, client_id=default_client_id("cli"),
                      timeout_s=args.timeout) as client:
            result = client.request(args.rt_command, **cmd_args)
    except TalusError as exc:
        _emit({"error": str(exc)})
        return EXIT_ERROR
    _emit(result)
    return 0
