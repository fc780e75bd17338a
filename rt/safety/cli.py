"""``talus faults matrix``: every fault on the twin, judged (see ``rt.safety.fault_matrix``)."""
from __future__ import annotations

import argparse
import json

from rt.model.robot_option import add_robot_option


def register(commands: argparse._SubParsersAction) -> None:
    p = commands.add_parser("matrix", help="inject every fault on the twin and report the "
                                           "supervisor's reaction")
    p.add_argument("--json", action="store_true")
    p.add_argument("--only", nargs="*", default=None, help="run only these faults")
    add_robot_option(p)
    p.set_defaults(func=_matrix)


def _fmt(v) -> str:
    return "-" if v is None else f"{v:g}"


def _matrix(args) -> int:
    from rt.errors import TalusError
    from rt.model import RobotModel
    from rt.safety.fault_matrix import run_matrix

    try:
        model = RobotModel.load(args.robot)
    except TalusError as exc:
        print(json.dumps({"error": str(exc)}))
        return 2
    result = run_matrix(args.only, model=model)
    if args.json:
        print(json.dumps(result))
        return 0
    print("fault matrix on the twin (1 kHz, simulated time; fault at "
          f"{result['fault_at_s']} s; times in ms)")
    print(f"{'fault':20s} {'det':4s} {'reaction':10s} {'cause':18s} {'latency':>8s} "
          f"{'to 0 V':>7s} {'to rest':>8s} {'ROM°':>6s} {'F%':>6s} {'mm':>6s}  final")
    for f in result["faults"]:
        e = f["excursion"]
        print(f"{f['name']:20s} {'yes' if f['detected'] else 'NO':4s} {f['reaction']:10s} "
              f"{f.get('cause', '-'):18s} {_fmt(f['latency_ms']):>8s} "
              f"{_fmt(f['time_to_zero_output_ms']):>7s} {_fmt(f['time_to_rest_ms']):>8s} "
              f"{_fmt(e['rom_deg']):>6s} {e['force_pct']:6.2f} {e['stroke_mm']:6.2f}  "
              f"{f['final_state']}")
    return 0
