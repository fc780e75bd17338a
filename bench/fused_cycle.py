"""The fused cycle wired into the graph (issue 16), against the per-block cycle: twin figures.

    .venv/bin/python bench/fused_cycle.py [--seconds 10] [--pairs 1]
                                          [--controllers paden_panja,adaptive,...]
                                          [--mode realtime] [--cpu-latency-us 0]

For each controller, ``talus bench loop``'s measurement (``run_loop_benchmark``) run per block
(``fused=False``: the five middle blocks' ``update`` one by one, the reference) then fused
(``rt.components.fused``: estimator → supervisor in one compiled call, each stage timed by the
CPU's cycle counter into its slot's ring), back to back, ``--pairs`` times. Prints medians
and p99 (µs) of the five middle blocks' sum, of each of them, and of the cycle without the
twin, with the fused / per-block ratio of medians. On a loaded machine only the ratios mean
anything. (ref4's prototype, which fused copies of the buffers outside the graph, was this
file before; its figures are in docs/worklog/2026-11-26/ref4.md.)
"""
from __future__ import annotations

import argparse
import json

import numpy as np

from rt.benchmarks.loop import run_loop_benchmark
from rt.components.fused import CHAIN
from rt.position_loop import build_sim_position_loop

ALL = ("paden_panja", "adaptive", "computed_torque", "computed_torque_ptp", "pd_g", "pd_g0",
       "pid")


def five(result: dict, key: str = "median") -> float:
    return float(sum(result["components"][s][key] for s in CHAIN))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--pairs", type=int, default=1)
    p.add_argument("--controllers", default=",".join(ALL))
    p.add_argument("--mode", choices=("realtime", "fast"), default="realtime")
    p.add_argument("--cpu-latency-us", type=int, default=0,
                   help="PM QoS bound as `talus bench loop` (-1: not requested)")
    p.add_argument("--json", action="store_true", help="also print every run's JSON")
    args = p.parse_args(argv)
    qos = None if args.cpu_latency_us < 0 else args.cpu_latency_us
    # Compile (or load) every kernel before the first timed run.
    build_sim_position_loop("paden_panja", duration_s=1.0).graph.stop()
    print(f"{args.seconds:g} s per run, {args.mode}, twin figures; medians / p99 µs; "
          "ratio = fused / per-block median")
    print(f"{'controller':20s} {'run':10s} {'five':>15s} "
          + " ".join(f"{s[:10]:>10s}" for s in CHAIN) + f" {'w/o twin':>15s} {'misses':>7s}")
    for name in args.controllers.split(","):
        runs: dict[str, list[dict]] = {"per-block": [], "fused": []}
        for _ in range(args.pairs):
            for label, fused in (("per-block", False), ("fused", True)):
                r = run_loop_benchmark(name, args.seconds, mode=args.mode,
                                       cpu_latency_us=qos, fused=fused)
                runs[label].append(r)
                if args.json:
                    print(json.dumps(r))
                c = r["cycle_without_twin_us"]
                print(f"{name:20s} {label:10s} {five(r):7.1f} / {five(r, 'p99'):5.0f} "
                      + " ".join(f"{r['components'][s]['median']:10.1f}" for s in CHAIN)
                      + f" {c['median']:7.1f} / {c['p99']:5.0f} {r['deadline_misses']:7d}",
                      flush=True)
        ratio_five = np.median([five(f) / five(b) for f, b in zip(runs["fused"],
                                                                   runs["per-block"])])
        ratio_cycle = np.median([f["cycle_without_twin_us"]["median"]
                                 / b["cycle_without_twin_us"]["median"]
                                 for f, b in zip(runs["fused"], runs["per-block"])])
        print(f"{name:20s} ratio: five {ratio_five:.2f}, cycle without the twin "
              f"{ratio_cycle:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
