"""The position loop's cycles by kind: approach, steady program, return, hold (issue 16, approach9).

    .venv/bin/python bench/approach_cycles.py [--controller paden_panja] [--seconds 6]
        [--mode fast|realtime] [--duration 2.5] [--json] [--main /path/to/a/checkout]

``build_sim_position_loop`` (the benchmark trajectory, ``--duration`` s of it, after its
approach, then its return and the hold at rest) run for ``--seconds``. Each cycle is classed
by the sequencer's ``phase`` port after it (APPROACH, PLAY, RETURN, REST/STOPPED: the hold) and
by the path the fused segment took: ``fast`` (the steady fast path's one compare, the plan
still valid after the cycle), ``whole`` (the kernel ran the whole segment: fast or general
path), ``general`` (``FusedChain._general`` ran: every check, the first cycle after any Python),
``python`` (the kernel stopped before the end: some block's Python ran this cycle). Per class:
the count and the cycle without the twin (graph's cycle ring minus the twin slot's, µs: median,
p99). With ``--main`` the same in a process on that checkout's code first. Twin figures; on a
loaded machine compare within one run only.

``--force`` (hold9): instead, the force programs' pre-flights (``protocols.session.preflight``:
the library's ``sine_fz``, ``gait_replay``, and ``sine_fz`` with the drives limited to 0.5 V,
which saturates and soft-stops: ``tests/test_preflight_paths.py``'s ``sine_fz_saturating``),
counting the cycles whose sequencer ran its Python (``ProgramReference._update``) by why, read
from the sequencer's state as the cycle begins: ``event`` (a request, an abort, a mode change,
the start-up), ``tare`` (the tare wait at the force program's first sample), ``ramp`` (the force
reference ramping down: RETURN/STOPPED/REST in force mode), ``yield`` (the compliant hold of a
force-control soft stop), ``other`` (an approach's arrival, a sample outside the stroke, an
interpreted read-ahead, the end of a program); with the pre-flight driver's own count of the
cycles it handed back to the loop (``cycles_python``) and the total.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent.parent
KINDS = {0: "approach", 1: "play", 2: "return", 3: "hold", 4: "hold"}


def measure(controller: str, seconds: float, mode: str, duration: float) -> dict[str, Any]:
    from rt.position_loop import build_sim_position_loop

    pl = build_sim_position_loop(controller, duration_s=duration, mode=mode)
    g, seg = pl.graph, pl.graph.segment
    phase = pl.reference.phase.data
    rows: list[tuple[str, bool, bool, bool]] = []   # kind, fast, whole, general
    run, general = seg.run, seg._general
    took_general = [False]

    def w_general(t: float, dt: float, idx: int) -> int:
        took_general[0] = True
        return general(t, dt, idx)

    def w_run(t: float, dt: float, idx: int) -> int:
        planned = seg._plan_ok
        took_general[0] = False
        n = run(t, dt, idx)
        whole = n == len(seg.slots) and seg.pending is None
        rows.append((KINDS[int(phase[0])], planned and not took_general[0], whole,
                     took_general[0]))
        return n

    seg.run, seg._general = w_run, w_general
    cycles = pl.loop.run(seconds=seconds)
    rings = g.timing_samples()
    pl.graph.stop()
    cyc, twin = rings["cycle"], rings["components"]["twin"]
    n = min(len(rows), len(cyc))
    rows, cyc, twin = rows[-n:], cyc[-n:], twin[-n:]
    by: dict[str, dict[str, Any]] = defaultdict(lambda: {"cycles": 0, "fast": 0, "whole": 0,
                                                         "general": 0, "us": []})
    for (kind, fast, whole, gen), c, tw in zip(rows, cyc, twin, strict=True):
        for key in (kind, "all"):
            d = by[key]
            d["cycles"] += 1
            d["fast"] += int(fast)
            d["whole"] += int(whole)
            d["general"] += int(gen)
            if c >= 0 and tw >= 0:
                d["us"].append((c - tw) / 1e3)
    out: dict[str, Any] = {"controller": controller, "mode": mode, "cycles": int(cycles),
                           "latched": [x["cause"] for x in pl.supervisor.latched()]}
    for key, d in by.items():
        us = np.asarray(d.pop("us"))
        d["python"] = d["cycles"] - d["whole"]
        if len(us):
            d["without_twin_us"] = {"median": round(float(np.median(us)), 1),
                                    "p99": round(float(np.percentile(us, 99)), 1)}
        out[key] = d
    return out


def _why(ref: Any) -> str:
    """Why the sequencer's Python runs this cycle (``--force``), from its state on entry."""
    from rt.references import sequencer_kernel as sk

    seq = ref._seq
    if (ref._pending is not None or ref._abort or seq[sk.S_STARTED] == 0.0
            or ref.mode.data[0] != seq[sk.S_MODE]):
        return "event"
    return ref.steady_kind()


