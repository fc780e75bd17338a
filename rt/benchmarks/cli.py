"""``talus bench tracking|loop``: benchmark figures as JSON (``--json``) or text."""
from __future__ import annotations

import argparse
import json

from rt.cli_args import name_choice, rate_hz, seconds
from rt.model.robot_option import add_robot_option
from rt.twin.realism import add_twin_arguments

#: The controllers rt.control registers (kept here so --help imports no numpy).
CONTROLLER_NAMES = ("pid", "pd_g", "pd_g0", "paden_panja", "computed_torque_ptp",
                    "computed_torque", "adaptive")


def register(commands: argparse._SubParsersAction) -> None:
    p = commands.add_parser(
        "tracking", help="thesis fig. 48/50 tracking experiments through the position loop on "
                         "the realistic twin")
    p.add_argument("--experiment", choices=("pid-vs-paden", "parameter-step", "payload-step"),
                   help="one experiment (default: all three with --profile thesis)")
    p.add_argument("--profile", choices=("product", "thesis"), default="product",
                   help="product: 1 kHz; thesis: 100 Hz and 1 kHz, beside the thesis's figures")
    p.add_argument("--rate", type=rate_hz(100.0, 2000.0), help="one loop rate, Hz (default: "
                   "the profile's)")
    p.add_argument("--seconds", type=seconds(hi=600.0), default=26.0,
                   help="experiment duration, s (default %(default)s)")
    p.add_argument("--robot", help="the description the controllers believe (default: nominal)")
    add_twin_arguments(p)
    p.add_argument("--json", action="store_true", help="one JSON object per run (JSON lines)")
    p.set_defaults(func=_tracking)
    register_loop(commands)


def _tracking(args) -> int:
    from rt.benchmarks.tracking import EXPERIMENTS, run_experiment, table
    from rt.errors import InputError
    from rt.model.description import load_description

    robot = load_description(args.robot) if args.robot else None
    truth = load_description(args.truth) if args.truth else None
    if args.experiment:
        experiments = [args.experiment]
    elif args.profile == "thesis":
        experiments = list(EXPERIMENTS)
    else:
        raise InputError("--experiment is required with --profile product")
    rates = ([args.rate] if args.rate else [100.0, 1000.0] if args.profile == "thesis"
             else [1000.0])
    results = []
    for rate in rates:
        for name in experiments:
            r = run_experiment(name, args.seconds, rate, args.profile, truth, robot,
                               args.ideal_twin)
            results.append(r)
            if args.json:
                print(json.dumps(r), flush=True)
    if not args.json:
        kind = "ideal twin" if args.ideal_twin else "realistic twin (truth apart from the model)"
        print(f"tracking through the position loop on the {kind}; thesis: real rig, 100 Hz")
        print(table(results))
    return 0


def register_loop(commands: argparse._SubParsersAction) -> None:
    p = commands.add_parser(
        "loop", help="run the position loop on the twin and report per-block and whole-cycle "
                     "execution times and deadline misses")
    p.add_argument("--controller", type=name_choice(CONTROLLER_NAMES), default="paden_panja",
                   help=", ".join(CONTROLLER_NAMES) + " ('-' and '_' alike)")
    p.add_argument("--seconds", type=seconds(hi=600.0), default=10.0,
                   help="run length, s (default %(default)s)")
    p.add_argument("--rate", type=rate_hz(100.0, 2000.0), default=1000.0,
                   help="loop rate, Hz (100-2000)")
    p.add_argument("--mode", choices=("realtime", "fast"), default="realtime",
                   help="realtime: paced by the clock (deadline misses meaningful); fast: "
                        "back-to-back in simulated time")
    p.add_argument("--cpu-latency-us", type=int, default=0, metavar="US",
                   help="bound every CPU's wake-up latency through PM QoS while the loop runs, "
                        "as the RT process does (0, the default: idle CPUs poll; needs root; "
                        "-1: not requested)")
    p.add_argument("--no-fused", action="store_true",
                   help="run the five middle blocks' update one by one (the per-block "
                        "reference) instead of the fused compiled chain; also "
                        "TALUS_FUSED_CYCLE=0")
    p.add_argument("--json", action="store_true")
    add_robot_option(p)
    p.set_defaults(func=_loop)


def _model(args):
    from rt.model import RobotModel

    return RobotModel.load(args.robot)


def _loop(args) -> int:
    from rt.benchmarks.loop import run_loop_benchmark

    if not -1 <= args.cpu_latency_us <= 10_000:
        raise SystemExit(f"--cpu-latency-us: a bound in [0, 10000] µs or -1, got "
                         f"{args.cpu_latency_us}")
    qos = None if args.cpu_latency_us < 0 else args.cpu_latency_us
    result = run_loop_benchmark(args.controller, args.seconds, args.rate, args.mode,
                                model=_model(args), cpu_latency_us=qos,
                                fused=False if args.no_fused else None)
    if args.json:
        print(json.dumps(result))
    else:
        print(f"{result['controller']} at {result['rate_hz']:.0f} Hz ({result['mode']}, twin): "
              f"{result['cycles']} cycles, {result['deadline_misses']} deadline misses")
        if result["latched"]:
            print(f"  the supervisor stopped the loop ({', '.join(result['latched'])}): the "
                  f"figures include the stop's cycles, not only steady ones")
        c = result["cycle_us"]
        print(f"  whole cycle      median {c['median']:7.1f}  p99 {c['p99']:7.1f}  max "
              f"{c['max']:8.1f} µs")
        c = result["cycle_without_twin_us"]
        print(f"  without the twin median {c['median']:7.1f}  p99 {c['p99']:7.1f}  max "
              f"{c['max']:8.1f} µs")
        for name, c in result["components"].items():
            print(f"  {name:16s} median {c['median']:7.1f}  p99 {c['p99']:7.1f}  max "
                  f"{c['max']:8.1f} µs")
    return 0
