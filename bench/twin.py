"""Digital-twin speed factor: simulated seconds per wall-clock second at 1 kHz control with
5 kHz physics, interpreted reference (``Twin(compiled=False)``) against the compiled twin
(issue 16), and the pre-flight time of a 60 s protocol with the split between the twin and the
loop.

Run:  .venv/bin/python bench/twin.py [--seconds S] [--repeats N] [--no-preflight] [--json]
      .venv/bin/python bench/twin.py --fused-ab [--seconds S] [--repeats N]
Target (issue 16): ≥ 60× real time; a 60 s protocol's pre-flight ≤ 1.5 s. Twin figures:
measured on the twin, this machine.

Two figures per configuration, each the median of ``--repeats`` runs:

* ``twin``: the twin alone, as the pre-flight's first block (``TwinStep``) pays it: one
  ``sync`` per 1 ms control period, the DAC codes set by a PD law on the true positions (a sine
  on each slider) so the robot really moves.
* ``devices``: the same through the real device paths, as ``bench/twin.py`` measured before
  issue 16: the PCL-833 driver reads the emulated card, the PCI-1720 driver writes codes, the
  ATI is read (the drivers' own cost is the difference).

Both are given in wall-clock time and in this thread's CPU time (``time.thread_time``): on a
machine shared with other jobs the CPU figure is the one that does not depend on the load.
"""
from __future__ import annotations

import argparse
import functools
import gc
import json
import math
import statistics
import time
from pathlib import Path

import numpy as np

from rt.devices.interfaces import Wrench
from rt.drivers.pci1720 import volts_to_code
from rt.twin.backends import TwinActuators, TwinEncoders, TwinForceTorque
from rt.twin.environment import parse_environment
from rt.twin.serve import holding_volts
from rt.twin.twin import SimClock, Twin

LIBRARY = Path(__file__).resolve().parent.parent / "protocols" / "library"


def _make(env: str, integrator: str, ideal: bool, compiled: bool, clock: SimClock) -> Twin:
    kwargs = {"environment": parse_environment(env), "clock": clock, "integrator": integrator,
              "compiled": compiled}
    return Twin.ideal(**kwargs) if ideal else Twin(**kwargs)


def run(seconds: float, env: str, integrator: str, ideal: bool, compiled: bool = True,
        devices: bool = False, rate_hz: float = 1000.0, fused: bool = True) -> dict:
    clock = SimClock()
    twin = _make(env, integrator, ideal, compiled, clock)
    twin.fused_period = fused
    hold = holding_volts(twin)
    q = np.zeros(3)
    w = Wrench()
    volts = [0.0, 0.0, 0.0]
    q0 = 0.2
    dt = 1.0 / rate_hz
    n = int(seconds * rate_hz)
    if devices:
        enc, card, ati = TwinEncoders(twin), TwinActuators(twin, 0), TwinForceTorque(twin)
        ati.start()
        card.enable()
    else:
        twin.set_card_enabled(0, True)
        codes = twin.dac_libs[0].codes3           # the double's code array
        truth = twin.plant.q
    gc.collect()
    gc.disable()
    c0 = time.thread_time()
    t_wall = time.perf_counter()
    for k in range(n):
        clock.t = (k + 1) * dt
        if devices:
            enc.read_positions_m(q)
            ati.read(w)
        else:
            twin.sync(clock.t)
            q = truth
        for i in range(3):
            ref = q0 + 0.02 * math.sin(2 * math.pi * 0.5 * clock.t + 2.0944 * i)
            volts[i] = hold[i] + 300.0 * (ref - q[i])
        if devices:
            card.write_volts(volts)
        else:
            for i in range(3):
                codes[i] = volts_to_code(max(-10.0, min(10.0, volts[i])))
    wall = time.perf_counter() - t_wall
    cpu = time.thread_time() - c0
    gc.enable()
    return {"env": env, "integrator": integrator, "twin": "ideal" if ideal else "realistic",
            "compiled": compiled, "path": "devices" if devices else "twin", "sim_s": seconds,
            "wall_s": wall, "cpu_s": cpu, "speed_factor": seconds / wall,
            "speed_factor_cpu": seconds / cpu, "us_per_control_period": wall / n * 1e6,
            "range_m": float(np.ptp(twin.plant.q))}


