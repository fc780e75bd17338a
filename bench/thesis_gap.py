"""Why Paden-Panja's period-2 error at 100 Hz is 2.8× the thesis's (fig. 50), from statics.

In the parameter-step experiment (thesis 4.1.4) the controller's model carries a 100 kg payload
the robot does not. Paden-Panja (τ = M q̈_d + C q̇_d + G + F − Kp e − Kd ė) then pushes every
axis by the model's error ΔM q̈_d + ΔC q̇_d + ΔG too hard, and its PD settles where Kp e balances
it: the period-2 error is that force over Kp, whatever the twin's imperfections (they move the
period-1 error, which the PD fights in both periods). This prints, along the benchmark
trajectory of period 2:

* the model error per axis and the error it predicts, e = Δτ / Kp, for the gains the 100 Hz
  rule gives (``rt.benchmarks.tracking.gains_for_rate``) — beside the twin's figure;
* the Kp the thesis's 2.809 mm implies for the same Δτ, and the closed loop's natural frequency
  ωn·T per sample it means (the thesis does not state its gains);
* the same prediction with the payload's COM on the platform's origin instead of 0.10 m above
  (how the thesis placed its 100 kg is not stated either).

    .venv/bin/python bench/thesis_gap.py [--rate 100]
"""
from __future__ import annotations

import argparse
import math

import numpy as np

from rt.benchmarks.tracking import PAYLOAD_COM_M, PAYLOAD_KG, Q0_M, STEP_S, THESIS, gains_for_rate
from rt.control.base import Reference
from rt.control.experiment import benchmark_reference_interpreted
from rt.model import RobotModel
from rt.model.dynamics import Payload


def model_error(com_m: tuple[float, float, float], seconds: float = 13.0,
                step_s: float = 0.02) -> np.ndarray:
    """Δτ (n, 3) N: the loaded model's M q̈_d + C q̇_d + G minus the unloaded one's along the
    benchmark trajectory (period 2's 13 s)."""
    plain = RobotModel.load()
    loaded = RobotModel.load()
    loaded.dyn.set_payload(Payload(PAYLOAD_KG, com_m))
    ref = benchmark_reference_interpreted(Q0_M)
    out = []
    s = Reference()
    for t in np.arange(STEP_S, STEP_S + seconds, step_s):
        ref(float(t), s)
        qd, qdd = np.array(s.qd), np.array(s.qdd)
        terms = []
        for m in (plain, loaded):
            st = m.dyn.state(s.q, s.qd)
            mm, cc, gg = m.dyn.mcg(st)
            terms.append(mm @ qdd + cc @ qd + gg)
        out.append(terms[1] - terms[0])
    return np.array(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rate", type=float, default=100.0)
    args = ap.parse_args()
    model = RobotModel.load()
    mass = float(model.dyn.mass_matrix(model.dyn.state((Q0_M,) * 3))[0, 0])
    gains = gains_for_rate("paden_panja", args.rate, mass)
    if gains is None:
        raise SystemExit("the 100 Hz rule applies below 500 Hz")
    kp, kd = gains["kp_n_per_m"], gains["kd_n_s_per_m"]
    period = 1.0 / args.rate
    thesis = THESIS["parameter-step"]["paden_panja"]["period2_mean_abs_mm"] * 1e-3
    print(f"{args.rate:g} Hz, axis mass {mass:.1f} kg: Kp {kp:.0f} N/m, Kd {kd:.0f} N s/m, "
          f"ωn·T {math.sqrt(kp / mass) * period:.3f}, ζ {kd / (2 * math.sqrt(kp * mass)):.2f}")
    for label, com in (("COM 0.10 m above P (the bench's)", PAYLOAD_COM_M),
                       ("COM at P's origin", (0.0, 0.0, 0.0))):
        d = model_error(com)
        e = d / kp
        implied = float(np.abs(d).mean()) / thesis
        print(f"  payload {label}: model error |Δτ| mean {np.abs(d).mean():.0f} N "
              f"(per axis {np.abs(d).mean(axis=0).round(0).tolist()} N); "
              f"predicted p2 mean |e| {1e3 * np.abs(e).mean():.2f} mm, RMS "
              f"{1e3 * math.sqrt(float((e ** 2).mean())):.2f} mm; thesis 2.809 mm implies Kp "
              f"≈ {implied:.0f} N/m = {implied / kp:.2f}× the rule's (ωn·T "
              f"{math.sqrt(implied / mass) * period:.3f})")


if __name__ == "__main__":
    main()