def measure_force() -> dict[str, Any]:
    from protocols import session
    from rt.model import RobotModel
    from rt.preflight import driver as driver_mod
    from rt.references.sequencer import ProgramReference
    from rt.safety.limits import RobotLimits

    library = HERE / "protocols" / "library"
    setups = {"sine_fz": session.SessionSetup(library / "sine_fz.yaml"),
              "gait_replay": session.SessionSetup(library / "gait_replay.yaml",
                                                  patient_weight_kg=70.0),
              "sine_fz_saturating": session.SessionSetup(
                  library / "sine_fz.yaml", robot_limits=RobotLimits(max_command_v=0.5))}
    counts: dict[str, int] = defaultdict(int)
    update = ProgramReference._update

    def counted(self: Any, dt: float) -> int:
        counts[_why(self)] += 1
        return update(self, dt)

    kept: dict[str, Any] = {}
    make = driver_mod.PreflightDriver

    def keep(*args: Any, **kwargs: Any) -> Any:
        kept["driver"] = make(*args, **kwargs)
        return kept["driver"]

    ProgramReference._update = counted  # type: ignore[method-assign]
    driver_mod.PreflightDriver = keep  # type: ignore[misc]
    out: dict[str, Any] = {}
    try:
        for name, setup in setups.items():
            counts.clear()
            kept.clear()
            try:
                verdict = "accepted" if session.preflight(setup, RobotModel.load()) else "?"
            except session.ProtocolValidationError as exc:
                verdict = "refused: " + str(exc).splitlines()[0][:60]
            drv = kept.get("driver")
            out[name] = {"verdict": verdict, "sequencer_python": dict(counts),
                         "cycles": None if drv is None
                         else drv.cycles_compiled + drv.cycles_python,
                         "driver_python": None if drv is None else drv.cycles_python}
    finally:
        ProgramReference._update = update  # type: ignore[method-assign]
        driver_mod.PreflightDriver = make  # type: ignore[misc]
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--controller", default="paden_panja")
    ap.add_argument("--seconds", type=float, default=6.0)
    ap.add_argument("--duration", type=float, default=2.5)
    ap.add_argument("--mode", choices=("fast", "realtime"), default="fast")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--main", type=Path, default=None)
    ap.add_argument("--inner", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--force", action="store_true",
                    help="the force programs' pre-flights: the sequencer's Python cycles by why")
    args = ap.parse_args()
    if args.force:
        res_f = measure_force()
        if args.json:
            print(json.dumps(res_f))
            return 0
        for name, d in res_f.items():
            why = "  ".join(f"{k} {v}" for k, v in sorted(d["sequencer_python"].items()))
            print(f"{name:20s} {d['verdict'][:40]:40s} cycles {d['cycles']}  driver's Python "
                  f"{d['driver_python']}  sequencer's Python: {why}")
        return 0
    if args.inner or args.main is None:
        res = measure(args.controller, args.seconds, args.mode, args.duration)
        res["tree"] = os.environ.get("PYTHONPATH") or str(HERE)
        results = [res]
    else:
        results = []
        for tree in (args.main, HERE):
            cmd = [sys.executable, str(tree / "bench" / "approach_cycles.py"), "--inner",
                   "--json", "--controller", args.controller, "--seconds", str(args.seconds),
                   "--duration", str(args.duration), "--mode", args.mode]
            if not (tree / "bench" / "approach_cycles.py").exists():
                cmd[1] = str(Path(__file__).resolve())
            env = dict(os.environ, PYTHONPATH=str(tree))
            done = subprocess.run(cmd, env=env, cwd=tree, capture_output=True, text=True,
                                  check=True)
            results.append(json.loads(done.stdout.strip().splitlines()[-1]))
    if args.json:
        print(json.dumps(results if len(results) > 1 else results[0]))
        return 0
    for res in results:
        print(f"{res['tree']}  {res['controller']}  {res['mode']}  cycles {res['cycles']}"
              f"  latched {res['latched']}")
        for key in ("approach", "play", "return", "hold", "all"):
            d = res.get(key)
            if d is None:
                continue
            us = d.get("without_twin_us", {})
            print(f"  {key:9s} {d['cycles']:6d} cycles  fast {d['fast']:6d}  whole "
                  f"{d['whole']:6d}  general {d['general']:6d}  python {d['python']:6d}"
                  f"  without twin median {us.get('median', float('nan')):6.1f} µs"
                  f"  p99 {us.get('p99', float('nan')):6.1f} µs")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
