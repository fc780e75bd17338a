"""``talus bench tracking|loop``: benchmark figures as JSON (``--json``) or text."""
from __future__ import annotations

import argparse
import json

from rt.model.robot_option import add_robot_option


def register(commands: argparse._SubParsersAction) -> None:
    p = commands.add_parser("tracking", help="thesis fig. 48/50 tracking experiments on the twin")
    p.add_argument("--experiment", choices=("pid-vs-paden", "payload-step"), required=True)
    p.add_argument("--seconds", type=float, default=26.0)
    p.add_argument("--json", action="store_true")
    add_robot_option(p)
    p.set_defaults(func=_tracking)
    register_loop(commands)


def _model(args):
    from rt.model import RobotModel

    return RobotModel.load(args.robot)


def _tracking(args) -> int:
    from rt.benchmarks.tracking import fig50_table, run_experiment

    result = run_experiment(args.experiment, args.seconds, model=_model(args))
    if args.json:
        print(json.dumps(result))
    elif args.experiment == "payload-step":
        print(fig50_table(result))
    else:
        for ctrl, r in result["controllers"].items():
            print(f"{ctrl:12s} peak |e| {r['peak_abs_m'] * 1e3:.3f} mm, mean |e| "
                  f"{r['period1']['mean_abs_m'] * 1e3:.3f} / {r['period2']['mean_abs_m'] * 1e3:.3f}"
                  " mm (periods 1/2)")
    return 0


def register_loop(commands: argparse._SubParsersAction) -> None:
    p = commands.add_parser(
        "loop", help="run the position loop on the twin and report per-block and whole-cycle "
                     "execution times and deadline misses")
    p.add_argument("--controller", default="paden_panja",
                   help="pid, pd_g, pd_g0, paden_panja, computed_torque_ptp, computed_torque, "
                        "adaptive")
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--rate", type=float, default=1000.0, help="loop rate, Hz (100-2000)")
    p.add_argument("--mode", choices=("realtime", "fast"), default="realtime",
                   help="realtime: paced by the clock (deadline misses meaningful); fast: "
                        "back-to-back in simulated time")
    p.add_argument("--json", action="store_true")
    add_robot_option(p)
    p.set_defaults(func=_loop)


def _loop(args) -> int:
    from rt.benchmarks.loop import run_loop_benchmark

    result = run_loop_benchmark(args.controller, args.seconds, args.rate, args.mode,
                                model=_model(args))
    if args.json:
        print(json.dumps(result))
    else:
        print(f"{result['controller']} at {result['rate_hz']:.0f} Hz ({result['mode']}, twin): "
              f"{result['cycles']} cycles, {result['deadline_misses']} deadline misses")
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
