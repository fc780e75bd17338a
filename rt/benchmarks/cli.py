"""``talus bench tracking|loop``: benchmark figures as JSON (``--json``) or text."""
from __future__ import annotations

import argparse
import json


def register(commands: argparse._SubParsersAction) -> None:
    p = commands.add_parser("tracking", help="thesis fig. 48/50 tracking experiments on the twin")
    p.add_argument("--experiment", choices=("pid-vs-paden", "payload-step"), required=True)
    p.add_argument("--seconds", type=float, default=26.0)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_tracking)


def _tracking(args) -> int:
    from rt.benchmarks.tracking import fig50_table, run_experiment

    result = run_experiment(args.experiment, args.seconds)
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
