"""Regenerate the data files of the shipped protocol library (``python -m protocols.library_data``).

* ``gait_walk_70kg.csv`` — the published-shape walking force (``protocols.gait``) of a 70 kg
  subject, 0.64 s stance, 500 Hz, 0.1 s unloaded before and after, with fx and fy.
* ``playback_tilt_demo.csv`` — a 12 s slider trajectory in the thesis format (``t,q0,q1,q2``,
  100 Hz, thesis 3.7.4) for the nominal robot: heave ±7.5 mm and tilts of 6° about both axes,
  windowed by sin² so it starts and ends at rest.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from protocols.gait import WALKING_STANCE_S, walking_grf, write_grf_csv
from protocols.library import LIBRARY_DIR
from rt.model.kinematics import Kinematics

GAIT_CSV = "gait_walk_70kg.csv"
PLAYBACK_CSV = "playback_tilt_demo.csv"
PLAYBACK_Z_M = 0.63


def playback_demo_q(kinematics: Kinematics, rate_hz: float = 100.0, duration_s: float = 12.0
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Times (s) and slider positions (m, (n, 3)) of the demo playback trajectory."""
    t = np.arange(round(duration_s * rate_hz) + 1) / rate_hz
    window = np.sin(math.pi * t / duration_s) ** 2
    z = PLAYBACK_Z_M + 0.0075 * window * np.sin(2.0 * math.pi * t / 6.0)
    roll = math.radians(6.0) * window * np.sin(2.0 * math.pi * t / 6.0)
    pitch = math.radians(6.0) * window * np.sin(2.0 * math.pi * t / 4.0)
    q = np.array([kinematics.ik(float(a), float(b), float(c)).q
                  for a, b, c in zip(z, roll, pitch)])
    return t, q


def regenerate(library_dir: Path = LIBRARY_DIR, kinematics: Kinematics | None = None) -> None:
    """Write both data files into ``library_dir``."""
    record = walking_grf(70.0, WALKING_STANCE_S, 500.0, 0.1)
    write_grf_csv(library_dir / GAIT_CSV, record, comments=(
        "Published-shape walking ground-reaction force (protocols.gait.walking_grf_bw):",
        "textbook values, not a measured subject. 70 kg subject, stance 0.64 s, 500 Hz,",
        "0.1 s unloaded before heel strike and after toe off. t in s, forces in N;",
        "fz vertical (loading positive), fx anterior-posterior, fy medial-lateral.",
    ))
    if kinematics is None:
        from rt.model import RobotModel
        kinematics = RobotModel.load().kin
    t, q = playback_demo_q(kinematics)
    with open(library_dir / PLAYBACK_CSV, "w", encoding="utf-8", newline="") as f:
        f.write("# Demo slider trajectory for the nominal twin (protocols.library_data):\n")
        f.write("# heave and 6 deg tilts at z = 0.63 m, 100 Hz, starting and ending at rest.\n")
        f.write("t,q0,q1,q2\n")
        f.writelines(f"{tk:.2f},{a:.7f},{b:.7f},{c:.7f}\n" for tk, (a, b, c) in zip(t, q))


if __name__ == "__main__":
    regenerate()
    print(f"wrote {GAIT_CSV} and {PLAYBACK_CSV} in {LIBRARY_DIR}")
