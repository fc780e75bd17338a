"""``talus rt status|stop|estop|reset``: requests to a running RT server; ``talus rt keys``.

Each prints the reply's ``result`` as one JSON line and exits 0; a refused request or an
unreachable server prints ``{"error": "..."}`` and exits 2. ``status``, ``stop`` and ``estop``
need no control of the robot; ``reset`` takes control for the one request (refused while
another client controls the robot) and acknowledges the latched faults it names with ``--ack``,
or those ``status`` shows when it runs. (``talus rt serve`` is added to this group by the entry
point, which composes what the RT process offers.)
"""
from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from rt.ipc.messages import DEFAULT_ENDPOINT

EXIT_ERROR = 2


def _emit(obj: dict[str, Any]) -> None:
    sys.stdout.write(json.dumps(obj) + "\n")
    sys.stdout.flush()


def _add_connection_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--endpoint", default=DEFAULT_ENDPOINT,
                        help="RT server request address (default %(default)s)")
    parser.add_argument("--timeout", type=float, default=1.0,
                        help="longest wait for the reply, s (default %(default)s)")
    parser.add_argument("--curve-secret", default=None, metavar="FILE",
                        help="this client's CurveZMQ NAME.key_secret (needed off loopback)")
    parser.add_argument("--server-key", default=None, metavar="FILE",
                        help="the server's CurveZMQ public NAME.key (needed off loopback)")


def client_curve(args: argparse.Namespace):
    """The client's CurveZMQ config from ``--curve-secret``/``--server-key`` (both or none)."""
    from rt.errors import ConfigurationError
    from rt.ipc.security import ClientCurveConfig

    if args.curve_secret is None and args.server_key is None:
        return None
    if args.curve_secret is None or args.server_key is None:
        raise ConfigurationError("CurveZMQ needs both --curve-secret and --server-key")
    return ClientCurveConfig(secret_key_file=args.curve_secret,
                             server_public_key_file=args.server_key)


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
        if name == "reset":
            p.add_argument("--ack", type=int, nargs="+", default=None, metavar="EVENT_ID",
                           help="the latched events to acknowledge (ids from `talus rt status`)"
                                "; default: those latched when the reset is sent")
            p.set_defaults(func=cmd_reset)
            continue
        p.set_defaults(func=cmd_request, rt_command=name)
    p = commands.add_parser(
        "keys", help="make a CurveZMQ key pair (NAME.key, NAME.key_secret) in --dir",
        description="Makes a CurveZMQ key pair for the RT server or a client; never overwrites. "
                    "Prints the two paths as one JSON line.")
    p.add_argument("--dir", required=True, help="directory for the key files (made if missing)")
    p.add_argument("--name", default="server", help="file name stem (default %(default)s)")
    p.set_defaults(func=cmd_keys)


def cmd_request(args: argparse.Namespace) -> int:
    """Send ``args.rt_command`` and print the result (or the error) as one JSON line."""
    from rt.errors import TalusError
    from rt.ipc.client import RtClient, default_client_id

    cmd_args: dict[str, Any] = {"source": args.source} if args.rt_command == "estop" else {}
    try:
        with RtClient(args.endpoint, client_id=default_client_id("cli"),
                      timeout_s=args.timeout, curve=client_curve(args)) as client:
            result = client.request(args.rt_command, **cmd_args)
    except TalusError as exc:
        _emit({"error": str(exc)})
        return EXIT_ERROR
    _emit(result)
    return 0


def cmd_reset(args: argparse.Namespace) -> int:
    """Take control, reset the acknowledged faults, give control back."""
    from rt.errors import TalusError
    from rt.ipc.client import RtClient, default_client_id

    try:
        with RtClient(args.endpoint, client_id=default_client_id("cli"),
                      timeout_s=args.timeout, curve=client_curve(args)) as client:
            ack = args.ack
            if ack is None:
                ack = [e["id"] for e in client.status()["latched"]]
            client.request("control_acquire", name="talus rt reset (CLI)")
            try:
                result = client.request("reset", acknowledge=ack)
            finally:
                client.request("control_release")
    except TalusError as exc:
        _emit({"error": str(exc)})
        return EXIT_ERROR
    _emit(result)
    return 0


def cmd_keys(args: argparse.Namespace) -> int:
    """Make a key pair; print ``{"public": ..., "secret": ...}`` (the paths, never the keys)."""
    from rt.errors import TalusError
    from rt.ipc.security import make_keys

    try:
        public, secret = make_keys(args.dir, args.name)
    except TalusError as exc:
        _emit({"error": str(exc)})
        return EXIT_ERROR
    _emit({"public": str(public), "secret": str(secret)})
    return 0
