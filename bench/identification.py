"""Identification on the realistic twin: the friction parameters' bias with each filtering.

One excitation recorded through the product's position loop on the realistic twin (the
in-process path of ``talus identify run``), then identified twice from the same samples:
``states`` (positions and forces filtered at 8 Hz, W from the filtered positions: the first
method) and ``parallel`` (W from positions filtered at 40 Hz, then W's columns and the forces
through the same 8 Hz filter). Prints, per axis, fv and fc: estimate, σ, truth, error in σ;
and the validation trajectory's force error (% of peak) for both. Twin figures.

    .venv/bin/python bench/identification.py [--seconds 40] [--ideal-twin]
"""
from __future__ import annotations

import argparse
import json

from rt.identification.estimate import (
    description_from_physical,
    estimate_base,
    estimate_physical,
    force_prediction_error,
    prepare,
)
from rt.identification.excitation import optimize_excitation
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
    rows, _ = pl.recorder.drain(start)
    rows = rows[:n]
    return rows[:, 1:4].copy(), rows[:, 13:16] * model.description.drive.force_per_volt_n


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=40.0)
    ap.add_argument("--ideal-twin", action="store_true",
                    help="no unmodelled effect (the truth still differs from the model)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    nominal = load_description()
    model = RobotModel.from_description(nominal)
    truth = default_truth()
    imp = RigImperfections.none() if args.ideal_twin else None
    exc = optimize_excitation(model)
    q, tau = raw_record(exc, args.seconds, model, truth, imp)
    from rt.control.experiment import benchmark_reference

    class _Bench:
        q0 = 0.20

        def __call__(self, t, out):
            benchmark_reference(self.q0)(t, out)
    vq, vtau = raw_record(_Bench(), args.seconds, model, truth, imp, seed=1)
    reg = Regressor(model.dyn)
    out = {"twin": "ideal effects" if args.ideal_twin else "realistic", "seconds": args.seconds}
    for filtering in ("states", "parallel"):
        est = estimate_base(reg, prepare(q, tau, RATE_HZ, filtering=filtering))
        tb = truth_base(truth, est.names)
        rows = {}
        for name in [f"fv{i}" for i in range(3)] + [f"fc{i}" for i in range(3)]:
            k = est.names.index(name)
            rows[name] = {"estimate": float(est.theta[k]), "sigma": float(est.sigma[k]),
                          "truth": float(tb[k]),
                          "error_sigmas": float((est.theta[k] - tb[k]) / est.sigma[k])}
        ident = description_from_physical(
            estimate_physical(reg, prepare(q, tau, RATE_HZ, filtering=filtering), nominal),
            nominal, "bench")
        val = prepare(vq, vtau, RATE_HZ, filtering=filtering)
        out[filtering] = {"friction": rows, "residual_rms_n": est.residual_rms_n,
                          "validation_pct_of_peak": {
                              "nominal": force_prediction_error(nominal, val)["rms_pct_of_peak"],
                              "identified": force_prediction_error(ident, val)[
                                  "rms_pct_of_peak"]}}
    if args.json:
        print(json.dumps(out))
        return
    print(f"identification on the {out['twin']} twin, {args.seconds:g} s excitation "
          "(twin figures)")
    print(f"{'filtering':9s} {'param':5s} {'estimate':>9s} {'σ':>7s} {'truth':>9s} "
          f"{'err %':>7s} {'err/σ':>7s}")
    for filtering in ("states", "parallel"):
        for name, r in out[filtering]["friction"].items():
            err = 100.0 * (r["estimate"] - r["truth"]) / r["truth"]
            print(f"{filtering:9s} {name:5s} {r['estimate']:9.2f} {r['sigma']:7.2f} "
                  f"{r['truth']:9.2f} {err:7.2f} {r['error_sigmas']:7.1f}")
        v = out[filtering]["validation_pct_of_peak"]
        print(f"{filtering:9s} residual {out[filtering]['residual_rms_n']:.2f} N; validation "
              f"force error: nominal {v['nominal']:.2f} %, identified {v['identified']:.2f} % "
              "of peak")


if __name__ == "__main__":
    main()
