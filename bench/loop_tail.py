"""Where the loop's p99 comes from: the position loop's steady cycles against a fixed-work
baseline, each in its own process, alternated (issue 16, guard8).

    .venv/bin/python bench/loop_tail.py [--seconds 10] [--pairs 2]
        [--controllers paden_panja,adaptive] [--work-us 20] [--main /path/to/a/checkout]

Variants, one process each (so each loads its own code), alternated within each pair:

* ``loop``: ``build_sim_position_loop`` in realtime mode, one run; the first 1100 cycles
  (the approach) are left out, the rest is the steady program (the approach ran ruckig's
  Python every cycle before approach9; it is compiled now, but the split is kept so that
  the figures compare with the earlier ones: ``bench/approach_cycles.py`` classes them);
* ``main``: the same with ``--main``'s code on ``PYTHONPATH`` (before/after);
* ``baseline``: the engine's ``Loop`` (same hygiene: SCHED_FIFO, mlockall, gc frozen and off)
  over one block whose ``update`` is a compiled arithmetic spin of ``--work-us``: a fixed
  amount of work with no Python, no memory traffic, no allocation. Its p99/median is what
  the platform does to a cycle that cannot vary.

Per run: the cycle without the twin (median / p99 / p99.9 / max, µs); for the cycles above
the p99, the slot that carried most of the excess over its own median (a compiled stage
taking the excess means the host stretched the cycle, not our Python); each slot's
p99/median; over the run, gc collections seen by ``gc.callbacks`` (1 = the collection before
the first cycle), the loop thread's minor/major page faults and involuntary context
switches (``getrusage(RUSAGE_THREAD)``; the minor faults count ``mlockall``'s population at
the start), the host's steal (``/proc/stat``, ticks), and the causes the supervisor latched (a
host stall of tens of ms may trip ``deadline_overruns``: such a run is no steady run).
Twin figures; on a loaded machine only the ratios within one run mean anything.
"""
from __future__ import annotations

import argparse
import gc
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent.parent
APPROACH_CYCLES = 1100          # the approach, left out (module docstring)


def _steal_ticks() -> int:
    with open("/proc/stat") as f:
        return int(f.readline().split()[8])


def _thread_usage() -> np.ndarray:
    r = resource.getrusage(resource.RUSAGE_THREAD)
    return np.array([r.ru_minflt, r.ru_majflt, r.ru_nivcsw])


def _summary(us: np.ndarray) -> dict[str, float]:
    return {"median": round(float(np.median(us)), 1), "p99": round(float(np.percentile(us, 99)), 1),
            "p999": round(float(np.percentile(us, 99.9)), 1), "max": round(float(us.max()), 1)}


def _baseline_loop(work_us: float) -> Any:
    from numba import njit

    from rt.engine import Array, Component, GraphBuilder
    from rt.engine.loop import Loop

    @njit(cache=True)
    def spin(n: int, out: np.ndarray) -> None:
        x = 0.0
        for i in range(n):
            x = x * 0.999999 + i
        out[0] = x

    class Work(Component):
        """Ports: out ``y``: float64[1], the spin's result (keeps it from being elided)."""

        def __init__(self, name: str, n: int) -> None:
            super().__init__(name)
            self.y = self.declare_output("y", Array(1))
            self.n = n

        def update(self, t: float, dt: float) -> int:
            spin(self.n, self.y.data)
            return 0

    buf = np.zeros(1)
    spin(1000, buf)
    n = 1000
    best = float("inf")
    for _ in range(200):
        t0 = time.perf_counter_ns()
        spin(n, buf)
        best = min(best, time.perf_counter_ns() - t0)
    b = GraphBuilder()
    b.add(Work("work", max(1, int(n * work_us * 1e3 / best))))
    return Loop(b.build(), rate_hz=1000.0, mode="realtime")


