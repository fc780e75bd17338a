"""The graph's delay latches copied in one compiled call (``rt.engine.latches``)."""
from __future__ import annotations

import numpy as np

from rt.engine.latches import copy_latches, latch_table
from rt.position_loop import build_sim_position_loop


def test_the_compiled_copy_is_the_python_copy_bit_for_bit():
    rng = np.random.default_rng(7)
    srcs = [rng.normal(size=n) for n in (1, 3, 6)]
    srcs[0][0] = np.nan
    srcs[1][1] = -0.0
    dsts = [np.zeros_like(s) for s in srcs]
    table = latch_table(list(zip(dsts, srcs)))
    assert table is not None and table.shape == (3, 3)
    copy_latches(table)
    for d, s in zip(dsts, srcs):
        assert d.tobytes() == s.tobytes()


def test_anything_but_float64_arrays_keeps_the_python_copies():
    a = np.zeros(3)
    assert latch_table([]) is None
    assert latch_table([(a, np.zeros(3, dtype=np.int64))]) is None     # another dtype
    assert latch_table([(a, np.zeros(4))]) is None                     # another length
    assert latch_table([(a, np.zeros((3, 2))[:, 0])]) is None          # not contiguous
    ro = np.zeros(3)
    ro.flags.writeable = False
    assert latch_table([(ro, a)]) is None                              # read-only latch
    assert latch_table([(a, object())]) is None                         # a Box (scalar port)


def test_the_position_loop_copies_its_latches_compiled():
    pl = build_sim_position_loop("paden_panja", duration_s=1.0, mode="fast")
    g = pl.graph
    assert g._latch_table is not None and len(g._latch_table) == len(g._latches) == 4
    pl.loop.run(cycles=5)
    for _copy, latch, src in g._latches:
        assert latch.tobytes() == src.tobytes()                        # after the cycle
