"""``talus ati read`` and ``talus twin serve-ati``.

Both print JSON lines on stdout. Errors are one ``{"error": "..."}`` line and exit code 2.
Heavy modules (numpy, the twin) are imported inside the commands, not at import time.
"""
from __future__ import annotations

import argparse
import json
import signal
import sys
import threading
from dataclasses import asdict
from typing import Any

from rt.ati.rdt import DEFAULT_COUNTS_PER_FORCE, DEFAULT_COUNTS_PER_TORQUE, RDT_PORT
from rt.errors import TalusError
from rt.model.robot_option import add_robot_option

EXIT_ERROR = 2


def _emit(obj: dict[str, Any]) -> None:
    sys.stdout.write(json.dumps(obj) + "\n")
    sys.stdout.flush()


def _add_counts_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--counts-per-force", type=float, default=DEFAULT_COUNTS_PER_FORCE,
                        help="counts per N (sensor configuration; default %(default)g)")
    parser.add_argument("--counts-per-torque", type=float, default=DEFAULT_COUNTS_PER_TORQUE,
                        help="counts per N m (sensor configuration; default %(default)g)")


def register(commands: argparse._SubParsersAction) -> None:
    """``talus ati ...`` commands."""
    p = commands.add_parser(
        "read", help="read wrenches from an ATI Net F/T over UDP RDT (JSON lines)",
        description="Print one JSON line per record: t (host monotonic s), seq (rdt_sequence), "
                    "fx fy fz (N), tx ty tz (N m), status (raw status word).")
    p.add_argument("--host", default="192.168.1.1", help="sensor address (default %(default)s)")
    p.add_argument("--port", type=int, default=RDT_PORT, help="RDT port (default %(default)s)")
    p.add_argument("--samples", type=int, default=1, help="records to read (default 1)")
    p.add_argument("--bias", action="store_true", help="software-bias the sensor first")
    p.add_argument("--timeout", type=float, default=1.0,
                   help="longest wait for each record, s (default %(default)s)")
    p.add_argument("--buffered", action="store_true",
                   help="use buffered streaming (several records per datagram)")
    _add_counts_options(p)
    p.set_defaults(func=cmd_read)


def register_twin_commands(commands: argparse._SubParsersAction) -> None:
    """``talus twin serve-ati``."""
    p = commands.add_parser(
        "serve-ati", help="serve the twin's ATI sensor over UDP RDT",
        description="Serve a TwinAtiSensorModel under a constant true wrench over the real RDT "
                    "protocol. Prints {\"serving\": ...} once bound (port 0 = ephemeral) and "
                    "the server counters when it stops.")
    p.add_argument("--host", default="127.0.0.1", help="bind address (default %(default)s)")
    p.add_argument("--port", type=int, default=RDT_PORT,
                   help="UDP port, 0 = ephemeral (default %(default)s)")
    p.add_argument("--rate", type=float, default=1000.0, help="record rate, Hz (default 1000)")
    p.add_argument("--seconds", type=float, default=None,
                   help="stop after this many seconds (default: until interrupted)")
    p.add_argument("--seed", type=int, default=0, help="noise/drift seed (default 0)")
    p.add_argument("--wrench", type=float, nargs=6, metavar=("FX", "FY", "FZ", "TX", "TY", "TZ"),
                   default=[0.0, 0.0, -50.0, 0.0, 0.0, 0.0],
                   help="true wrench, N and N m (default 0 0 -50 0 0 0: light static load)")
    p.add_argument("--buffer", type=int, default=10,
                   help="records per datagram in buffered mode (default %(default)s)")
    p.add_argument("--env", default=None,
                   help="run the full twin in real time in this environment (free, "
                        "payload:KG[@S], plate[:HEIGHT_M], ankle) and serve its sensor instead "
                        "of a constant wrench")
    p.add_argument("--volts", type=float, nargs=3, default=None, metavar=("V1", "V2", "V3"),
                   help="with --env: amplifier commands held on the twin (default: the "
                        "gravity-compensating voltages at home)")
    _add_counts_options(p)
    add_robot_option(p)
    p.set_defaults(func=cmd_serve_ati)


def cmd_read(args: argparse.Namespace) -> int:
    """Read ``args.samples`` records and print them; exit 2 when the sensor does not answer."""
    from rt.ati.rdt_client import RdtForceTorqueSensor

    try:
        with RdtForceTorqueSensor(args.host, args.port, counts_per_force=args.counts_per_force,
                                  counts_per_torque=args.counts_per_torque,
                                  buffered=args.buffered) as sensor:
            if args.bias:
                sensor.bias()  # before start, so every streamed record is biased
            samples = sensor.read_samples(args.samples, args.timeout, start=True)
            sensor.stop()
    except TalusError as exc:
        _emit({"error": str(exc)})
        return EXIT_ERROR
    for w in samples:
        _emit({"t": w.t, "seq": w.sequence, "fx": w.fx, "fy": w.fy, "fz": w.fz,
               "tx": w.tx, "ty": w.ty, "tz": w.tz, "status": w.status})
    if len(samples) < args.samples:
        _emit({"error": f"only {len(samples)} of {args.samples} records arrived "
                        f"(waited up to {args.timeout} s for each)"})
        return EXIT_ERROR
    return 0


class _Terminate(Exception):
    """Raised from the SIGTERM handler to leave the serving wait."""


def _raise_terminate(signum: int, frame: object) -> None:
    raise _Terminate()


def cmd_serve_ati(args: argparse.Namespace) -> int:
    """Serve the twin sensor until ``--seconds`` elapse, Ctrl-C or SIGTERM."""
    from rt.ati.rdt import CountsPerUnit
    from rt.ati.rdt_server import RdtServer
    from rt.ati.twin_sensor import TwinAtiSensorModel

    try:
        if args.env is not None:
            from rt.twin.serve import twin_wrench_source

            from rt.model.description import load_description

            source = twin_wrench_source(args.env, args.volts, args.seed,
                                        load_description(args.robot))
        else:
            model = TwinAtiSensorModel(seed=args.seed)
            source = model.make_source(args.wrench)
        server = RdtServer(source, host=args.host, port=args.port, rate_hz=args.rate,
                           buffer_records=args.buffer,
                           counts=CountsPerUnit(args.counts_per_force, args.counts_per_torque))
    except TalusError as exc:
        _emit({"error": str(exc)})
        return EXIT_ERROR
    except OSError as exc:
        _emit({"error": f"cannot serve RDT on {args.host}:{args.port}: {exc}"})
        return EXIT_ERROR
    previous = None
    if threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGTERM, _raise_terminate)
    try:
        with server:
            _emit({"serving": {"host": server.host, "port": server.port,
                               "rate_hz": server.rate_hz}})
            try:
                threading.Event().wait(args.seconds)
            except (KeyboardInterrupt, _Terminate):
                pass
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
    _emit({"stopped": asdict(server.counters)})
    return 0
