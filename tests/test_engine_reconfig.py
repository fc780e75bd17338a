"""Runtime reconfiguration at cycle boundaries: rate, parameters, component swap + handover."""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass

import numpy as np
import pytest

from rt.engine import FLOAT, Array, Component, GraphBuilder, Lifecycle, Loop
from rt.errors import InputError


class Ramp(Component):
    """Ports: out ``r``: float64[1] — the loop time t (s), as a reference to follow."""

    def __init__(self, name: str = "ramp") -> None:
        super().__init__(name)
        self.r = self.declare_output("r", Array(1))

    def update(self, t: float, dt: float) -> int:
        self.r.data[0] = t
        return 0


class Gain(Component):
    """Ports: in ``x``: float64[1]; out ``y``: float64[1] = k x (+ offset); out ``n``: float
    (cycles run). State: cycles run (an int in a one-element array)."""

    @dataclass(frozen=True)
    class Params:
        k: float = 1.0
        offset: float = 0.0

        def __post_init__(self) -> None:
            if not 0.0 <= self.k <= 100.0:
                raise ValueError(f"k = {self.k} outside [0, 100]")

    def __init__(self, name: str, k: float = 1.0) -> None:
        super().__init__(name, self.Params(k))
        self.x = self.declare_input("x", Array(1))
        self.y = self.declare_output("y", Array(1))
        self.n = self.declare_output("n", FLOAT)
        self.handovers: list[Component] = []

    def make_state(self) -> np.ndarray:
        return np.zeros(1)

    def handover(self, old: Component) -> None:
        # Bumpless: continue from the old one's last output (our outputs share its buffers).
        self.handovers.append(old)
        assert self.y.data is old.y.data
        self.state[0] = old.state[0]
        self.offset = float(self.y.data[0]) - self.params.k * float(self.x.data[0])

    offset = 0.0

    def update(self, t: float, dt: float) -> int:
        self.state[0] += 1
        self.n.data.value = self.state[0]
        self.y.data[0] = self.params.k * self.x.data[0] + self.offset + self.params.offset
        return 0


class Recorder(Component):
    """Ports: in ``y``: float64[1]; records it each cycle (preallocated)."""

    def __init__(self, name: str = "rec") -> None:
        super().__init__(name)
        self.y = self.declare_input("y", Array(1))
        self.seen = np.full(20000, np.nan)
        self.i = 0

    def update(self, t: float, dt: float) -> int:
        if self.i < self.seen.size:
            self.seen[self.i] = self.y.data[0]
        self.i += 1
        return 0


def gain_graph(k: float = 2.0):
    b = GraphBuilder(stats_capacity=4096)
    b.add(Ramp())
    b.add(Gain("g1", k), slot="ctl")
    b.add(Recorder())
    b.connect("ramp.r", "ctl.x")
    b.connect("ctl.y", "rec.y")
    return b.build()


def test_set_param_applies_at_the_next_boundary():
    g = gain_graph(2.0)
    loop = Loop(g, rate_hz=1000.0, mode="fast")
    loop.run(cycles=10)
    res = loop.set_param("ctl", "k", 3.0)
    assert not res.done() and res.ok is None  # nothing happens between cycles
    assert g.component("ctl").params.k == 2.0
    loop.run(cycles=5)
    assert res.wait(0) and res.ok and res.cycle == 10 and res.value.k == 3.0
    rec = g.component("rec").seen
    assert rec[9] == pytest.approx(2.0 * 9e-3) and rec[10] == pytest.approx(3.0 * 10e-3)


def test_rejected_set_param_changes_nothing():
    g = gain_graph(2.0)
    loop = Loop(g, mode="fast")
    loop.run(cycles=10)
    ctl = g.component("ctl")
    params, state = ctl.params, ctl.state.copy()
    bad = loop.set_params("ctl", k=500.0, offset=1.0)     # k out of range spoils the pair
    unknown = loop.set_param("ctl", "kd", 1.0)
    no_slot = loop.set_param("nope", "k", 1.0)
    assert no_slot.done() and not no_slot.ok and "no slot 'nope'" in no_slot.error
    loop.run(cycles=1)
    assert bad.ok is False and "k = 500.0 outside [0, 100]" in bad.error and bad.cycle == 10
    assert unknown.ok is False and "no parameter 'kd'" in unknown.error
    with pytest.raises(InputError, match="outside"):
        bad.result()
    assert ctl.params is params and ctl.lifecycle is Lifecycle.ACTIVE
    assert ctl.state[0] == state[0] + 1  # the component simply ran on
    assert g.component("rec").seen[10] == pytest.approx(2.0 * 10e-3)


