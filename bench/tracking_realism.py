"""The thesis's fig. 48/50 experiments at 100 Hz with and without a realism effect, interleaved.

For each experiment and controller, the same run on the realistic twin with the effect under
study switched off (the twin before it was added) and on (the default now), one after the
other, so both see the same machine. Prints mean |e| and RMS per period (and the peak) beside
the thesis's figures, and the ratio twin/thesis. Twin figures.

    .venv/bin/python bench/tracking_realism.py [--effect amplifier_offset_v] [--rate 100]
"""
from __future__ import annotations

import argparse
import json

from rt.benchmarks.tracking import EXPERIMENTS, THESIS, StoppedBySupervisor, metrics, run_one
from rt.twin.realism import RigImperfections


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--effect", default="amplifier_offset_v",
                    help="a RigImperfections field switched off for the 'before' runs")
    ap.add_argument("--rate", type=float, default=100.0)
    ap.add_argument("--experiments", nargs="+", default=["parameter-step", "pid-vs-paden"])
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    on = RigImperfections()
    if args.effect not in RigImperfections.model_fields:
        raise SystemExit(f"unknown effect {args.effect!r}")
    off = on.model_copy(update={args.effect: 0.0})
    results = []
    for exp in args.experiments:
        for ctrl in EXPERIMENTS[exp]:
            row = {"experiment": exp, "controller": ctrl}
            for label, imp in (("off", off), ("on", on)):
                try:
                    t, e, _ = run_one(exp, ctrl, rate_hz=args.rate, imperfections=imp)
                    row[label] = metrics(t, e)
                except StoppedBySupervisor as exc:
                    row[label] = {"stopped_by_supervisor": str(exc)}
            results.append(row)
    if args.json:
        print(json.dumps({"effect": args.effect, "rate_hz": args.rate, "results": results}))
        return
    print(f"{args.effect}: off = {getattr(off, args.effect)}, on = {getattr(on, args.effect)}; "
          f"{args.rate:g} Hz, realistic twin (twin figures, mm)")
    print(f"{'experiment':15s} {'controller':12s} {'metric':9s} {'off':>8s} {'on':>8s} "
          f"{'thesis':>8s} {'on/thesis':>9s}")
    for r in results:
        th = THESIS[r["experiment"]].get(r["controller"], {})
        if any("stopped_by_supervisor" in r[k] for k in ("off", "on")):
            print(f"{r['experiment']:15s} {r['controller']:12s} stopped: "
                  f"{r['on'].get('stopped_by_supervisor', r['off'].get('stopped_by_supervisor'))}")
            continue
        lines = [("peak", lambda m: m["peak_abs_m"], th.get("peak_abs_mm"))]
        if r["experiment"] != "pid-vs-paden":
            for p in ("period1", "period2"):
                lines.append((f"{p[0]}{p[-1]} mean", lambda m, p=p: m[p]["mean_abs_m"],
                              th.get(f"{p}_mean_abs_mm")))
                lines.append((f"{p[0]}{p[-1]} RMS", lambda m, p=p: m[p]["rms_m"],
                              th.get(f"{p}_rms_mm")))
        for label, get, thesis in lines:
            a, b = 1e3 * get(r["off"]), 1e3 * get(r["on"])
            ratio = f"{b / thesis:9.2f}" if thesis else ""
            ts = f"{thesis:8.3f}" if thesis else ""
            print(f"{r['experiment']:15s} {r['controller']:12s} {label:9s} {a:8.3f} {b:8.3f} "
                  f"{ts:>8s} {ratio:>9s}")


if __name__ == "__main__":
    main()
