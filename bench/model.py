"""Model timings: median (and p90) µs per call over ≥ 10 000 calls on this machine.

Run:  .venv/bin/python bench/model.py [--calls N]
Targets (issue 2): FK ≤ 30 µs, M+C+G ≤ 40 µs, regressor ≤ 100 µs. These VMs vary ±30 % run to
run (PLATFORM.md): compare figures from one run.
"""
from __future__ import annotations

import argparse
import gc
import json
import time

import numpy as np

from rt.model import RobotModel
from rt.model.regressor import Regressor


def measure(fn, calls: int) -> dict[str, float]:
    for _ in range(200):
        fn()
    times = np.empty(calls)
    clock = time.perf_counter
    for i in range(calls):
        t0 = clock()
        fn()
        times[i] = clock() - t0
    us = times * 1e6
    return {"median_us": float(np.median(us)), "p90_us": float(np.percentile(us, 90))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--calls", type=int, default=10_000)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    robot = RobotModel.load()
    kin, dyn = robot.kin, robot.dyn
    reg = Regressor(dyn)
    rng = np.random.default_rng(1)
    # A 1 kHz-like walk: successive poses one cycle apart, so FK's warm start is realistic.
    poses = [(0.63 + 0.05 * np.sin(t), 0.15 * np.sin(1.3 * t), 0.12 * np.cos(0.7 * t))
             for t in np.linspace(0.0, 10.0, args.calls)]
    qs = [kin.ik(*p).q for p in poses]
    qd = np.array([0.05, -0.03, 0.02])
    qdd = rng.normal(0.0, 1.0, 3)
    it = iter(range(10 ** 9))

    def fk():
        kin.fk(qs[next(it) % len(qs)])

    st = dyn.state(qs[0], qd)
    gc.collect()
    gc.disable()
    results = {
        "ik": measure(lambda: kin.ik(0.63, 0.1, -0.05), args.calls),
        "fk_warm": measure(fk, args.calls),
        "state_fk_plus_maps": measure(lambda: dyn.state(qs[0], qd), args.calls),
        "jacobians": measure(lambda: (st.forward_jacobian(), st.inverse_jacobian()), args.calls),
        "mcg": measure(lambda: dyn.mcg(st), args.calls),
        "state_plus_mcg": measure(lambda: dyn.mcg(dyn.state(qs[0], qd)), args.calls),
        "regressor": measure(lambda: reg(st, qdd), args.calls),
    }
    gc.enable()
    if args.json:
        print(json.dumps(results))
        return
    print(f"talus model timings, {args.calls} calls each (median / p90, µs)")
    targets = {"fk_warm": 30.0, "mcg": 40.0, "regressor": 100.0}
    for name, r in results.items():
        target = f"  target ≤ {targets[name]:.0f}" if name in targets else ""
        print(f"  {name:20s} {r['median_us']:7.1f} / {r['p90_us']:7.1f}{target}")


if __name__ == "__main__":
    main()
