"""The RT process loads the twin's session kernels before its loop runs
(``Twin.warm_session_paths``): a session's foot strap then loads nothing inside a cycle (its
first strap stalled one cycle by 30-54 ms while numba loaded the plant's contact period from
its cache), and the warmed twin itself is left as it was.

Run in a fresh interpreter: numba's loaded kernels are process-wide, and other tests in this
process may have loaded them already."""
from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np

from rt.twin.twin import Twin

SCRIPT = textwrap.dedent("""
    import sys
    from numba.core import dispatcher
    loads = []
    original = dispatcher.Dispatcher._compile_for_args
    def spy(self, *a, **k):
        loads.append(self.py_func.__qualname__)
        return original(self, *a, **k)
    dispatcher.Dispatcher._compile_for_args = spy
    from rt.twin.environment import patient_foot
    from rt.twin.twin import Twin
    tw = Twin()
    tw.place((0.2, 0.2, 0.2))
    tw.sync(0.01)
    if sys.argv[1] == "warm":
        tw.warm_session_paths()
    loads.clear()
    c = tw.plant.kin.fk(tw.plant.q, check=False)
    foot = patient_foot(tw.plant.kin, c.z, c.roll, c.pitch)
    tw.set_environment_on_arrival(lambda _q: foot, tw.plant.q.copy())
    tw.sync(tw.t + 0.003)
    print(",".join(loads))
""")


def _loads_at_the_strap(how: str) -> list[str]:
    out = subprocess.run([sys.executable, "-c", SCRIPT, how], capture_output=True, text=True,
                         timeout=300, check=True).stdout
    last = out.rstrip("\n").rsplit("\n", 1)[-1]       # the script's last line: the loads
    return [x for x in last.split(",") if x]


def test_a_warmed_twin_loads_no_kernel_at_the_foot_strap():
    assert _loads_at_the_strap("cold")           # the stall this prevents (plant.advance …)
    assert _loads_at_the_strap("warm") == []


def test_warming_leaves_the_twin_as_it_was():
    tw = Twin()
    tw.place((0.21, 0.2, 0.19))
    tw.sync(0.01)
    q, qd, t, env = tw.plant.q.copy(), tw.plant.qd.copy(), tw.t, tw.environment
    tw.warm_session_paths()
    assert np.array_equal(tw.plant.q, q) and np.array_equal(tw.plant.qd, qd)
    assert tw.t == t and tw.environment is env
