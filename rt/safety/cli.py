"""``talus faults matrix``: every fault on the twin, judged (see ``rt.safety.fault_matrix``)."""
from __future__ import annotations

import argparse
import json

from rt.model.robot_option import add_robot_option


def register(commands: argparse._SubParsersAction) -> None:
    p = commands.add_parser("matrix", help="inject every fault on the twin and report the "
                                           "supervisor's reaction")
    p.add_argument("--json", action="store_true")
    p.add_argument("--only", nargs="+", default=None, metavar="FAULT",
                   help="run only these faults ('-' and '_' alike; an unknown name is refused "
                        "with the list)")
    add_robot_option(p)
    p.set_defaults(func=_matrix)


def _selected(only: list[str] | None) -> list[str] | None:
    """The fault names to run, in their declared spelling; InputError names unknown ones."""
    if only is None:
        return None
    from rt.cli_args import canonical_name
    from rt.errors import InputError
    from rt.model import RobotModel
    from rt.safety.fault_matrix import RT_PROCESS_LOSS, scenarios

    known = {canonical_name(n): n
             for n in [sc.name for sc in scenarios(RobotModel.load())] + [RT_PROCESS_LOSS]}
    unknown = [n for n in only if canonical_name(n) not in known]
    if unknown:
        raise InputError(f"unknown fault(s) {', '.join(unknown)}; known: "
                         f"{', '.join(sorted(known.values()))}")
    return [known[canonical_name(n)] for n in only]


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
    result = run_matrix(_selected(args.only), model=model)
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
              f"{f['final_state']}" + _pull_text(f))
    return 0


def _pull_text(f: dict) -> str:
    """A force-hold row's pull on the foot after its stop (none: nothing)."""
    if "pull_end_ms" not in f:
        return ""
    end = f["pull_end_ms"]
    alarm = f.get("alarm_ms")
    return (f"  stop {f['stop_ms']:g} ms ({f['stop_cause']}), pull peak {f['pull_peak_n']:g} N, "
            + ("still pulled at the end" if end is None else f"over {end:g} ms after the stop")
            + ("" if alarm is None else f", pull_in_stop alarm {alarm:g} ms after the stop")
            + f", rise {f.get('rise_mm', 0.0):g} mm")