def _median_runs(repeats: int, **kwargs) -> dict:
    runs = [run(**kwargs) for _ in range(repeats)]
    out = dict(runs[0])
    for key in ("wall_s", "cpu_s", "speed_factor", "speed_factor_cpu", "us_per_control_period"):
        out[key] = statistics.median(r[key] for r in runs)
    out["speed_factor_p10"] = sorted(r["speed_factor"] for r in runs)[len(runs) // 10]
    out["repeats"] = repeats
    return out


def preflight_time(protocol: str, compiled: bool) -> dict:
    """A library protocol's pre-flight: wall and CPU time, and the twin's share of the CPU
    (its block, ``TwinStep.update``, timed; the rest is the loop: controllers, estimator,
    reference, supervisor, device drivers, session tap). One ``thread_time`` read costs
    ≈ 0.7 µs on this VM: the twin's block alone is timed (before twin7 every ``Twin.sync``,
    four a cycle, was: ≈ 6 µs a cycle of timing counted as the twin's)."""
    from protocols import session
    from rt.components.twin_step import TwinStep
    from rt.model import RobotModel

    spent = [0.0]
    step = TwinStep.update

    def timed_step(self, t, dt):
        c = time.thread_time()
        try:
            return step(self, t, dt)
        finally:
            spent[0] += time.thread_time() - c

    make = session.Twin
    session.Twin = functools.partial(Twin, compiled=compiled)  # type: ignore[misc]
    TwinStep.update = timed_step                               # type: ignore[method-assign]
    try:
        model = RobotModel.load()
        setup = session.SessionSetup(protocol_path=LIBRARY / protocol)
        c0 = time.thread_time()
        t0 = time.perf_counter()
        result = session.preflight(setup, model)
        wall = time.perf_counter() - t0
        cpu = time.thread_time() - c0
    finally:
        session.Twin = make                                    # type: ignore[misc]
        TwinStep.update = step                                 # type: ignore[method-assign]
    return {"protocol": protocol, "compiled": compiled,
            "duration_s": result["predicted"]["duration_s"], "wall_s": wall, "cpu_s": cpu,
            "twin_cpu_s": spent[0], "loop_cpu_s": cpu - spent[0]}


def compile_cost() -> float:
    """Seconds to load or compile the twin's kernels in a fresh process (numba's on-disk cache
    makes the second process pay the load only)."""
    import subprocess
    import sys
    code = ("import time; t = time.perf_counter(); from rt.twin.twin import Twin; "
            "tw = Twin(); tw.set_card_enabled(0, True); tw.sync(0.002); "
            "print(time.perf_counter() - t)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    return float(out.stdout.strip().splitlines()[-1])


def fused_ab(seconds: float, repeats: int, as_json: bool) -> None:
    """The compiled twin's period, general path (``plant.advance`` then the sensors in Python)
    against the fused one (``kernels.period``), interleaved run by run; CPU µs per
    period, medians."""
    rows = []
    for env, integ, ideal in CONFIGS:
        for fused in (False, True):
            run(0.2, env, integ, ideal, fused=fused)               # warm both paths
        cpu: dict[bool, list[float]] = {False: [], True: []}
        for _ in range(repeats):
            for fused in (False, True):
                r = run(seconds, env, integ, ideal, fused=fused)
                cpu[fused].append(r["cpu_s"] / (seconds * 1000.0) * 1e6)
        old, new = statistics.median(cpu[False]), statistics.median(cpu[True])
        rows.append({"env": env, "integrator": integ, "twin": "ideal" if ideal else "realistic",
                     "general_us": old, "fused_us": new, "ratio": new / old,
                     "speed_factor_cpu_fused": 1000.0 / new})
    if as_json:
        print(json.dumps(rows))
        return
    print(f"compiled twin, CPU µs per 1 ms period, median of {repeats} interleaved runs of "
          f"{seconds:g} s (twin figures, this machine)")
    for r in rows:
        print(f"  {r['twin']:9s} {r['env']:11s} {r['integrator']:16s} general "
              f"{r['general_us']:6.1f}  fused {r['fused_us']:6.1f}  ratio {r['ratio']:.2f}  "
              f"→ {r['speed_factor_cpu_fused']:.0f}× real time (CPU)")


CONFIGS = (("free", "symplectic_euler", False), ("plate:0.75", "symplectic_euler", False),
           ("ankle", "symplectic_euler", False), ("free", "symplectic_euler", True),
           ("free", "rk4", True))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--protocol", default="active_assist.yaml",
                        help="library protocol whose pre-flight is timed (60 s by default)")
    parser.add_argument("--no-preflight", action="store_true")
    parser.add_argument("--fused-ab", action="store_true",
                        help="only the compiled twin's fused period (one call with its sensor "
                             "readings, the default) against its general path, interleaved")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    if args.fused_ab:
        fused_ab(args.seconds, args.repeats, args.json)
        return
    first_call = compile_cost()
    for compiled in (False, True):                    # warm the compiled kernels
        run(0.2, "free", "symplectic_euler", False, compiled)
        run(0.2, "free", "symplectic_euler", True, compiled)
        run(0.2, "free", "rk4", True, compiled)
    results = []
    for env, integ, ideal in CONFIGS:
        for devices in (False, True):
            for compiled in (False, True):
                results.append(_median_runs(args.repeats, seconds=args.seconds, env=env,
                                            integrator=integ, ideal=ideal, compiled=compiled,
                                            devices=devices))
    pre = []
    if not args.no_preflight:
        preflight_time("position_playback.yaml", True)     # loads the loop's kernels
        pre = [preflight_time(args.protocol, c) for c in (False, True)]
    if args.json:
        print(json.dumps({"runs": results, "preflight": pre, "first_call_s": first_call}))
        return
    print(f"twin speed, 1 kHz control, 5 kHz physics, {args.seconds:g} s simulated, median of "
          f"{args.repeats} runs (twin figures, this machine); × real time in wall-clock / "
          "CPU time")
    print(f"  {'twin':9s} {'env':11s} {'integrator':16s} {'path':7s} "
          f"{'interpreted':>20s}   {'compiled':>20s}   µs/period (compiled, wall)")
    for k in range(0, len(results), 2):
        old, new = results[k], results[k + 1]
        print(f"  {old['twin']:9s} {old['env']:11s} {old['integrator']:16s} {old['path']:7s} "
              f"{old['speed_factor']:7.1f}× / {old['speed_factor_cpu']:6.1f}× CPU   "
              f"{new['speed_factor']:7.1f}× / {new['speed_factor_cpu']:6.1f}× CPU   "
              f"{new['us_per_control_period']:6.1f}")
    print(f"first use in a fresh process (numba cache load, or compile when the cache is "
          f"cold): {first_call:.2f} s")
    for p in pre:
        label = "compiled" if p["compiled"] else "interpreted"
        print(f"pre-flight of {p['protocol']} ({p['duration_s']:g} s protocol), {label} twin: "
              f"{p['wall_s']:.2f} s wall, {p['cpu_s']:.2f} s CPU — twin {p['twin_cpu_s']:.2f} s "
              f"({p['twin_cpu_s'] / p['cpu_s'] * 100:.0f} %), loop {p['loop_cpu_s']:.2f} s "
              f"({p['loop_cpu_s'] / p['cpu_s'] * 100:.0f} %)")


if __name__ == "__main__":
    main()
