"""A profile of one steady cycle of the position loop on the twin (issue 16, guard8).

    .venv/bin/python bench/cycle_profile.py [--controller paden_panja] [--cycles 20000]
        [--main /path/to/a/checkout]

Fast mode (the cycles back to back, hot caches), after the approach: the graph's slot rings
(the fused kernel's stage stamps) and wrappers around ``Graph.step``, ``FusedChain.run``,
``fused_kernel.fused_cycle``, ``Twin.sync`` (the call inside the segment's fast path) and
``Graph._end_cycle``; each wrapper's own cost (an empty wrapper's median) is subtracted. So:
the fused call = the kernel call + the fast path's Python; the cycle without the twin = the
fused call + the graph's own step (``_end_cycle``: the delay latches, the cycle's stamp).
With ``--main`` the same in a process on that checkout's code, then this one. Twin figures;
on a loaded machine compare the two within one run only.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent.parent


def profile(controller: str, cycles: int) -> dict[str, Any]:
    import rt.components.fused as fu
    from rt.position_loop import build_sim_position_loop

    pl = build_sim_position_loop(controller, duration_s=60.0, mode="fast")
    pl.loop.run(cycles=1100)                  # the approach: the steady cycles after it
    g, seg, tw = pl.graph, pl.graph.segment, pl.twin
    pc = time.perf_counter_ns
    ns: dict[str, list[int]] = {k: [] for k in ("step", "run", "kernel", "sync_in_run",
                                                "end_cycle", "empty")}
    inside = [False]
    sync, kernel, run, step, end = tw.sync, fu.fused_cycle, seg.run, g.step, g._end_cycle

    def w_sync(t: float | None = None) -> None:
        t0 = pc()
        sync(t)
        if inside[0]:
            ns["sync_in_run"].append(pc() - t0)

    def w_kernel(addr: int) -> int:
        t0 = pc()
        r = kernel(addr)
        ns["kernel"].append(pc() - t0)
        return r

    def w_run(t: float, dt: float, idx: int) -> int:
        inside[0] = True
        t0 = pc()
        r = run(t, dt, idx)
        ns["run"].append(pc() - t0)
        inside[0] = False
        return r

    def w_step(t: float, dt: float) -> int:
        t0 = pc()
        r = step(t, dt)
        ns["step"].append(pc() - t0)
        return r

    def w_end(idx: int, t0_: int, faults: int) -> int:
        t0 = pc()
        r = end(idx, t0_, faults)
        ns["end_cycle"].append(pc() - t0)
        return r

    for _ in range(20000):
        t0 = pc()
        ns["empty"].append(pc() - t0)
    tw.sync, fu.fused_cycle, seg.run, g.step, g._end_cycle = (w_sync, w_kernel, w_run, w_step,
                                                              w_end)
    pl.loop.run(cycles=cycles)
    rings = g.timing_samples()
    slots = {s: float(np.median(v[-cycles:])) / 1e3 for s, v in rings["components"].items()}
    without = float(np.median(rings["cycle"][-cycles:] - rings["components"]["twin"][-cycles:]))
    empty = float(np.median(ns.pop("empty"))) / 1e3
    calls = {k: round(float(np.median(v)) / 1e3 - empty, 2) for k, v in ns.items() if v}
    calls["fast_path_python"] = round(calls["run"] - calls["kernel"], 2)
    return {"controller": controller, "fast_path_in_force": bool(seg._plan_ok),
            "wrapper_us": round(empty, 3), "calls_us": calls,
            "slots_us": {s: round(v, 2) for s, v in slots.items()},
            "cycle_without_twin_us": round(without / 1e3, 2)}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--controller", default="paden_panja")
    p.add_argument("--cycles", type=int, default=20000)
    p.add_argument("--main", type=Path, default=None, help="a checkout to profile first")
    p.add_argument("--here", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.here or args.main is None:
        print(json.dumps(profile(args.controller, args.cycles)))
        return 0
    for label, root in (("main", args.main), ("this", HERE)):
        env = dict(os.environ, PYTHONPATH=str(root))
        out = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--here",
                              "--controller", args.controller, "--cycles", str(args.cycles)],
                             cwd=root, env=env, capture_output=True, text=True, check=True)
        print(f"{label}: {out.stdout.strip().splitlines()[-1]}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