def measure(kind: str, controller: str, seconds: float, work_us: float) -> dict:
    """One run in this process (``kind`` "loop" or "baseline")."""
    collections = [0]

    def seen(phase: str, info: dict) -> None:
        collections[0] += phase == "start"

    gc.callbacks.append(seen)
    pl = None
    if kind == "loop":
        from rt.position_loop import build_sim_position_loop

        pl = build_sim_position_loop(controller, duration_s=seconds + 1.5, mode="realtime")
        loop, skip = pl.loop, APPROACH_CYCLES
    else:
        loop, skip = _baseline_loop(work_us), 200
    collections[0] = 0                # the set-up's collections are not the loop's
    u0, s0 = _thread_usage(), _steal_ticks()
    loop.run(seconds=seconds + skip * 1e-3)
    u1, s1 = _thread_usage(), _steal_ticks()
    rings = loop.graph.timing_samples()
    cycle = rings["cycle"].astype(float)[skip:]
    slots = {k: v.astype(float)[skip:] for k, v in rings["components"].items()}
    twin = slots.pop("twin", None)
    ok = cycle >= 0
    if twin is not None:
        ok &= twin >= 0
        cycle = cycle - np.where(twin >= 0, twin, 0.0)
    us = cycle[ok] / 1e3
    p99 = float(np.percentile(us, 99))
    med = {k: float(np.median(v[v >= 0])) for k, v in slots.items()}
    carried: dict[str, int] = {}
    for i in np.nonzero(ok & (cycle / 1e3 > p99))[0]:
        excess = {k: v[i] - med[k] for k, v in slots.items() if v[i] >= 0}
        top = max(excess, key=lambda k: excess[k])
        carried[top] = carried.get(top, 0) + 1
    d = u1 - u0
    return {"kind": kind, "controller": controller if kind == "loop" else None,
            "work_us": work_us if kind == "baseline" else None, "cycles": int(ok.sum()),
            "cycle_without_twin_us": _summary(us), "slow_cycles_carried_by": carried,
            "slot_median_us": {k: round(v / 1e3, 2) for k, v in med.items()},
            "slot_p99_over_median": {k: round(float(np.percentile(v[v >= 0], 99)) / med[k], 1)
                                     for k, v in slots.items() if med[k] > 500},
            "gc_collections": collections[0], "minor_faults": int(d[0]),
            "major_faults": int(d[1]), "involuntary_switches": int(d[2]),
            "steal_ticks": s1 - s0, "deadline_misses": int(loop.stats().misses),
            "latched": [] if pl is None else [x["cause"] for x in pl.supervisor.latched()]}


def run_variant(kind: str, controller: str, args: argparse.Namespace) -> dict:
    env = dict(os.environ)
    cwd = HERE
    if kind == "main":
        env["PYTHONPATH"] = str(args.main)
        cwd = args.main
    out = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--one",
                          "loop" if kind == "main" else kind, "--controllers", controller,
                          "--seconds", f"{args.seconds:g}", "--work-us", f"{args.work_us:g}"],
                         cwd=cwd, env=env, capture_output=True, text=True, check=True)
    result = json.loads(out.stdout.strip().splitlines()[-1])
    result["variant"] = kind
    return result


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--pairs", type=int, default=2)
    p.add_argument("--controllers", default="paden_panja,adaptive")
    p.add_argument("--work-us", type=float, default=20.0, help="the baseline's fixed work")
    p.add_argument("--main", type=Path, default=None, help="a checkout to compare with")
    p.add_argument("--one", choices=("loop", "baseline"), help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.one:
        print(json.dumps(measure(args.one, args.controllers, args.seconds, args.work_us)))
        return 0
    for pair in range(args.pairs):
        for controller in args.controllers.split(","):
            for kind in ("main", "loop") if args.main else ("loop",):
                r = run_variant(kind, controller, args)
                load = os.getloadavg()[0]
                print(f"pair {pair + 1} {controller} {kind} (load {load:.1f}): "
                      f"{json.dumps(r)}", flush=True)
        r = run_variant("baseline", "", args)
        print(f"pair {pair + 1} baseline {args.work_us:g} µs (load {os.getloadavg()[0]:.1f}): "
              f"{json.dumps(r)}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
