"""The twin's pre-flight path is bit for bit the golden run (issue 16's speed work must not
move a single bit of any pre-flight figure unknowingly: a change of the floats writes a new
golden, with its reason and its accuracy, below).

A closed loop on the realistic twin (default truth and imperfections: amplifier offset and
delay, current loop, compliant screw with backlash, friction with its ripple and heating,
brakes, encoder latency, the ATI's tool weight, filter, noise and drift) through the device
backends the pre-flight loop uses: the PCL-833 driver reading the emulated card, the PCI-1720
driver writing codes to the emulated DAC, the ATI sampled as the force reader reads it. The
drives are switched off for 60 ms (the brakes engage) and back on. Every 25 ms the encoder
counts, the decoded positions, the ATI sample and the plant's whole packed state are compared
with the golden file's, as float hex: equality, not a tolerance.

``tests/data/twin_golden_2026-11-26f.json`` was written by this file's ``__main__``
(``python tests/test_twin_golden.py OUT``) when the substep's mass and bias took fewer
operations for the same dynamics (issue 16, branch preflight9: the rods' rotation as one
scalar inertia, Ṡ q̇ as H(q̇, q̇) evaluated once, the yaw's sine and cosine from R): 320 of its
7776 values moved, by at most 1.2e-15 relative (round-off), and the error against ten times
the substeps is unchanged (``bench/twin_accuracy.py``: x_m 34.43 µm, q̇ 1.453 mm/s, as
before). The golden before it (``…-26b``, branch ident5-exact-amp) pinned the twin once it
realised its truth's amplifier exactly (the mean current over each substep and the fractional
delay); the first, from commit 43b157e, the older discretization. The replay tests of
``tests/test_twin_compiled.py`` compare the twin's paths with each other; this one pins the
substep kernels they share. A different libm (``sin``, ``exp``) would show here first.
"""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from rt.devices.interfaces import FT_READ_SIZE
from rt.twin.backends import TwinActuators, TwinEncoders, TwinForceTorque
from rt.twin.environment import parse_environment
from rt.twin.serve import holding_volts
from rt.twin.twin import SimClock, Twin

GOLDEN = Path(__file__).parent / "data" / "twin_golden_2026-11-26f.json"
ENVS = ("free", "plate:0.75", "ankle")
DT = 0.001
SECONDS = 0.6
EVERY = 25


def trajectory(env: str) -> list[list[str]]:
    """Rows of float hex every ``EVERY`` periods: t, counts, positions, ATI read, state S."""
    clock = SimClock()
    twin = Twin(environment=parse_environment(env), seed=5, clock=clock)
    enc, card, ft = TwinEncoders(twin), TwinActuators(twin, 0), TwinForceTorque(twin)
    ft.start()
    card.enable()
    hold = holding_volts(twin)
    q = np.zeros(3)
    q0 = twin.plant.q.copy()
    ati = np.zeros(FT_READ_SIZE)
    volts = np.zeros(3)
    rows = []
    for k in range(round(SECONDS / DT)):
        t = (k + 1) * DT
        clock.t = t
        twin.sync(t)
        enc.read_positions_m(q)
        ft.read_array(ati)
        on = not 0.30 <= t < 0.36
        if on and not card.enabled:
            card.enable()
        elif not on and card.enabled:
            card.disable()
        for i in range(3):
            ref = q0[i] + 0.004 * math.sin(2.0 * math.pi * 2.0 * t + 2.0944 * i)
            volts[i] = max(-6.0, min(6.0, hold[i] + 300.0 * (ref - q[i]))) if on else 0.0
        card.write_volts(volts)
        if k % EVERY == EVERY - 1:
            counts = [float(c) for c in enc.read_counts()]
            values = [t, *counts, *q, *ati, *twin.plant.S]
            rows.append([float(v).hex() for v in values])
    return rows


@pytest.mark.parametrize("env", ENVS)
def test_the_twin_is_bit_for_bit_the_golden_run(env):
    golden = json.loads(GOLDEN.read_text())[env]
    rows = trajectory(env)
    assert len(rows) == len(golden)
    for k, (row, ref) in enumerate(zip(rows, golden)):
        diff = [i for i, (a, b) in enumerate(zip(row, ref)) if a != b]
        assert not diff, (f"{env}: row {k} (t = {float.fromhex(row[0]):.3f} s) differs in "
                          f"columns {diff[:10]}: {[(float.fromhex(row[i]), float.fromhex(ref[i])) for i in diff[:3]]}")


if __name__ == "__main__":
    Path(sys.argv[1]).write_text(json.dumps({env: trajectory(env) for env in ENVS}))
