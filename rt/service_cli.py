"""``talus rt serve``: run the RT process in the foreground until SIGTERM/SIGINT."""
from __future__ import annotations

import argparse
import json
import signal
import sys
import threading

from rt.cli_args import seconds


def register_serve(commands: argparse._SubParsersAction) -> None:
    p = commands.add_parser("serve", help="run the RT process (loop + supervisor + IPC server)",
                            description="Owns the hardware (the digital twin with --backend "
                            "sim) and the 1 kHz loop; serves commands and publishes telemetry "
                            "and events. Prints {\"serving\": ...} once ready, a summary at "
                            "exit.")
    p.add_argument("--backend", choices=("sim", "twin_shm"), default="sim",
                   help="sim: the twin in this process; twin_shm: the rig process started with "
                        "'talus twin rig --shm NAME' (its amplifier watchdog guards this process)")
    p.add_argument("--shm", default=None, help="with --backend twin_shm: the rig's segment")
    p.add_argument("--config", default=None, help="RT config YAML (see rt.service.RtConfig)")
    p.add_argument("--endpoint", default=None, help="override the request endpoint")
    p.add_argument("--pub-endpoint", default=None, help="override the publish endpoint")
    p.add_argument("--seconds", type=seconds(hi=30 * 24 * 3600.0), default=None,
                   help="stop after this long (s)")
    p.set_defaults(func=_serve)


def _serve(args) -> int:
    from rt.errors import TalusError
    from rt.service import load_config, serve

    try:
        config = load_config(args.config)
        updates = {"backend": args.backend}
        if args.shm:
            updates["shm"] = args.shm
        if args.endpoint:
            updates["endpoint"] = args.endpoint
        if args.pub_endpoint:
            updates["pub_endpoint"] = args.pub_endpoint
        config = config.model_copy(update=updates)
    except TalusError as exc:
        print(json.dumps({"error": str(exc)}))
        return 2
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    if args.seconds is not None:
        threading.Timer(args.seconds, stop.set).start()

    def ready(server) -> None:
        print(json.dumps({"serving": {"endpoint": server.endpoint,
                                      "pub_endpoint": server.pub_endpoint}}), flush=True)

    try:
        summary = serve(config, stop, ready)
    except TalusError as exc:
        print(json.dumps({"error": str(exc)}))
        return 2
    summary["events"] = len(summary["events"])
    print(json.dumps({"stopped": summary}), flush=True)
    sys.stdout.flush()
    return 0
