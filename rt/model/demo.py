"""A readable tour of the robot model (the first ``make demo``)."""
from __future__ import annotations

import math
import time
from typing import TextIO

import numpy as np

from rt.model import RobotModel
from rt.model.dynamics import Payload
from rt.model.workspace import conditioning, heave_range, max_tilt


def run_demo(model: RobotModel, out: TextIO) -> None:
    kin, dyn = model.kin, model.dyn
    d = model.description
    w = out.write
    w(f"talus robot model: {d.name} (digital-twin nominal parameters)\n\n")
    w("Workspace\n")
    z_lo, z_hi = heave_range(kin)
    mid = 0.5 * (z_lo + z_hi)
    w(f"  heave with the platform level: {z_lo:.3f} .. {z_hi:.3f} m (home z = {mid:.3f} m)\n")
    for z in (z_lo + 0.05, mid, z_hi - 0.05):
        roll = max_tilt(kin, z, "roll")
        pitch = max_tilt(kin, z, "pitch")
        w(f"  at z = {z:.3f} m: max |roll| {math.degrees(roll):5.1f} deg, "
          f"max |pitch| {math.degrees(pitch):5.1f} deg\n")
    w("\nInverse then forward kinematics (parasitic x, y, yaw follow from the constraints)\n")
    for z, roll_deg, pitch_deg in ((mid, 0.0, 0.0), (mid, 10.0, 0.0), (mid, 0.0, -10.0),
                                   (mid + 0.05, 12.0, 8.0)):
        cfg = kin.ik(z, math.radians(roll_deg), math.radians(pitch_deg))
        back = kin.fk(cfg.q)
        cond = conditioning(dyn, cfg)
        w(f"  z {z:.3f} roll {roll_deg:5.1f} pitch {pitch_deg:5.1f} -> q "
          f"[{cfg.q[0]:.4f} {cfg.q[1]:.4f} {cfg.q[2]:.4f}] m, x {cfg.x * 1e3:+.2f} mm "
          f"y {cfg.y * 1e3:+.2f} mm yaw {math.degrees(cfg.yaw):+.3f} deg; FK error "
          f"{abs(back.z - z) * 1e9:.2g} nm in {back.iterations} Newton steps; "
          f"conditioning {cond['inverse']:.2f}\n")
    w("\nDynamics in actuator space at home (Pinocchio tree projected on the sliders)\n")
    home = kin.ik(mid, 0.0, 0.0)
    st = dyn.state(home.q, (0.05, -0.02, 0.03))
    m, _c, g = dyn.mcg(st)
    w(f"  M (kg):\n{_indent(m)}\n  G (N): {np.array2string(g, precision=2)}\n")
    w(f"  reflected motor inertia {d.drive.reflected_inertia_kg:.1f} kg per axis; "
      f"{d.drive.force_per_volt_n:.0f} N per command volt, ±{d.drive.command_limit_v} V "
      f"-> ±{d.drive.force_per_volt_n * d.drive.command_limit_v:.0f} N\n")
    st = dyn.state(home.q)
    g0 = dyn.gravity(st)
    dyn.set_payload(Payload(100.0))
    g100 = dyn.gravity(dyn.state(home.q))
    dyn.set_payload(None)
    w(f"  a 100 kg payload at the platform centre adds {np.array2string(g100 - g0, precision=1)}"
      f" N (hand statics: m g / 3 = {100 * d.gravity_m_s2 / 3:.1f} N per slider)\n")
    w("\nTiming (median of 2000 calls, this machine)\n")
    w(f"  FK {_median_us(lambda: kin.fk(home.q)):.1f} µs, "
      f"M+C+G {_median_us(lambda: dyn.mcg(st)):.1f} µs\n")


def _indent(m: np.ndarray) -> str:
    return "\n".join("    " + np.array2string(row, precision=3) for row in m)


def _median_us(fn, n: int = 2000) -> float:
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times) * 1e6)
