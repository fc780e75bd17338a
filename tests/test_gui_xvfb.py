"""A real window under Xvfb (the xcb platform, Debian's xvfb and xcb libraries installed by
`make`): `talus gui --screenshot DIR` runs the demo session and writes every page; each PNG is
the clinic screen's size and shows something (not one flat colour)."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import gui_support  # noqa: F401  (offscreen for this process; the child uses xcb)
from PySide6.QtGui import QImage

EXPECTED = {"prescribe", "run", "review", "calibrate", "settings", "run_live", "stopped",
            "calibrate_camera"}


def _expected() -> set[str]:
    """Log in, Patients and Users are rendered when the clinical record is installed."""
    try:
        import patients.service  # noqa: F401
    except ImportError:
        return EXPECTED
    return EXPECTED | {"login", "patients", "users"}


def _distinct_colours(image: QImage, step: int = 17) -> int:
    seen = set()
    for y in range(0, image.height(), step):
        for x in range(0, image.width(), step):
            seen.add(image.pixel(x, y))
    return len(seen)


def test_real_window_under_xvfb_renders_every_page(tmp_path):
    xvfb_run = shutil.which("xvfb-run")
    assert xvfb_run, "xvfb-run is missing: `make setup` installs Debian's xvfb"
    talus = Path(sys.executable).with_name("talus")
    out = tmp_path / "shots"
    env = {k: v for k, v in os.environ.items() if k != "QT_QPA_PLATFORM"}
    env["QT_QPA_PLATFORM"] = "xcb"
    proc = subprocess.run(
        [xvfb_run, "-a", "-s", "-screen 0 1366x768x24", str(talus), "gui", "--screenshot",
         str(out), "--recordings-dir", str(tmp_path / "rec"), "--settings",
         str(tmp_path / "gui.json")], env=env, check=False, capture_output=True, text=True,
        timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    files = [Path(f) for f in json.loads(proc.stdout.strip().splitlines()[-1])["screenshots"]]
    assert {f.stem for f in files} == _expected()
    for f in files:
        image = QImage(str(f))
        assert (image.width(), image.height()) == (1366, 768), f
        assert _distinct_colours(image) > 20, f
    # Refuses to overwrite what it did not create in this run, unless --force.
    again = subprocess.run([str(talus), "gui", "--screenshot", str(out)],
                           env={**env, "QT_QPA_PLATFORM": "offscreen"},
                           check=False, capture_output=True, text=True, timeout=120)
    assert again.returncode == 2 and "--force" in again.stderr
