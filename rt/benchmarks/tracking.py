"""The thesis's tracking experiments on the twin (fig. 48: PID vs Paden-Panja; fig. 50: a
100 kg payload step at 13 s under Paden-Panja and the adaptive law).

The trajectory is fixed so results compare across changes: each slider follows
q_i(t) = q0 + 0.030 sin(2π·0.25 t + φ_i) + 0.015 sin(2π·0.6 t + ψ_i) m about q0 = 0.20 m
(mid-stroke), φ_i = ψ_i = 0, 2π/3, 4π/3, for 26 s after a ruckig approach from rest at q0.
Controllers use the nominal model (no payload); the twin carries the true payload. Metrics are
mean absolute and RMS joint error (measured q − q_d) over all joints and samples of period 1
(0-13 s) and period 2 (13-26 s), and the peak absolute error over the whole 26 s.
"""
from __future__ import annotations

import numpy as np

from rt.control.experiment import benchmark_reference, run_tracking
from rt.twin.environment import PayloadStep

Q0_M = 0.20
DURATION_S = 26.0
STEP_S = 13.0

#: Thesis figures (Xenomai, 100 Hz, real rig), mm.
THESIS = {
    "pid-vs-paden": {"pid": {"peak_abs_mm": 7.0}, "paden_panja": {"peak_abs_mm": 1.0}},
    "payload-step": {"adaptive": {"period1_mean_abs_mm": 0.681, "period2_mean_abs_mm": 0.687},
                     "paden_panja": {"period1_mean_abs_mm": 0.615,
                                     "period2_mean_abs_mm": 2.809}},
}

EXPERIMENTS = {
    "pid-vs-paden": (("pid", "paden_panja"), None),
    "payload-step": (("paden_panja", "adaptive", "pid"), PayloadStep(mass_kg=100.0, at_s=STEP_S,
                                                                     com_m=(0.0, 0.0, 0.10))),
}


def metrics(t: np.ndarray, error: np.ndarray) -> dict:
    out = {}
    for name, window in (("period1", t < STEP_S), ("period2", t >= STEP_S)):
        e = error[window]
        out[name] = {"mean_abs_m": float(np.abs(e).mean()),
                     "rms_m": float(np.sqrt(np.mean(e ** 2)))}
    out["peak_abs_m"] = float(np.abs(error).max())
    return out


def run_experiment(name: str, seconds: float = DURATION_S, model=None) -> dict:
    """Run one experiment (on ``model``, default the nominal robot); returns the issue's JSON
    shape plus the thesis's figures."""
    controllers, env = EXPERIMENTS[name]
    results = {}
    approach = None
    for ctrl in controllers:
        log = run_tracking(ctrl, seconds, benchmark_reference(Q0_M), env,
                           approach_from=(Q0_M, Q0_M, Q0_M), model=model)
        results[ctrl] = metrics(log.t, log.error)
        approach = log.approach_s
    return {"experiment": name, "twin": True, "rate_hz": 1000.0, "duration_s": seconds,
            "approach_s": approach, "controllers": results, "thesis": THESIS[name]}


def fig50_table(result: dict) -> str:
    """A table shaped like thesis fig. 50, twin beside thesis."""
    lines = ["payload step, 100 kg at 13 s (twin, 1 kHz) vs thesis fig. 50 (rig, 100 Hz)",
             f"{'controller':14s} {'period':8s} {'twin mean|e| mm':>16s} {'twin RMS mm':>12s}"
             f" {'thesis mean|e| mm':>18s}"]
    for ctrl, r in result["controllers"].items():
        for period in ("period1", "period2"):
            thesis = THESIS["payload-step"].get(ctrl, {}).get(f"{period}_mean_abs_mm")
            lines.append(f"{ctrl:14s} {period:8s} {r[period]['mean_abs_m'] * 1e3:16.3f} "
                         f"{r[period]['rms_m'] * 1e3:12.3f} "
                         f"{'' if thesis is None else f'{thesis:18.3f}'}")
    ad = result["controllers"]["adaptive"]["period2"]["mean_abs_m"]
    pp = result["controllers"]["paden_panja"]["period2"]["mean_abs_m"]
    lines.append(f"Paden-Panja / adaptive mean|e| after the step: {pp / ad:.1f} "
                 f"(thesis {2.809 / 0.687:.1f})")
    return "\n".join(lines)
