"""``talus identify run`` end to end on the realistic twin (short excitation)."""
from __future__ import annotations

import json
import subprocess
import sys

from rt.model import RobotModel
from rt.model.description import load_description


def test_identify_writes_a_loadable_description_and_refuses_to_overwrite(tmp_path):
    out = tmp_path / "identified.yaml"
    cmd = [sys.executable, "-m", "talus", "identify", "run", "--out", str(out), "--seconds",
           "20", "--json"]
    proc = subprocess.run(cmd, check=False, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout)
    desc = load_description(out)
    RobotModel.from_description(desc)                       # loadable with --robot
    assert len(desc.friction.viscous_axes) == 3
    assert all(b["sigma"] >= 0.0 for b in result["base"])
    v = result["validation"]
    assert v["identified"]["rms_pct_of_peak"] < v["nominal"]["rms_pct_of_peak"]
    # The file exists now: a second run without --force is refused and changes nothing.
    before = out.read_bytes()
    proc = subprocess.run(cmd, check=False, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "exists" in proc.stdout   # one {"error"} line
    assert out.read_bytes() == before
