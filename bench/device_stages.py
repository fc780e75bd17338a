"""The device blocks as stages of the fused cycle (issue 16): interleaved before/after pairs.

    .venv/bin/python bench/device_stages.py [--seconds 10] [--pairs 2]
        [--controllers paden_panja,adaptive] [--main /path/to/a/checkout/of/main]

Each variant is ``talus bench loop --json`` in its own process (so each loads its own code):

* ``devices``: this checkout's default, the sensors, the middle chain, the drive and the
  recorder tap in one compiled call (``rt.components.fused``);
* ``middle``: the same code with ``TALUS_FUSED_DEVICES=0`` (the device blocks run their
  ``update``; the middle chain fused: the state before the device stages);
* ``per-block``: ``TALUS_FUSED_CYCLE=0`` (every block's ``update``, the reference);
* ``main``: ``--main``'s checkout (its code on ``PYTHONPATH``), its default.

The variants alternate within each pair, so they meet the same host noise. Prints each run's
cycle without the twin (median / p99 µs) and the device slots' medians, then per controller
the median ratio of each variant's cycle-without-twin median to ``per-block``'s and to
``main``'s. Twin figures; on a loaded machine only the ratios mean anything.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

DEVICES = ("encoders", "force", "stops", "drive", "recorder")
HERE = Path(__file__).resolve().parent.parent


def run_variant(variant: str, controller: str, seconds: float, main: Path | None) -> dict:
    env = dict(os.environ)
    cwd = HERE
    if variant == "middle":
        env["TALUS_FUSED_DEVICES"] = "0"
    elif variant == "per-block":
        env["TALUS_FUSED_CYCLE"] = "0"
    elif variant == "main":
        assert main is not None
        env["PYTHONPATH"] = str(main)
        cwd = main
    out = subprocess.run([sys.executable, "-m", "talus", "bench", "loop", "--seconds",
                          f"{seconds:g}", "--controller", controller, "--json"], cwd=cwd,
                         env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def in_process(controller: str, chunks: int, cycles: int) -> dict[str, list[float]]:
    """Three loops in this process (devices fused, middle only, per block), stepped in
    ``chunks`` alternating stretches of ``cycles`` cycles (fast mode: back to back in
    simulated time), each loop's cycle without the twin (µs) per stretch: the medians of
    the same host minutes."""
    from rt.position_loop import build_sim_position_loop

    loops = {}
    for v in ("devices", "middle", "per-block"):
        os.environ["TALUS_FUSED_DEVICES"] = "0" if v == "middle" else "1"
        pl = build_sim_position_loop(controller, duration_s=3600.0, mode="fast")
        pl.graph.fused = v != "per-block"
        pl.loop.run(cycles=1500)              # the approach: the benchmark's motion after it
        loops[v] = pl
    os.environ.pop("TALUS_FUSED_DEVICES", None)
    out: dict[str, list[float]] = {v: [] for v in loops}
    for _ in range(chunks):
        for v, pl in loops.items():
            g = pl.graph
            g.reset_stats()
            pl.loop.run(cycles=cycles)
            r = g.timing_samples()
            c, tw = r["cycle"], r["components"]["twin"]
            ok = (c >= 0) & (tw >= 0)
            out[v].append(float(np.median(c[ok] - tw[ok])) / 1e3)
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--pairs", type=int, default=2)
    p.add_argument("--controllers", default="paden_panja,adaptive")
    p.add_argument("--main", type=Path, default=None,
                   help="a checkout of main to compare with (its code on PYTHONPATH)")
    p.add_argument("--in-process", type=int, default=0, metavar="CHUNKS",
                   help="instead: the three variants in this process, CHUNKS alternating "
                        "stretches of 2000 cycles each (fast mode)")
    args = p.parse_args(argv)
    if args.in_process:
        for name in args.controllers.split(","):
            res = in_process(name, args.in_process, 2000)
            med = {v: float(np.median(x)) for v, x in res.items()}
            ratios = {v: float(np.median(np.array(res[v]) / np.array(res["per-block"])))
                      for v in res}
            mid = float(np.median(np.array(res["devices"]) / np.array(res["middle"])))
            print(f"{name:12s} cycle w/o twin median of {args.in_process} stretches (µs): "
                  + ", ".join(f"{v} {m:.1f}" for v, m in med.items())
                  + "; / per-block: " + ", ".join(f"{v} {r:.2f}" for v, r in ratios.items())
                  + f"; devices / middle {mid:.2f}", flush=True)
        return 0
    variants = ["devices", "middle", "per-block"] + (["main"] if args.main else [])
    print(f"{args.seconds:g} s per run, realtime, twin figures; cycle without the twin "
          f"median / p99 µs; device slots' medians µs")
    print(f"{'controller':12s} {'variant':10s} {'w/o twin':>15s} "
          + " ".join(f"{d:>9s}" for d in DEVICES) + f" {'middle5':>8s}")
    for name in args.controllers.split(","):
        runs: dict[str, list[dict]] = {v: [] for v in variants}
        for _ in range(args.pairs):
            for v in variants:
                r = run_variant(v, name, args.seconds, args.main)
                runs[v].append(r)
                c = r["cycle_without_twin_us"]
                comp = r["components"]
                mid = sum(comp[s]["median"] for s in ("estimator", "model", "reference",
                                                       "controller", "supervisor"))
                print(f"{name:12s} {v:10s} {c['median']:7.1f} / {c['p99']:5.0f} "
                      + " ".join(f"{comp[d]['median']:9.1f}" for d in DEVICES)
                      + f" {mid:8.1f}", flush=True)
        for base in ("per-block", "main"):
            if base not in runs:
                continue
            parts = []
            for v in variants:
                if v == base:
                    continue
                ratio = np.median([a["cycle_without_twin_us"]["median"]
                                   / b["cycle_without_twin_us"]["median"]
                                   for a, b in zip(runs[v], runs[base])])
                parts.append(f"{v} {ratio:.2f}")
            print(f"{name:12s} cycle w/o twin / {base}: " + ", ".join(parts))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