def test_rate_change_takes_effect_at_the_next_boundary():
    holder = {}

    class Asker(Component):
        """Ports: none. Asks for 500 Hz during cycle 5 and records dt."""

        def __init__(self) -> None:
            super().__init__("asker")
            self.dts = np.zeros(20)
            self.i = 0

        def update(self, t: float, dt: float) -> int:
            self.dts[self.i] = dt
            if self.i == 5:
                holder["res"] = holder["loop"].set_rate(500.0)
            self.i += 1
            return 0

    b = GraphBuilder(stats_capacity=1024)
    asker = b.add(Asker())
    loop = holder["loop"] = Loop(b.build(), rate_hz=1000.0, mode="fast")
    loop.run(cycles=20)
    res = holder["res"]
    # Asked during cycle 5, applied at the start of cycle 6: the period after cycle 6 is 2 ms.
    assert res.ok and res.cycle == 6 and loop.rate_hz == 500.0
    assert np.all(asker.dts[:7] == 1e-3) and np.all(asker.dts[7:] == 2e-3)
    assert loop.t == pytest.approx(6e-3 + 13 * 2e-3, abs=1e-12)
    refused = loop.set_rate(5000.0)
    assert refused.done() and not refused.ok and "outside the supported 100-2000 Hz" in refused.error


def test_rate_change_in_a_running_realtime_thread():
    class Dt(Component):
        """Ports: none. Records measured dt (s)."""

        def __init__(self) -> None:
            super().__init__("dt")
            self.dts = np.zeros(5000)
            self.i = 0

        def update(self, t: float, dt: float) -> int:
            if self.i < 5000:
                self.dts[self.i] = dt
            self.i += 1
            return 0

    b = GraphBuilder(stats_capacity=1024)
    d = b.add(Dt())
    loop = Loop(b.build(), rate_hz=1000.0, mode="realtime")
    loop.start()
    try:
        time.sleep(0.05)
        res = loop.set_rate(200.0)
        res.result(timeout=30.0)
        time.sleep(0.1)
    finally:
        loop.stop()
    c = res.cycle
    assert c is not None and c > 10 and d.i > c + 5
    assert np.median(d.dts[1:c]) == pytest.approx(1e-3, rel=0.2)
    assert np.median(d.dts[c + 1:d.i]) == pytest.approx(5e-3, rel=0.2)


def test_swap_with_handover_at_a_cycle_boundary_is_bumpless():
    g = gain_graph(2.0)
    loop = Loop(g, rate_hz=1000.0, mode="fast")
    loop.run(cycles=100)
    old = g.component("ctl")
    new = Gain("g2", 5.0)
    res = loop.swap("ctl", new)
    # prepared now (ports bound, configured), applied at the boundary
    assert not res.done() and new.lifecycle is Lifecycle.INACTIVE
    assert new.x.data is old.x.data and new.y.data is old.y.data
    assert g.component("ctl") is old
    loop.run(cycles=50)
    assert res.ok and res.cycle == 100 and res.value is new
    assert g.component("ctl") is new and new.handovers == [old]
    assert old.lifecycle is Lifecycle.INACTIVE and new.lifecycle is Lifecycle.ACTIVE
    assert new.state[0] == 100 + 50  # state carried over by handover
    seen = g.component("rec").seen
    # No jump at the switch: the output continues from old's last value with the new slope.
    assert seen[100] - seen[99] == pytest.approx(5.0 * 1e-3, abs=1e-12)
    assert seen[99] - seen[98] == pytest.approx(2.0 * 1e-3, abs=1e-12)
    np.testing.assert_allclose(np.diff(seen[100:150]), 5e-3, atol=1e-12)
    # The slot's statistics restarted with the new occupant.
    st = g.stats().components["ctl"]
    assert st.component == "g2" and st.count == 50
    # and the old component can go back in the same slot
    back = loop.swap("ctl", old)
    loop.run(cycles=1)
    assert back.ok and g.component("ctl") is old and old.lifecycle is Lifecycle.ACTIVE


