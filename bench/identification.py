"""Identification on the realistic twin: every base parameter against the twin's truth, for the
excitation as played (at the speed and acceleration limits) and for the same path played slowly.

One optimised excitation (``optimize_excitation``: the path time-scaled to the limits) is
recorded through the product's position loop on the twin (the in-process path of ``talus
identify run``); the same positions played ``--slow`` times as fast (the first optimiser's
≈ 47 mm/s, 0.08 m/s²) are recorded too. Both are identified with the module's method (parallel
filter, Stribeck samples left out). Prints, per base parameter: truth, estimate, relative error,
σ, error in σ — and each run's validation force error on the benchmark trajectory (% of its
peak) for the nominal, identified and true descriptions. Twin figures.

    .venv/bin/python bench/identification.py [--seconds 40] [--slow 0.33] [--ideal-twin]
        [--offsets both|on|off] [--save-recordings F.npz | --recordings F.npz]
        [--compare-tracking [--controllers pid,pd_g,...]] [--json]

Each run is fitted without and with the amplifiers' offset columns (``--offsets both``): with
them, the leg masses fold into the rotor inertias and the offsets (``estimate.py``, 5.).
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
from rt.model.description import description_from_dict, load_description
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


def identify_run(q, tau, val, reg, nominal, truth, offsets: bool = True,
                 truth_offsets_n=None) -> dict[str, Any]:
    """One fit of a recording (``offsets``: with the amplifiers' offset columns) and its
    validation; every identified quantity against the truth (and the twin's offsets, N)."""
    data = prepare(q, tau, RATE_HZ, amplifier=nominal.drive)
    est = estimate_base(reg, data, offsets=offsets)
    tb = truth_base(truth, est.names, truth_offsets_n)
    rows = [{"name": n, "truth": float(t), "estimate": float(e), "sigma": float(s),
             "rel_error": float((e - t) / abs(t)) if abs(t) > 1e-9 else None,
             "error_sigmas": float((e - t) / s) if s > 0 else None}
            for n, e, s, t in zip(est.names, est.theta, est.sigma, tb)]
    phys = estimate_physical(reg, data, nominal, offsets=offsets)
    ident = description_from_physical(phys, nominal, "bench")
    out: dict[str, Any] = {
        "offsets": offsets, "base": rows, "residual_rms_n": est.residual_rms_n,
        "friction_ripple_n": None if est.ripple_n is None else est.ripple_n.tolist(),
        "physical": {"slider_mass_kg": [nominal.bodies.slider.mass_kg,
                                        ident.bodies.slider.mass_kg,
                                        truth.bodies.slider.mass_kg],
                     "rod_mass_kg": [nominal.bodies.rod.mass_kg, ident.bodies.rod.mass_kg,
                                     truth.bodies.rod.mass_kg],
                     "platform_mass_kg": [nominal.bodies.platform.mass_kg,
                                          ident.bodies.platform.mass_kg,
                                          truth.bodies.platform.mass_kg]},
        "validation_pct_of_peak": {
            label: force_prediction_error(d, val)["rms_pct_of_peak"]
            for label, d in (("nominal", nominal), ("identified", ident), ("truth", truth))},
        "description": ident.model_dump()}
    if est.offset_n is not None and est.offset_sigma_n is not None:
        out["amplifier_offsets_n"] = {
            "estimate": est.offset_n.tolist(), "sigma": est.offset_sigma_n.tolist(),
            "physical_fit": phys[-3:].tolist(),
            "truth": None if truth_offsets_n is None else list(truth_offsets_n)}
    return out


def _tracking(truth, robots: dict[str, Any],
              controllers: tuple[str, ...] = ("paden_panja", "computed_torque")
              ) -> dict[str, Any]:
    """Each controller (default Paden-Panja and computed torque) on the realistic twin (13 s
    of the pid-vs-paden experiment, 1 kHz) with each model: mean |e| and RMS (m)."""
    from rt.benchmarks.tracking import run_one

    out = {}
    for ctrl in controllers:
        for label, robot in robots.items():
            _t, e, _ = run_one("pid-vs-paden", ctrl, 13.0, 1000.0, truth, robot, False)
            out[f"{ctrl}/{label}"] = {"mean_abs_m": float(abs(e).mean()),
                                      "rms_m": float((e ** 2).mean() ** 0.5)}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=40.0)
    ap.add_argument("--slow", type=float, default=0.33,
                    help="speed factor of the slow run (0: no slow run)")
    ap.add_argument("--ideal-twin", action="store_true",
                    help="no unmodelled effect (the truth still differs from the model)")
    ap.add_argument("--offsets", choices=("both", "on", "off"), default="both",
                    help="fit with the amplifiers' offset columns, without, or both")
    ap.add_argument("--recordings", help="an .npz of the raw recordings to reuse (written by "
                    "--save-recordings; keys q, tau, vq, vtau): the at-the-limits run only")
    ap.add_argument("--save-recordings", help="write the raw recordings to this .npz")
    ap.add_argument("--compare-tracking", action="store_true",
                    help="also track with the nominal and each identified model (13 s each; "
                         "a model with offsets also without their compensation)")
    ap.add_argument("--controllers", default="paden_panja,computed_torque",
                    help="the controllers --compare-tracking runs (comma-separated)")
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
    import numpy as np

    saved = np.load(args.recordings) if args.recordings else None
    if saved is not None:
        vq, vtau = saved["vq"], saved["vtau"]
    else:
        vq, vtau = raw_record(_Bench(), args.seconds, model, truth, imp, seed=1)
    val = prepare(vq, vtau, RATE_HZ, amplifier=model.description.drive)
    reg = Regressor(model.dyn)
    truth_offsets = ((imp or RigImperfections()).amplifier_offsets_v()
                     * truth.drive.force_per_volt_n)
    runs = {"at the limits": exc}
    if args.slow > 0.0 and saved is None:
        runs[f"slow ×{args.slow:g}"] = slowed(exc, args.slow)
    fits = {"both": (False, True), "on": (True,), "off": (False,)}[args.offsets]
    out: dict[str, Any] = {"twin": "ideal effects" if args.ideal_twin else "realistic",
                           "seconds": args.seconds, "runs": {}}
    robots: dict[str, Any] = {"nominal": nominal}
    for label, e in runs.items():
        if saved is not None:
            q, tau = saved["q"], saved["tau"]
        else:
            q, tau = raw_record(e, args.seconds, model, truth, imp)
            if args.save_recordings and label == "at the limits":
                np.savez(args.save_recordings, q=q, tau=tau, vq=vq, vtau=vtau)
        for off in fits:
            key = f"{label}, offsets {'on' if off else 'off'}"
            r = identify_run(q, tau, val, reg, nominal, truth, off, truth_offsets)
            robots[key] = description_from_dict(r.pop("description"), key)
            out["runs"][key] = {"peaks": e.peaks(), "f0_hz": e.f0_hz, **r}
    if args.compare_tracking:
        # Each description with offsets is also tracked with its offsets zeroed: the same
        # model without the supervisor's compensation, so the table shows what it brings.
        for key in [k for k, r in robots.items() if any(r.drive.amplifier_offset_v)]:
            data = robots[key].model_dump()
            data["drive"]["amplifier_offset_v"] = [0.0, 0.0, 0.0]
            robots[f"{key}, not compensated"] = description_from_dict(data, key)
        out["tracking"] = _tracking(truth, robots, tuple(args.controllers.split(",")))
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
        if "amplifier_offsets_n" in r:
            o = r["amplifier_offsets_n"]
            print("amplifier offsets (N, given the believed leg masses): "
                  + ", ".join(f"{v:+.2f} ± {s:.2f}" for v, s in zip(o["estimate"], o["sigma"]))
                  + "; physical fit " + ", ".join(f"{v:+.2f}" for v in o["physical_fit"])
                  + ("" if o["truth"] is None
                     else "; truth " + ", ".join(f"{v:+.2f}" for v in o["truth"])))
        for body, (nom, ide, tru) in r["physical"].items():
            print(f"{body}: nominal {nom:.4g}, identified {ide:.4g} ({100 * (ide / tru - 1):+.2f} "
                  f"% of the truth {tru:.4g})")
        v = r["validation_pct_of_peak"]
        print("validation force error (benchmark trajectory), % of peak: "
              + ", ".join(f"{k} {x:.2f}" for k, x in v.items()))
    for k, t in out.get("tracking", {}).items():
        print(f"tracking {k:45s} mean|e| {t['mean_abs_m'] * 1e6:7.2f} µm  RMS "
              f"{t['rms_m'] * 1e6:7.2f} µm")


if __name__ == "__main__":
    main()
