"""Engine overhead and real-time lateness of the loop on this machine.

Run:  .venv/bin/python bench/loop_overhead.py [--seconds 10] [--rate 1000] [--cpu N]

1. Fast mode, a graph of 8 components whose ``update`` does nothing: the whole-cycle time the
   graph measures is then the engine's own overhead per cycle (timing of every component,
   status checks, rings), median/p99 µs; plus the loop's per-iteration cost (wall time / cycles,
   which adds the command check and time bookkeeping). The same with 8 components doing one
   small numpy operation each, for scale.
2. Realtime mode at 1 kHz for 10 s: lateness p50/p99/max (µs), deadline misses (start later
   than 20 % of the period), re-phasings, and what real-time hygiene was achieved.

Figures vary ±30 % run to run on these VMs (PLATFORM.md); compare ratios from one run.
Not a pass/fail test.
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np

from rt.engine import Array, Component, GraphBuilder, Loop


class Nop(Component):
    """Ports: in ``u`` (except the first): float64[3]; out ``y``: float64[3]. Does nothing."""

    def __init__(self, name: str, has_input: bool) -> None:
        super().__init__(name)
        if has_input:
            self.u = self.declare_input("u", Array(3))
        self.y = self.declare_output("y", Array(3))

    def update(self, t: float, dt: float) -> int:
        return 0


class AddOne(Nop):
    """Ports: as Nop; ``y = u + 1`` (the first: ``y = t``)."""

    def update(self, t: float, dt: float) -> int:
        if self.inputs:
            np.add(self.u.data, 1.0, out=self.y.data)
        else:
            self.y.data.fill(t)
        return 0


def make_graph(cls: type, n: int = 8):
    b = GraphBuilder()
    for i in range(n):
        b.add(cls(f"c{i}", i > 0))
        if i:
            b.connect(f"c{i - 1}.y", f"c{i}.u")
    return b.build()


def fast(cls: type, cycles: int) -> dict[str, float]:
    g = make_graph(cls)
    loop = Loop(g, mode="fast")
    loop.run(cycles=2000)  # warm-up
    g.reset_stats()
    t0 = time.perf_counter()
    loop.run(cycles=cycles)
    wall = time.perf_counter() - t0
    c = g.stats().cycle
    return {"cycle_p50_us": c.p50_us, "cycle_p99_us": c.p99_us, "cycle_max_us": c.max_us,
            "loop_iteration_mean_us": wall / cycles * 1e6}


def realtime(seconds: float, rate: float, cpu: int | None, hygiene: bool) -> dict:
    g = make_graph(AddOne)
    cpus = None if cpu is None else [cpu]
    if hygiene:
        loop = Loop(g, rate_hz=rate, mode="realtime", cpus=cpus)
    else:
        loop = Loop(g, rate_hz=rate, mode="realtime", cpus=cpus, rt_priority=None,
                    lock_memory=False, switch_interval_s=None)
    loop.run(seconds=seconds)
    s = loop.stats()
    return {"stats": s, "cycles": s.cycles, "lateness_p50_us": s.lateness.p50_us,
            "lateness_p99_us": s.lateness.p99_us, "lateness_max_us": s.lateness.max_all_us,
            "misses": s.misses, "miss_ratio_pct": 100 * s.miss_ratio, "rephases": s.rephases,
            "cycle_p99_us": s.graph.cycle.p99_us}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--cycles", type=int, default=200_000, help="fast-mode cycles")
    ap.add_argument("--seconds", type=float, default=10.0, help="realtime duration (s)")
    ap.add_argument("--rate", type=float, default=1000.0, help="realtime rate (Hz)")
    ap.add_argument("--cpu", type=int, default=None, help="pin the loop thread to this CPU")
    ap.add_argument("--no-hygiene", action="store_true", help="no SCHED_FIFO/mlockall")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()

    nop = fast(Nop, args.cycles)
    add = fast(AddOne, args.cycles)
    rt = realtime(args.seconds, args.rate, args.cpu, not args.no_hygiene)
    if args.json:
        rt.pop("stats")
        print(json.dumps({"fast_nop": nop, "fast_add_one": add, "realtime": rt}, indent=2))
        return
    print(f"fast mode, 8 components, {args.cycles} cycles")
    print(f"  no-op updates  (= engine overhead): cycle p50 {nop['cycle_p50_us']:.2f} µs, "
          f"p99 {nop['cycle_p99_us']:.2f} µs  -> {nop['cycle_p50_us'] / 8:.2f} µs/component; "
          f"loop iteration mean {nop['loop_iteration_mean_us']:.2f} µs")
    print(f"  np.add updates (for scale):         cycle p50 {add['cycle_p50_us']:.2f} µs, "
          f"p99 {add['cycle_p99_us']:.2f} µs; loop iteration mean "
          f"{add['loop_iteration_mean_us']:.2f} µs")
    s = rt["stats"]
    print(f"realtime mode, {args.rate:g} Hz, {args.seconds:g} s, 8 np.add components")
    print(f"  lateness p50 {rt['lateness_p50_us']:.2f} µs, p99 {rt['lateness_p99_us']:.2f} µs, "
          f"max {rt['lateness_max_us']:.1f} µs; misses {rt['misses']}/{rt['cycles']} "
          f"({rt['miss_ratio_pct']:.3f} %, > {s.miss_tolerance_us:.0f} µs late); "
          f"re-phased {rt['rephases']}x")
    print(f"  whole cycle p99 {rt['cycle_p99_us']:.1f} µs, max {s.graph.cycle.max_all_us:.1f} µs")
    print("  hygiene: " + s.hygiene.summary().replace("\n", "\n           "))


if __name__ == "__main__":
    main()
