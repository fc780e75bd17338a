"""``talus rt serve``: run the RT process in the foreground until SIGTERM/SIGINT."""
from __future__ import annotations

import argparse
import json
import signal
import sys
import threading
from typing import Any, Callable

from rt.model.robot_option import add_robot_option


def register_serve(commands: argparse._SubParsersAction,
                   extensions: Callable[[], dict[str, Any]] | None = None) -> None:
    """Add ``serve``; ``extensions()`` gives ``rt.service.serve`` its session factory and extra
    programs (the entry point composes them)."""
    p = commands.add_parser("serve", help="run the RT process (loop + supervisor + IPC server)",
                            description="Owns the hardware (the digital twin with --backend "
                            "sim) and the 1 kHz loop; serves commands and publishes telemetry "
                            "and events. Prints {\"serving\": ...} once ready, a summary at "
                            "exit.")
    p.add_argument("--backend", choices=("sim", "twin_shm", "rig"), default=None,
                   help="sim: the twin in this process (the default); twin_shm: the rig process "
                        "started with 'talus twin rig --shm NAME' (its amplifier watchdog guards "
                        "this process); rig: the real cards described in the config's rig: "
                        "section (see rt/data/rig_example.yaml)")
    add_robot_option(p)
    p.add_argument("--shm", default=None, help="with --backend twin_shm: the rig's segment")
    p.add_argument("--config", default=None, help="RT config YAML (see rt.service.RtConfig)")
    p.add_argument("--endpoint", default=None, help="override the request endpoint")
    p.add_argument("--pub-endpoint", default=None, help="override the publish endpoint")
    p.add_argument("--seconds", type=float, default=None, help="stop after this long")
    p.add_argument("--heartbeat-timeout", type=float, default=None,
                   help="the owner's silence after which a motion soft-stops, s (default: the "
                        "config's, 0.25)")
    p.add_argument("--fast", action="store_true",
                   help="with --backend sim: run the twin as fast as possible (demos, tests)")
    p.add_argument("--recordings-dir", default=None,
                   help="where sessions are recorded (default: the config's, else the user "
                        "data directory)")
    p.set_defaults(func=_serve, extensions=extensions)


def _serve(args) -> int:
    from pydantic import ValidationError

    from rt.errors import TalusError
    from rt.ipc.messages import describe_validation_error
    from rt.service import RtConfig, load_config, serve

    try:
        config = load_config(args.config)
        updates = {}
        if args.backend:
            updates["backend"] = args.backend
        if args.shm:
            updates["shm"] = args.shm
        if args.endpoint:
            updates["endpoint"] = args.endpoint
        if args.pub_endpoint:
            updates["pub_endpoint"] = args.pub_endpoint
        if args.robot:
            updates["robot"] = args.robot
        if args.fast:
            updates["loop_mode"] = "fast"
        if args.heartbeat_timeout is not None:
            updates["heartbeat_timeout_s"] = args.heartbeat_timeout
        if args.recordings_dir:
            updates["recordings_dir"] = args.recordings_dir
        config = RtConfig.model_validate({**config.model_dump(), **updates})
    except TalusError as exc:
        print(json.dumps({"error": str(exc)}))
        return 2
    except ValidationError as exc:
        print(json.dumps({"error": f"bad option: {describe_validation_error(exc)}"}))
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
        summary = serve(config, stop, ready,
                        **(args.extensions() if args.extensions is not None else {}))
    except TalusError as exc:
        print(json.dumps({"error": str(exc)}))
        return 2
    summary["events"] = len(summary["events"])
    print(json.dumps({"stopped": summary}), flush=True)
    sys.stdout.flush()
    return 0
