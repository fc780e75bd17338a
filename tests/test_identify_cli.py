"""``talus identify run`` end to end on the realistic twin (short excitation)."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np

from rt.model import RobotModel
from rt.model.description import load_description


def test_identify_writes_a_loadable_description_and_refuses_to_overwrite(tmp_path):
    out = tmp_path / "identified.yaml"
    cmd = [sys.executable, "-m", "talus", "identify", "run", "--out", str(out), "--seconds",
           "20", "--offsets", "--json"]
    proc = subprocess.run(cmd, check=False, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout)
    desc = load_description(out)
    RobotModel.from_description(desc)                       # loadable with --robot
    assert len(desc.friction.viscous_axes) == 3
    assert all(b["sigma"] >= 0.0 for b in result["base"])
    v = result["validation"]
    assert v["identified"]["rms_pct_of_peak"] < v["nominal"]["rms_pct_of_peak"]
    assert v["identified"]["rms_pct_of_peak"] < 5.0                 # issue 15's target
    # Issue 15 on the realistic twin (compliant, backlashed screw with split friction, its
    # ripple per revolution, amplifier lag, warming grease): the rotor inertias and friction
    # within 5 % of the truth, and within 4 σ + 1 %: σ is statistical only, and 1 % allows
    # for the two biases measured and left in (the amplifier's current-loop lag beyond the
    # held half period and the grease warming during the run: ≤ 0.8 % together on the 40 s
    # figure in the ident4 closing note). Before the twin's coupled Coulomb step and
    # the estimator's ripple columns fv was −4.8…−9.6 %.
    # With the amplifiers' offsets as unknowns the rotor inertias are folded with the leg
    # masses ("Jr0 + slider0.m": estimate.py's docstring, 5.).
    base = {b["name"].split(" ")[0]: b for b in result["base"]}
    for name in [f"{p}{i}" for p in ("Jr", "fv", "fc") for i in range(3)]:
        b = base[name]
        assert b["rel_error"] < 0.05, (name, b)
        assert abs(b["estimate"] - b["truth"]) <= (4.0 * b["sigma"]
                                                   + 0.01 * abs(b["truth"])), (name, b)
    # The screw's friction ripple it estimated: the twin's ±8 % of the Coulomb level
    # (5-6 N) within 20 %.
    from rt.twin.realism import RigImperfections, default_truth

    want = RigImperfections().friction_ripple * np.array(default_truth().friction.coulomb_axes)
    np.testing.assert_allclose(result["friction_ripple_n"], want, rtol=0.2)
    # The amplifiers' offsets (the twin's ±15 mV draw: −2.7/−4.3/−1.5 N), given the leg masses
    # the lab believes: off by g × each believed leg mass's error (the data cannot separate
    # them, estimate.py's docstring 5.) and by the ATI cable's weight share (2 N over three
    # axes, a constant force too: −0.6…−0.8 N on the 40 s figure); nothing else beyond 0.5 N.
    off = result["amplifier_offsets"]
    g = load_description().gravity_m_s2
    legs = ("slider0.m", "rod1.m", "slider2.m")
    from rt.model.regressor import Regressor

    def leg_masses(desc) -> np.ndarray:
        reg = Regressor(RobotModel.from_description(desc).dyn)
        return np.array([reg.theta_base()[reg.base.names.index(n)] for n in legs])

    mass_error = leg_masses(load_description()) - leg_masses(default_truth())
    residual = np.array(off["estimate_n"]) - np.array(off["truth_n"]) - g * mass_error
    assert np.all((residual > -1.5) & (residual < 0.3)), residual
    assert desc.drive.amplifier_offset_v == off["written_v"]
    np.testing.assert_allclose(desc.drive.amplifier_offsets_n, off["estimate_n"], atol=0.2)
    # … and a loop built from the file (what --robot loads) compensates them at its outputs:
    # every cycle's volts are the command's less the written offsets (the signature on the
    # twin: tests/test_offset_compensation.py).
    from rt.position_loop import build_sim_position_loop

    pl = build_sim_position_loop("paden_panja", model=RobotModel.load(out), start_program=False)
    pl.loop.run(cycles=200)
    rows, _ = pl.recorder.drain(0)
    pl.graph.stop()
    assert pl.supervisor.amplifier_offset_v == tuple(off["written_v"])
    per_volt = desc.drive.force_per_volt_n
    np.testing.assert_allclose(rows[:, 13:16], rows[:, 10:13] / per_volt - off["written_v"],
                               rtol=0.0, atol=1e-12)
    # The file exists now: a second run without --force is refused and changes nothing.
    before = out.read_bytes()
    proc = subprocess.run(cmd, check=False, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "exists" in proc.stdout   # one {"error"} line
    assert out.read_bytes() == before
