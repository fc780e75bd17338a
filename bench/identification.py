"""Identification on the realistic twin: every base parameter against the twin's truth, for the
excitation as played (at the speed and acceleration limits) and for the same path played slowly.

One optimised excitation (``optimize_excitation``: the path time-scaled to the limits) is
recorded through the product's position loop on the twin (the in-process path of ``talus
identify run``); the same positions played ``--slow`` times as fast (the first optimiser's
≈ 47 mm/s, 0.08 m/s²) are recorded too. Both are identified with the module's method (parallel
filter, Stribeck samples left out). Prints, per base parameter: truth, estimate, relative error,
σ, error in σ — and each run's validation force error on the benchmark trajectory (% of its
peak) for the nominal, identified and true descriptions. Twin figures.

    .venv/bin/python bench/identification.py [--seconds 40] [--slow 0.33] [--ideal-twin] [--json]
"""
from __future__ import annotations

import argparse
import json
from typing import Any

from rt.identification.estimate import (
    description_from_physical,
    estimate_base,
    estimate_physical,
    force_prediction_error,
    prepare,
)
from rt.identification.excitation import FourierExcitation, optimize_excitation
from rt.identification.workflow import RATE_HZ, truth_base
from rt.model import RobotModel
from rt.model.description import load_description
from rt.model.regressor import Regressor
from rt.position_loop import build_sim_position_loop
from rt.twin.realism import RigImperfections, default_truth
from rt.twin.twin import Twin


def raw_record(excitation, seconds: float, model: RobotModel, truth, imp, seed: int = 0):
    """Encoder positions and commanded forces at 1 kHz (unfiltered)."""
    twin = Twin(truth, seed=seed, imperfections=imp)
    twin.place((excitation.q0,) * 3)
    pl = build_sim_position_loop("paden_panja", None, excitation, seconds, rate_hz=RATE_HZ,
                                 model=model, twin=twin)
    while pl.reference.phase.data[0] != 1.0:
        pl.loop.run(cycles=1)
    _, start = pl.recorder.drain(0)
    n = round(seconds * RATE_HZ)
    pl.loop.run(cycles=n)
    if pl.reference.phase.data[0] == 3.0:
        raise SystemExit("the supervisor stopped the excitation")
    rows, _ = pl.recorder.drain(start)
    rows = rows[:n]
    return rows[:, 1:4].copy(), rows[:, 13:16] * model.description.drive.force_per_volt_n


def slowed(exc: FourierExcitation, factor: float) -> FourierExcitation:
    """The same positions played ``factor`` times as fast (speed × factor, accel × factor²)."""
    return FourierExcitation(exc.a * factor, exc.b * factor, exc.q0, exc.f0_hz * factor)


def identify_run(q, tau, val, reg, nominal, truth) -> dict[str, Any]:
    data = prepare(q, tau, RATE_HZ, amplifier=nominal.drive)
    est = estimate_base(reg, data)
    tb = truth_base(truth, est.names)
    rows = [{"name": n, "truth": float(t), "estimate": float(e), "sigma": float(s),
             "rel_error": float((e - t) / abs(t)) if abs(t) > 1e-9 else None,
             "error_sigmas": float((e - t) / s) if s > 0 else None}
            for n, e, s, t in zip(est.names, est.theta, est.sigma, tb)]
    ident = description_from_physical(estimate_physical(reg, data, nominal), nominal, "bench")
    return {"base": rows, "residual_rms_n": est.residual_rms_n,
            "friction_ripple_n": None if est.ripple_n is None else est.ripple_n.tolist(),
            "validation_pct_of_peak": {
                label: force_prediction_error(d, val)["rms_pct_of_peak"]
                for label, d in (("nominal", nominal), ("identified", ident), ("truth", truth))}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=40.0)
    ap.add_argument("--slow", type=float, default=0.33,
                    help="speed factor of the slow run (0: no slow run)")
    ap.add_argument("--ideal-twin", action="store_true",
                    help="no unmodelled effect (the truth still differs from the model)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    nominal = load_description()
    model = RobotModel.from_description(nominal)
    truth = default_truth()
    imp = RigImperfections.none() if args.ideal_twin else None
    exc = optimize_excitation(model)
    from rt.control.experiment import benchmark_reference

    class _Bench:
        q0 = 0.20

        def __call__(self, t, out):
            benchmark_reference(self.q0)(t, out)
    vq, vtau = raw_record(_Bench(), args.seconds, model, truth, imp, seed=1)
    val = prepare(vq, vtau, RATE_HZ, amplifier=model.description.drive)
    reg = Regressor(model.dyn)
    runs = {"at the limits": exc}
    if args.slow > 0.0:
        runs[f"slow ×{args.slow:g}"] = slowed(exc, args.slow)
    out: dict[str, Any] = {"twin": "ideal effects" if args.ideal_twin else "realistic",
                           "seconds": args.seconds, "runs": {}}
    for label, e in runs.items():
        q, tau = raw_record(e, args.seconds, model, truth, imp)
        out["runs"][label] = {"peaks": e.peaks(), "f0_hz": e.f0_hz,
                              **identify_run(q, tau, val, reg, nominal, truth)}
    if args.json:
        print(json.dumps(out))
        return
    print(f"identification on the {out['twin']} twin, {args.seconds:g} s excitation "
          "(twin figures)")
    for label, r in out["runs"].items():
        e, v, a = r["peaks"]
        print(f"\n{label}: f0 {r['f0_hz']:.3f} Hz, peaks {e * 1e3:.1f} mm, {v * 1e3:.0f} mm/s, "
              f"{a:.2f} m/s²; residual {r['residual_rms_n']:.2f} N")
        print(f"{'base parameter':34s} {'truth':>10s} {'estimate':>10s} {'rel err':>8s} "
              f"{'σ':>9s} {'err/σ':>6s}")
        for b in r["base"]:
            rel = f"{100 * b['rel_error']:7.2f}%" if b["rel_error"] is not None else "     n/a"
            es = f"{b['error_sigmas']:6.1f}" if b["error_sigmas"] is not None else "   n/a"
            print(f"{b['name']:34s} {b['truth']:10.4g} {b['estimate']:10.4g} {rel} "
                  f"{b['sigma']:9.3g} {es}")
        if r["friction_ripple_n"] is not None:
            print("screw friction ripple per axis (nuisance parameters): "
                  + ", ".join(f"{x:.2f} N" for x in r["friction_ripple_n"]))
        v = r["validation_pct_of_peak"]
        print("validation force error (benchmark trajectory), % of peak: "
              + ", ".join(f"{k} {x:.2f}" for k, x in v.items()))


if __name__ == "__main__":
    main()
