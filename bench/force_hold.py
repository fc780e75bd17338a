"""A force hold on the calibration plate and a 20 N step from it (issue 15): is the hold
friction-limited?

Run:  .venv/bin/python bench/force_hold.py [--truth nominal|perturbed|both]
      [--law shipped|uncompensated|both] [--json]

The robot twin presses the twin plate (2e6 N/m through the tool tip, 0.5 mm gap at the start)
under the product's force control (``rt.position_loop.build_protocol_loop``, fast mode:
simulated time, deterministic): 0 → 600 N in 0.5 s, held 2 s, +20 N for 1 s, back to 600 N for
1 s, unloaded in 0.5 s. Printed per twin truth and law (twin figures):

* hold: the standard deviation and peak-to-peak of the measured force over the last 1 s of
  the 600 N hold (the ATI's own z noise is 0.25 N);
* step +20 / −20: the time after which the measured force stays within ±2 N of the new
  reference for the rest of a 0.5 s window (0.5 s: never within);
* the largest slider command (N).

``--truth nominal``: the twin's friction is the believed one (the calibration twin's); the
default ``perturbed``: the default realistic truth (per-axis Coulomb and static friction
6-21 % above the believed). ``--law uncompensated``: the shipped law with
``friction_compensation = 0`` (the law before the compensation).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from typing import Any

# bench/calibration.py is named like the package imported below: run as a script, this folder
# comes first on sys.path and would shadow it.
_HERE = os.path.dirname(os.path.abspath(__file__))
sys.path = [p for p in sys.path if os.path.abspath(p or os.curdir) != _HERE]

import numpy as np

from calibration.push import (
    ForceTableGenerator,
)
from calibration.twin_runner import plate_above_tool_tip
from rt.components.protocol_blocks import HybridController
from rt.model import RobotModel
from rt.position_loop import build_protocol_loop, sim_devices
from rt.safety.events import Reaction
from rt.safety.limits import PatientLimits, RobotLimits
from rt.twin.realism import default_truth
from rt.twin.twin import SimClock, Twin

DT = 1e-3
POSE = (0.633, 0.0, 0.0)
HOLD_N, STEP_N = 600.0, 20.0
WINDOW = 500


def run(truth: str, law: str, model: RobotModel) -> dict[str, Any]:
    q0 = np.array(model.kin.ik(*POSE).q)
    env = plate_above_tool_tip(model, POSE[0])
    clock = SimClock()
    twin = Twin(model.description if truth == "nominal" else default_truth(), env, seed=5,
                clock=clock)
    twin.place(q0)
    gains = {"friction_compensation": 0.0} if law == "uncompensated" else None
    pl = build_protocol_loop(sim_devices(twin, clock), None, model, 1.0 / DT, "fast",
                             patient_limits=PatientLimits(
                                 max_force_n=RobotLimits().max_platform_force_n),
                             force_gains=gains)
    profile = np.concatenate([np.linspace(0.0, HOLD_N, 500), np.full(2000, HOLD_N),
                              np.full(1000, HOLD_N + STEP_N), np.full(1000, HOLD_N),
                              np.linspace(HOLD_N, 0.0, 500)])
    gen = ForceTableGenerator("hold", profile, POSE, DT, model.kin)
    report = gen.validate()              # (also prepares the program's table)
    if not report.ok:
        raise RuntimeError("; ".join(report.violations))
    ctl = pl.graph.component("controller")
    assert isinstance(ctl, HybridController)
    ref = pl.reference
    f, fd, tau = [], [], []
    try:
        ref.request(gen)
        epoch = ref.epoch
        for _ in range(12000):
            pl.loop.run(seconds=DT)
            if pl.supervisor.reaction >= Reaction.SOFT_STOP:
                raise RuntimeError(f"stopped: {pl.events.snapshot()[-3:]}")
            if ref.ctrl_mode.data[0] > 0.5:
                f.append(-float(pl.graph.output("force.wrench")[2]))
                fd.append(ctl.law_force_ref_n)
                tau.append(float(np.max(np.abs(pl.graph.output("controller.tau")))))
            if ref.epoch > epoch and not ref.busy:
                break
    finally:
        pl.graph.stop()
    fa, fda = np.array(f), np.array(fd)
    up = int(np.argmax(fda >= HOLD_N + STEP_N - 1.0))
    down = up + int(np.argmax(fda[up:] <= HOLD_N + 1.0))

    def settle(k: int, target: float) -> float:
        out = np.flatnonzero(np.abs(fa[k:k + WINDOW] - target) > 2.0)
        return float((out[-1] + 1) * DT) if len(out) else 0.0

    hold = fa[up - 1000:up]
    return {"truth": truth, "law": law, "hold_std_n": float(hold.std()),
            "hold_p2p_n": float(np.ptp(hold)), "step_up_s": settle(up, HOLD_N + STEP_N),
            "step_down_s": settle(down, HOLD_N), "max_command_n": float(max(tau))}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--truth", choices=("nominal", "perturbed", "both"), default="both")
    ap.add_argument("--law", choices=("shipped", "uncompensated", "both"), default="both")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    truths = ("nominal", "perturbed") if args.truth == "both" else (args.truth,)
    laws = ("uncompensated", "shipped") if args.law == "both" else (args.law,)
    model = RobotModel.load()
    rows = [run(t, law, model) for t in truths for law in laws]
    if args.json:
        print(json.dumps({"twin": True, "rows": rows}))
        return 0
    print("600 N hold on the twin plate, ±20 N steps (twin figures, simulated time)")
    print(f"{'truth':10s} {'law':14s} {'hold std':>8s} {'p2p':>6s} {'+20 N':>7s} {'-20 N':>7s} "
          f"{'max cmd':>8s}")
    for r in rows:
        print(f"{r['truth']:10s} {r['law']:14s} {r['hold_std_n']:7.3f}N {r['hold_p2p_n']:5.2f}N "
              f"{r['step_up_s']:6.3f}s {r['step_down_s']:6.3f}s {r['max_command_n']:7.0f}N")
    return 0


if __name__ == "__main__":
    sys.exit(main())
