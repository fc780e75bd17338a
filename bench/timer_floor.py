"""The machine's timing floor: how many deadlines a loop that does *nothing* misses here.

    .venv/bin/python bench/timer_floor.py [--seconds 300] [--chunks 10] [--rate 1000]
        [--cpu-latency-us 0] [--json]

Two loops, alternated in ``--chunks`` stretches (so both meet the same host noise), each waiting the way the product's loop does (sleep until
``spin_us`` before the deadline, then spin on the clock; a miss is a start later than 20 % of
the period, as ``Loop``):

1. ``bench/timer_floor.c`` compiled with ``cc -O2`` into a temporary directory: no Python, no
   work, ``clock_nanosleep`` to an absolute time, SCHED_FIFO 80 and mlockall tried as the
   product's loop does. Its misses are the host's (scheduler, VM
   exits, steal, interrupts): no code of ours can remove them on this machine.
2. The engine's ``Loop`` in realtime mode over ``bench/loop_overhead.py``'s eight no-op
   components, with the same hygiene as the RT process (SCHED_FIFO tried, mlockall, gc off):
   the floor of the Python loop itself, before any block does work.

The PM QoS wake-up bound (``--cpu-latency-us``, default 0 as the RT process) is held for both.
Compare with ``bench/loop_10min.py`` (the position loop on the twin): what it misses beyond
these two floors is the cycle's own cost. Twin-free figures for this machine; not a test.
"""
from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from rt.engine import Loop
from rt.engine.rt_hygiene import release_cpu_latency_bound, try_cpu_latency_bound

sys.path.insert(0, str(Path(__file__).resolve().parent))
from loop_overhead import Nop, make_graph

SOURCE = Path(__file__).with_suffix(".c")
SPIN_US = 150.0                 # Loop's default spin before each deadline
MISS_TOLERANCE = 0.2            # Loop's default: a start later than 20 % of the period


def _percentiles_from_pairs(pairs: list[list[int]]) -> dict[str, float]:
    bins = np.array([b for b, _ in pairs], dtype=float)
    counts = np.array([c for _, c in pairs], dtype=float)
    cum = np.cumsum(counts) / counts.sum()
    pick = {q: float(bins[np.searchsorted(cum, q / 100.0)] + 1) for q in (50, 99, 99.9, 99.99)}
    return {"p50_us": pick[50], "p99_us": pick[99], "p999_us": pick[99.9],
            "p9999_us": pick[99.99]}


def _compile(tmp: str) -> Path:
    cc = shutil.which("cc")
    if cc is None:
        raise SystemExit("timer_floor: no C compiler (cc) on PATH")
    exe = Path(tmp) / "timer_floor"
    subprocess.run([cc, "-O2", "-o", str(exe), str(SOURCE)], check=True)
    return exe


def c_chunk(exe: Path, rate: float, seconds: float) -> dict:
    out = subprocess.run([str(exe), str(rate), str(seconds), str(SPIN_US), str(MISS_TOLERANCE)],
                         check=True, capture_output=True, text=True)
    r = json.loads(out.stdout)
    return {"sched_fifo": bool(r["fifo"]), "mlockall": bool(r["mlockall"]),
            "cycles": r["cycles"], "misses": r["misses"], "max_late_us": r["max_late_ns"] / 1e3,
            "hist": r["hist"]}


def python_chunk(rate: float, seconds: float) -> dict:
    loop = Loop(make_graph(Nop), rate_hz=rate, mode="realtime", spin_us=SPIN_US,
                miss_tolerance=MISS_TOLERANCE)
    loop.run(seconds=seconds)
    s = loop.stats()
    return {"cycles": s.lateness.count, "misses": s.misses, "max_late_us": s.lateness.max_all_us,
            "p50_us": s.lateness.p50_us, "p99_us": s.lateness.p99_us, "rephases": s.rephases}


def interleaved(rate: float, seconds: float, chunks: int) -> dict:
    """C and Python chunks alternated (C first), ``seconds / chunks`` each, so that both loops
    see the same stretches of the host's noise; totals and the misses of every chunk."""
    per = seconds / chunks
    c_runs, py_runs = [], []
    with tempfile.TemporaryDirectory(prefix="talus-floor-") as tmp:
        exe = _compile(tmp)
        for _ in range(chunks):
            c_runs.append(c_chunk(exe, rate, per))
            py_runs.append(python_chunk(rate, per))
    hist: dict[int, int] = {}
    for r in c_runs:
        for b, n in r.pop("hist"):
            hist[b] = hist.get(b, 0) + n
    c_cycles = sum(r["cycles"] for r in c_runs)
    c_misses = sum(r["misses"] for r in c_runs)
    py_cycles = sum(r["cycles"] for r in py_runs)
    py_misses = sum(r["misses"] for r in py_runs)
    return {
        "c": {"sched_fifo": all(r["sched_fifo"] for r in c_runs),
              "mlockall": all(r["mlockall"] for r in c_runs),
              "cycles": c_cycles, "misses": c_misses, "miss_pct": 100.0 * c_misses / c_cycles,
              "max_late_us": max(r["max_late_us"] for r in c_runs),
              "misses_per_chunk": [r["misses"] for r in c_runs],
              **_percentiles_from_pairs(sorted([b, n] for b, n in hist.items()))},
        "python": {"cycles": py_cycles, "misses": py_misses,
                   "miss_pct": 100.0 * py_misses / py_cycles,
                   "max_late_us": max(r["max_late_us"] for r in py_runs),
                   "misses_per_chunk": [r["misses"] for r in py_runs],
                   "p50_us": float(np.median([r["p50_us"] for r in py_runs])),
                   "p99_us": float(np.median([r["p99_us"] for r in py_runs])),
                   "rephases": sum(r["rephases"] for r in py_runs),
                   "note": "p50/p99: median over chunks of each chunk's last 65536 cycles"},
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--seconds", type=float, default=300.0, help="per loop, all chunks (s)")
    ap.add_argument("--chunks", type=int, default=10,
                    help="alternate C and Python this many times (default 10)")
    ap.add_argument("--rate", type=float, default=1000.0, help="Hz")
    ap.add_argument("--cpu-latency-us", type=int, default=0,
                    help="PM QoS wake-up bound held for both loops (-1: none)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    if not (args.seconds > 0 and args.rate > 0 and args.chunks >= 1):
        ap.error("--seconds and --rate must be > 0, --chunks ≥ 1")
    qos = (False, "not asked") if args.cpu_latency_us < 0 else \
        try_cpu_latency_bound(args.cpu_latency_us)
    try:
        result = {"rate_hz": args.rate, "seconds": args.seconds,
                  "cpu_latency_us": args.cpu_latency_us, "pm_qos": qos[1],
                  "chunks": args.chunks,
                  **interleaved(args.rate, args.seconds, args.chunks)}
    finally:
        if qos[0]:
            release_cpu_latency_bound()
    if args.json:
        print(json.dumps(result, indent=2))
        return
    print(f"timing floor at {args.rate:g} Hz, {args.seconds:g} s per loop, PM QoS: {qos[1]}")
    for name in ("c", "python"):
        r = result[name]
        print(f"  {name:6s} misses {r['misses']} of {r['cycles']} ({r['miss_pct']:.3f} %), "
              f"lateness p50 {r['p50_us']:.0f} / p99 {r['p99_us']:.0f} / max "
              f"{r['max_late_us']:.0f} µs; per chunk {r['misses_per_chunk']}")


if __name__ == "__main__":
    main()
