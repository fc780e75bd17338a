"""approach9: a second soft stop during a stop (main: arrives early with a velocity step; approach9: at rest, no step).

    PYTHONPATH=<tree> .venv/bin/python docs/worklog/2026-11-26f/approach9_double_stop.py
"""
import numpy as np

from rt.references.approach import Approach, ApproachStatus

ap = Approach()
ap.reset([0.2, 0.2, 0.2], [0.1, -0.05, 0.0])
ap.soft_stop()
p, v, a = np.zeros(3), np.zeros(3), np.zeros(3)
for _ in range(100):
    ap.update(p, v, a)
print("after 100 cycles of a stop: v", v, "a", a)
ap.reset(p, v, a); st = ap.soft_stop()         # the sequencer's _brake() again (a second stop)
print("second stop planned: duration", ap.duration, st)
prev = v.copy(); n = 0; jump = 0.0
while True:
    s = ap.update(p, v, a); n += 1
    jump = max(jump, float(np.abs(v - prev).max())); prev = v.copy()
    if s != ApproachStatus.WORKING:
        break
print("arrived after", n, "cycles; largest velocity step between cycles", jump, "m/s; v", v)
