"""``talus twin step`` and ``talus twin serve-ati``."""
from __future__ import annotations

import argparse
import json
import math
import sys

from rt.cli_args import finite_float, rate_hz, seconds, seed
from rt.model.robot_option import add_robot_option

#: The amplifier commands a user may hold (V); the drive clamps at ±6 V, the DAC spans ±10 V.
VOLTS = finite_float(-10.0, 10.0, unit="V")

def register(commands: argparse._SubParsersAction) -> None:
    from rt.ati.cli import register_twin_commands
    from rt.twin.realism import add_twin_arguments

    p = commands.add_parser(
        "step", help="run the twin with constant amplifier commands; JSON lines out",
        description="Hold the three amplifier commands (V, through the real PCI-1720 driver: "
                    "12-bit, clamped at ±6 V) for --seconds and print, at --rate, the time (s), "
                    "q (m, decoded from the PCL-833 counters), qd (m/s, ground truth) and the "
                    "ATI wrench (N, N m, sensor frame).")
    p.add_argument("--seconds", type=seconds(), required=True, help="simulated duration (s)")
    p.add_argument("--volts", type=VOLTS, nargs=3, required=True, metavar=("V1", "V2", "V3"))
    p.add_argument("--env", default="free",
                   help="free | payload:KG[@S] | plate[:HEIGHT_M] | ankle (default free)")
    p.add_argument("--rate", type=rate_hz(1.0, 5000.0), default=100.0,
                   help="output lines per second (1-5000)")
    p.add_argument("--seed", type=seed(), default=0)
    add_robot_option(p)
    add_twin_arguments(p)
    p.set_defaults(func=_step)
    register_twin_commands(commands)
    from rt.twin.rig_cli import register_rig_command

    register_rig_command(commands)


def _step(args) -> int:
    import numpy as np

    from rt.devices.interfaces import Wrench
    from rt.model.description import load_description
    from rt.twin.backends import TwinActuators, TwinEncoders, TwinForceTorque
    from rt.twin.environment import parse_environment
    from rt.twin.realism import twin_setup
    from rt.twin.twin import SimClock, Twin

    clock = SimClock()
    truth, imperfections = twin_setup(
        args, load_description(args.robot) if args.robot else None)
    twin = Twin(truth, parse_environment(args.env), seed=args.seed, clock=clock,
                imperfections=imperfections)
    encoders = TwinEncoders(twin)
    card = TwinActuators(twin, 0)
    sensor = TwinForceTorque(twin)
    sensor.start()
    card.enable()
    card.write_volts(args.volts)
    q = np.zeros(3)
    w = Wrench()
    n = round(args.seconds * args.rate)
    for k in range(n + 1):
        clock.t = k / args.rate
        encoders.read_positions_m(q)
        sensor.read(w)
        sys.stdout.write(json.dumps({
            "t": round(clock.t, 9), "q": _finite(q.tolist()),
            "qd": _finite(twin.plant.qd.tolist()), "wrench": _finite(w.as_tuple())},
            allow_nan=False) + "\n")
    card.close()
    return 0


def _finite(values) -> list[float | None]:
    """JSON has no NaN or infinity: a value that is not finite (no sample yet) is null."""
    return [v if math.isfinite(v) else None for v in values]