def test_incompatible_swaps_are_refused_at_once_and_change_nothing():
    class Narrow(Component):
        """Ports: in ``x``: float64[1]; out ``y``: float64[2] (wrong shape)."""

        def __init__(self) -> None:
            super().__init__("narrow")
            self.x = self.declare_input("x", Array(1))
            self.y = self.declare_output("y", Array(2))

        def update(self, t: float, dt: float) -> int:
            return 0

    class Needy(Gain):
        """Ports: Gain's plus in ``extra``: float (no source in the slot)."""

        def __init__(self) -> None:
            super().__init__("needy")
            self.extra = self.declare_input("extra", FLOAT)

    g = gain_graph()
    loop = Loop(g, mode="fast")
    loop.run(cycles=3)
    old = g.component("ctl")
    for comp, message in [
        (Narrow(), (r"output 'y' is float64\[2\], the slot's is float64\[1\]; "
                   r"output 'n' \(float\) is missing")),
        (Needy(), r"input 'extra' \(float\) has no source in slot 'ctl'"),
        (old, "already in that slot"),
    ]:
        res = loop.swap("ctl", comp)
        assert res.done() and res.ok is False
        assert "cannot swap" in res.error or "already" in res.error
        assert __import__("re").search(message, res.error), res.error
    assert loop.swap("nope", Gain("g9")).ok is False
    loop.run(cycles=1)
    assert g.component("ctl") is old and old.lifecycle is Lifecycle.ACTIVE


def test_a_failing_handover_aborts_the_swap():
    class Grumpy(Gain):
        """Ports: Gain's. Refuses every handover."""

        def handover(self, old: Component) -> None:
            raise RuntimeError("cannot take over from that one")

    g = gain_graph()
    loop = Loop(g, mode="fast")
    loop.run(cycles=3)
    old = g.component("ctl")
    grumpy = Grumpy("grumpy")
    res = loop.swap("ctl", grumpy)
    loop.run(cycles=2)
    assert res.ok is False and "cannot take over from that one" in res.error
    assert "'g1' stays" in res.error
    assert g.component("ctl") is old and old.lifecycle is Lifecycle.ACTIVE
    assert grumpy.lifecycle is Lifecycle.INACTIVE and grumpy._graph is None
    assert g.component("rec").seen[4] == pytest.approx(2.0 * 4e-3)


def test_swap_into_a_running_threaded_loop():
    g = gain_graph(1.0)
    loop = Loop(g, rate_hz=1000.0, mode="realtime")
    loop.start()
    try:
        time.sleep(0.02)
        new = Gain("fast_gain", 4.0)
        results = []
        # Several threads submitting at once: each command is applied exactly once, in order.
        threads = [threading.Thread(target=lambda k=k: results.append(
            loop.set_param("ctl", "offset", float(k)))) for k in range(4)]
        for th in threads:
            th.start()
        for th in threads:
            th.join()
        assert loop.swap("ctl", new).result(timeout=30.0) is new
        assert all(r.wait(2.0) and r.ok for r in results)
    finally:
        loop.stop()
    assert g.component("ctl") is new and new.lifecycle is Lifecycle.ACTIVE
    assert new.handovers and new.handovers[0].name == "g1"


def test_the_command_queue_is_bounded():
    g = gain_graph()
    loop = Loop(g, mode="fast", command_capacity=2)
    a, b, c = (loop.set_param("ctl", "k", v) for v in (1.0, 2.0, 3.0))
    assert not a.done() and not b.done()
    assert c.done() and c.ok is False and "queue full" in c.error
    with pytest.raises(TimeoutError, match="not applied within 0.01 s"):
        a.result(timeout=0.01)
    loop.run(cycles=1)
    assert a.ok and b.ok and g.component("ctl").params.k == 2.0
