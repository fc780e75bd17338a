"""``talus twin step`` and ``talus twin serve-ati``."""
from __future__ import annotations

import argparse
import json
import math
import sys

from rt.model.robot_option import add_robot_option


def register(commands: argparse._SubParsersAction) -> None:
    from rt.ati.cli import register_twin_commands

    p = commands.add_parser(
        "step", help="run the twin with constant amplifier commands; JSON lines out",
        description="Hold the three amplifier commands (V, through the real PCI-1720 driver: "
                    "12-bit, clamped at ±6 V) for --seconds and print, at --rate, the time (s), "
                    "q (m, decoded from the PCL-833 counters), qd (m/s, ground truth) and the "
                    "ATI wrench (N, N m, sensor frame).")
    p.add_argument("--seconds", type=float, required=True, help="simulated duration (s)")
    p.add_argument("--volts", type=float, nargs=3, required=True, metavar=("V1", "V2", "V3"))
    p.add_argument("--env", default="free",
                   help="free | payload:KG[@S] | plate[:HEIGHT_M] | ankle (default free)")
    p.add_argument("--rate", type=float, default=100.0, help="output lines per second")
    p.add_argument("--seed", type=int, default=0)
    add_robot_option(p)
    p.set_defaults(func=_step)
    register_twin_commands(commands)
    from rt.twin.rig_cli import register_rig_command

    register_rig_command(commands)


def _step(args) -> int:
    import numpy as np

    from rt.devices.interfaces import Wrench
    from rt.errors import TalusError
    from rt.model.description import load_description
    from rt.twin.backends import TwinActuators, TwinEncoders, TwinForceTorque
    from rt.twin.environment import parse_environment
    from rt.twin.twin import SimClock, Twin

    try:
        if not 0.0 < args.seconds <= 3600.0:
            raise_input(f"--seconds must be in (0, 3600], got {args.seconds}")
        if not 1.0 <= args.rate <= 5000.0:
            raise_input(f"--rate must be in [1, 5000] Hz, got {args.rate}")
        clock = SimClock()
        twin = Twin(load_description(args.robot), environment=parse_environment(args.env),
                    seed=args.seed, clock=clock)
        encoders = TwinEncoders(twin)
        card = TwinActuators(twin, 0)
        sensor = TwinForceTorque(twin)
        sensor.start()
        card.enable()
        card.write_volts(args.volts)
        q = np.zeros(3)
        w = Wrench()
        n = int(round(args.seconds * args.rate))
        for k in range(n + 1):
            clock.t = k / args.rate
            encoders.read_positions_m(q)
            sensor.read(w)
            sys.stdout.write(json.dumps({
                "t": round(clock.t, 9), "q": q.tolist(), "qd": twin.plant.qd.tolist(),
                "wrench": [None if math.isnan(v) else v for v in w.as_tuple()]}) + "\n")
        card.close()
    except TalusError as exc:
        print(json.dumps({"error": str(exc)}))
        return 2
    return 0


def raise_input(message: str) -> None:
    from rt.errors import InputError

    raise InputError(message)
