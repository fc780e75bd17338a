"""Digital-twin speed factor: simulated seconds per wall-clock second at 1 kHz control with
5 kHz physics, through the real device paths (PCL-833 decode, PCI-1720 codes, ATI model).

Run:  .venv/bin/python bench/twin.py [--seconds S] [--json]
Target (issue 3): ≥ 20× real time. "realistic" is the default twin (truth apart from the
model, the rig's imperfections); "ideal" is ``Twin.ideal()`` (the physics before issue 15). A twin figure: measured on the twin, this machine.
Each control period does what a loop does: read encoders, read the ATI, write the DAC; the
command is a PD law on floats so the robot really moves (a sine on each slider).
"""
from __future__ import annotations

import argparse
import gc
import json
import math
import time

import numpy as np

from rt.devices.interfaces import Wrench
from rt.twin.backends import TwinActuators, TwinEncoders, TwinForceTorque
from rt.twin.environment import parse_environment
from rt.twin.serve import holding_volts
from rt.twin.twin import SimClock, Twin


def run(seconds: float, env: str, integrator: str, ideal: bool, rate_hz: float = 1000.0) -> dict:
    clock = SimClock()
    kwargs = {"environment": parse_environment(env), "clock": clock, "integrator": integrator}
    twin = Twin.ideal(**kwargs) if ideal else Twin(**kwargs)
    enc, card, ati = TwinEncoders(twin), TwinActuators(twin, 0), TwinForceTorque(twin)
    ati.start()
    card.enable()
    hold = holding_volts(twin)
    q = np.zeros(3)
    w = Wrench()
    volts = [0.0, 0.0, 0.0]
    q0 = 0.2
    dt = 1.0 / rate_hz
    n = int(seconds * rate_hz)
    gc.collect()
    gc.disable()
    t_wall = time.perf_counter()
    for k in range(n):
        clock.t = (k + 1) * dt
        enc.read_positions_m(q)
        ati.read(w)
        for i in range(3):
            ref = q0 + 0.02 * math.sin(2 * math.pi * 0.5 * clock.t + 2.0944 * i)
            volts[i] = hold[i] + 300.0 * (ref - q[i])
        card.write_volts(volts)
    wall = time.perf_counter() - t_wall
    gc.enable()
    return {"env": env, "integrator": integrator, "twin": "ideal" if ideal else "realistic", "sim_s": seconds, "wall_s": wall,
            "speed_factor": seconds / wall, "us_per_control_period": wall / n * 1e6,
            "range_m": float(np.ptp(twin.plant.q))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    run(0.2, "free", "symplectic_euler", False)          # warm the compiled kernels
    run(0.2, "free", "symplectic_euler", True)
    run(0.2, "free", "rk4", True)
    results = [run(args.seconds, env, integ, ideal) for env, integ, ideal in
               (("free", "symplectic_euler", False), ("plate:0.75", "symplectic_euler", False),
                ("ankle", "symplectic_euler", False), ("free", "symplectic_euler", True),
                ("free", "rk4", True))]
    if args.json:
        print(json.dumps(results))
        return
    print(f"twin speed, 1 kHz control, 5 kHz physics, {args.seconds:.0f} s simulated each "
          "(twin figures, this machine)")
    for r in results:
        print(f"  {r['twin']:9s} {r['env']:12s} {r['integrator']:17s} speed {r['speed_factor']:6.1f}× real time"
              f"   {r['us_per_control_period']:6.1f} µs per control period")


if __name__ == "__main__":
    main()
