"""Graph builder checks, dependency order, delays, zero-copy ports, statistics, faults."""
from __future__ import annotations

import itertools
import math
import tracemalloc
from dataclasses import dataclass

import numpy as np
import pytest

from rt.devices.interfaces import Wrench
from rt.engine import (
    BOOL,
    FLOAT,
    INT,
    STATUS_EXCEPTION,
    Array,
    Component,
    GraphBuilder,
    Lifecycle,
    Loop,
    Struct,
)
from rt.errors import ConfigurationError


class Source(Component):
    """Ports: out ``y``: float64[3] — the constant ``params.value``."""

    @dataclass(frozen=True)
    class Params:
        value: float = 0.0

    def __init__(self, name: str, value: float = 0.0) -> None:
        super().__init__(name, self.Params(value))
        self.y = self.declare_output("y", Array(3))

    def update(self, t: float, dt: float) -> int:
        self.y.data.fill(self.params.value)
        return 0


class AddOne(Component):
    """Ports: in ``u``: float64[3]; out ``y``: float64[3] — ``u + 1``."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.u = self.declare_input("u", Array(3))
        self.y = self.declare_output("y", Array(3))

    def update(self, t: float, dt: float) -> int:
        np.add(self.u.data, 1.0, out=self.y.data)
        return 0


class Sink(Component):
    """Ports: in ``u``: float64[3]; keeps the last value seen in ``state``."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.u = self.declare_input("u", Array(3))

    def make_state(self) -> np.ndarray:
        return np.zeros(3)

    def update(self, t: float, dt: float) -> int:
        self.state[:] = self.u.data
        return 0


class Scalars(Component):
    """Ports: in ``x``: float; out ``n``: int (cycles seen), ``flag``: bool (x > 1)."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.x = self.declare_input("x", FLOAT)
        self.n = self.declare_output("n", INT)
        self.flag = self.declare_output("flag", BOOL)

    def update(self, t: float, dt: float) -> int:
        self.n.data.value += 1
        self.flag.data.value = self.x.data.value > 1.0
        return 0


class Clock(Component):
    """Ports: out ``t``: float — the loop time (s)."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.t = self.declare_output("t", FLOAT)

    def update(self, t: float, dt: float) -> int:
        self.t.data.value = t
        return 0


def chain_graph(n: int = 5, reverse: bool = True):
    b = GraphBuilder(stats_capacity=1024)
    names = [f"a{i}" for i in range(n)]
    # Added in reverse so that only the topological sort can get the order right.
    for name in (reversed(names) if reverse else names):
        b.add(AddOne(name))
    b.add(Source("src", 10.0))
    b.add(Sink("sink"))
    b.connect("src.y", "a0.u")
    for a, c in itertools.pairwise(names):
        b.connect(f"{a}.y", f"{c}.u")
    b.connect(f"{names[-1]}.y", "sink.u")
    g = b.build()
    g.configure()
    g.start()
    return g


def test_chain_runs_in_dependency_order_within_one_cycle():
    g = chain_graph(5)
    assert g.order == ("src", "a0", "a1", "a2", "a3", "a4", "sink")
    assert g.step(0.0, 1e-3) == 0
    np.testing.assert_array_equal(g.component("sink").state, [15.0, 15.0, 15.0])
    np.testing.assert_array_equal(g.output("a2.y"), [13.0] * 3)


class Accumulate(Component):
    """Ports: in ``prev``: float64[3] (own output, delayed); out ``y``: float64[3] = prev + 1."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.prev = self.declare_input("prev", Array(3))
        self.y = self.declare_output("y", Array(3))

    def update(self, t: float, dt: float) -> int:
        np.add(self.prev.data, 1.0, out=self.y.data)
        return 0


def test_delayed_feedback_reads_previous_cycle_value():
    b = GraphBuilder(stats_capacity=1024)
    b.add(Accumulate("acc"))
    b.add(Sink("probe"))
    b.connect("acc.y", "acc.prev", delay=1, initial=[100.0, 200.0, 300.0])
    b.connect("acc.y", "probe.u", delay=1)
    g = b.build()
    g.configure()
    g.start()
    g.step(0.0, 1e-3)
    # First cycle: the delayed inputs hold their initial values.
    np.testing.assert_array_equal(g.output("acc.y"), [101.0, 201.0, 301.0])
    np.testing.assert_array_equal(g.component("probe").state, [0.0, 0.0, 0.0])
    for _ in range(4):
        g.step(0.0, 1e-3)
    np.testing.assert_array_equal(g.output("acc.y"), [105.0, 205.0, 305.0])
    # The probe reads acc.y one cycle late even though it runs after acc in the same cycle.
    np.testing.assert_array_equal(g.component("probe").state, [104.0, 204.0, 304.0])


def test_two_component_loop_needs_and_accepts_a_delay():
    def build(delay: int):
        b = GraphBuilder(stats_capacity=1024)
        b.add(AddOne("p"))
        b.add(AddOne("q"))
        b.connect("p.y", "q.u")
        b.connect("q.y", "p.u", delay=delay)
        return b.build()

    with pytest.raises(ConfigurationError, match=r"cycle without delay: (p\.y -> q\.u, q\.y -> p\.u"
                                                  r"|q\.y -> p\.u, p\.y -> q\.u)"):
        build(0)
    g = build(1)
    g.configure()
    g.start()
    for _ in range(3):
        g.step(0.0, 1e-3)
    # p(k) = q(k-1) + 1, q(k) = p(k) + 1, q(-1) = 0  ->  q(k) = 2(k+1)
    np.testing.assert_array_equal(g.output("q.y"), [6.0] * 3)


# ----------------------------------------------------------------------------- refusals
class Wide(Component):
    """Ports: in ``u``: float64[6]; out ``y``: float64[6]; out ``s``: float."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.u = self.declare_input("u", Array(6))
        self.y = self.declare_output("y", Array(6))
        self.s = self.declare_output("s", FLOAT)

    def update(self, t: float, dt: float) -> int:
        return 0


def _builder():
    b = GraphBuilder(stats_capacity=1024)
    b.add(Source("src"))
    b.add(AddOne("a"))
    b.add(Wide("w"))
    return b


@pytest.mark.parametrize("wiring, expected", [
    # unknown component / port
    ([("src.y", "a.u"), ("nope.y", "w.u")], r"no component in slot 'nope' \(slots: src, a, w\)"),
    ([("src.y", "a.u"), ("src.z", "w.u")], r"'src' in slot 'src' has no output port 'z' \(outputs: y\)"),
    ([("src.y", "a.bogus"), ("w.y", "w.u")], r"has no input port 'bogus' \(inputs: u\)"),
    # direction
    ([("a.u", "w.u"), ("src.y", "a.u")], r"'a\.u' is an input port; the source must be an output"),
    ([("src.y", "a.y"), ("src.y", "a.u"), ("w.y", "w.u")],
     r"'a\.y' is an output port; the target must be an input"),
    # types and shapes
    ([("src.y", "a.u"), ("a.y", "w.u")],
     r"type mismatch: output 'a\.y' is float64\[3\], input 'w\.u' is float64\[6\]"),
    ([("w.s", "a.u"), ("w.y", "w.u")],
     r"type mismatch: output 'w\.s' is float, input 'a\.u' is float64\[3\]"),
    # connection counts
    ([("src.y", "a.u")], r"input w\.u \(float64\[6\]\) is not connected"),
    ([("src.y", "a.u"), ("a.y", "a.u"), ("w.y", "w.u")],
     r"input 'a\.u' is connected 2 times \(from 'src\.y', 'a\.y'\)"),
    # cycles
    ([("src.y", "a.u"), ("w.y", "w.u")], r"cycle without delay: w\.y -> w\.u"),
])
def test_builder_refuses_bad_wiring_naming_the_problem(wiring, expected):
    b = _builder()
    for src, dst in wiring:
        b.connect(src, dst)
    with pytest.raises(ConfigurationError, match=expected):
        b.build()


def test_builder_reports_all_problems_at_once_and_bad_options():
    b = _builder()
    b.connect("src.y", "a.u", delay=2)
    b.connect("w.y", "w.u", initial=[0.0] * 6)
    with pytest.raises(ConfigurationError) as info:
        b.build()
    msg = str(info.value)
    assert "delay must be 0 or 1 cycle, got 2" in msg
    assert "an initial value only applies to a delayed connection" in msg
    assert "cycle without delay" in msg


def test_builder_refuses_bad_initial_values_and_malformed_addresses():
    b = _builder()
    b.connect("src.y", "a.u")
    b.connect("w.y", "w.u", delay=1, initial=[1.0, 2.0])  # shape (2,) cannot fill (6,)
    with pytest.raises(ConfigurationError, match=r"initial value \[1\.0, 2\.0\] does not fit a "
                                                 r"float64\[6\] port"):
        b.build()
    with pytest.raises(ConfigurationError, match="must be 'slot.port'"):
        GraphBuilder().connect("src", "a.u")


def test_builder_refuses_duplicates_and_late_port_declarations():
    b = GraphBuilder(stats_capacity=1024)
    src = b.add(Source("src"))
    with pytest.raises(ConfigurationError, match="slot 'src' is already taken"):
        b.add(Source("src"))
    with pytest.raises(ConfigurationError, match="already in a graph"):
        b.add(src, slot="other")
    with pytest.raises(ConfigurationError, match="ports must be declared in __init__"):
        src.declare_output("late", FLOAT)
    b.add(Sink("k"))
    b.connect("src.y", "k.u")
    b.build()
    with pytest.raises(ConfigurationError, match="already built"):
        b.add(Source("again"))


# ----------------------------------------------------------------------------- zero copy
def test_inputs_are_read_only_views_of_the_producer_buffer():
    g = chain_graph(3)
    a0, a1 = g.component("a0"), g.component("a1")
    assert np.shares_memory(a1.u.data, a0.y.data)
    assert a1.u.source == "a0.y"
    with pytest.raises(ValueError):
        a1.u.data[0] = 1.0  # a consumer cannot scribble on its producer's output
    before = [(p.data.ctypes.data, id(p.data)) for c in g.components.values()
              for p in list(c.inputs.values()) + list(c.outputs.values())]
    for _ in range(100):
        g.step(0.0, 1e-3)
    after = [(p.data.ctypes.data, id(p.data)) for c in g.components.values()
             for p in list(c.inputs.values()) + list(c.outputs.values())]
    assert before == after  # same buffers: nothing is reallocated or rebound by a cycle


def test_scalar_and_struct_ports_share_one_object():
    class WrenchSource(Component):
        """Ports: out ``w``: Wrench (N, N m)."""

        def __init__(self, name: str) -> None:
            super().__init__(name)
            self.w = self.declare_output("w", Struct(Wrench))

        def update(self, t: float, dt: float) -> int:
            self.w.data.fz = 2.0 * t
            return 0

    class WrenchSink(Component):
        """Ports: in ``now``, ``before``: Wrench (the latter one cycle late); keeps the fz seen."""

        def __init__(self, name: str) -> None:
            super().__init__(name)
            self.now = self.declare_input("now", Struct(Wrench))
            self.before = self.declare_input("before", Struct(Wrench))
            self.seen = [0.0, 0.0]

        def update(self, t: float, dt: float) -> int:
            self.seen[0], self.seen[1] = self.now.data.fz, self.before.data.fz
            return 0

    b = GraphBuilder(stats_capacity=1024)
    b.add(Clock("clk"))
    b.add(Scalars("sc"))
    b.add(WrenchSource("ws"))
    b.add(WrenchSink("wk"))
    b.connect("clk.t", "sc.x")
    b.connect("ws.w", "wk.now")
    b.connect("ws.w", "wk.before", delay=1)
    g = b.build()
    g.configure()
    g.start()
    assert g.component("sc").x.data is g.component("clk").t.data
    assert g.component("wk").now.data is g.component("ws").w.data
    g.step(0.5, 0.5)
    g.step(1.5, 1.0)
    assert g.output("sc.n").value == 2 and g.output("sc.flag").value is True
    assert g.component("wk").seen == [3.0, 1.0]


def test_a_thousand_cycles_allocate_no_lasting_memory():
    """Growth threshold: anything a cycle kept alive would cost at least one Python object per
    cycle (≥ 24 B for the smallest, a float; ≥ 96 B for a 3-element numpy array), i.e.
    ≥ 24 000 B over 1000 cycles. 4 KiB leaves room for one-off lazily created objects (a method
    cache, an interned int) while failing any per-cycle retention."""
    g = chain_graph(7)
    loop = Loop(g, mode="fast", stats_capacity=1024)
    loop.run(cycles=200)  # warm up (first-call caches)
    tracemalloc.start()
    try:
        base, _ = tracemalloc.get_traced_memory()
        loop.run(cycles=1000)
        for _ in range(1000):
            g.step(0.0, 1e-3)
        grown = tracemalloc.get_traced_memory()[0] - base
    finally:
        tracemalloc.stop()
    assert grown < 4096, f"{grown} B retained over 2000 cycles"


# ----------------------------------------------------------------------------- stats, faults
def test_stats_have_the_right_counts_and_plausible_values():
    g = chain_graph(3)
    for _ in range(300):
        g.step(0.0, 1e-3)
    s = g.stats()
    assert s.cycles == 300 and s.cycle.count == 300 and s.cycle.window == 300
    assert list(s.components) == list(g.order)
    for slot, st in s.components.items():
        assert st.count == 300 and st.window == 300 and st.lifecycle == "active"
        assert 0.0 < st.p50_us <= st.p99_us <= st.max_us < 1e5, slot
        assert st.mean_us < s.cycle.mean_us
    assert s.cycle.p50_us <= s.cycle.p99_us <= s.cycle.max_us <= s.cycle.max_all_us
    # The whole cycle includes every component (medians are robust to one-off host stalls).
    assert s.cycle.p50_us >= sum(st.p50_us for st in s.components.values()) * 0.8
    # The ring keeps the last `capacity` samples, the count keeps everything.
    for _ in range(1000):
        g.step(0.0, 1e-3)
    s = g.stats()
    assert s.cycle.count == 1300 and s.cycle.window == 1024
    assert "whole cycle" in s.table()


def test_an_untimed_graph_runs_the_same_cycle_and_reports_no_samples():
    timed, untimed = chain_graph(3), chain_graph(3)
    untimed.timed = False
    assert timed.timed and not untimed.timed
    for g in (timed, untimed):
        for _ in range(50):
            g.step(0.0, 1e-3)
    assert untimed.cycles == timed.cycles == 50
    assert untimed.output("a2.y").tolist() == timed.output("a2.y").tolist() == [13.0] * 3
    s = untimed.stats()
    assert s.cycle.count == 50 and s.cycle.window == 0 and math.isnan(s.cycle.p50_us)
    assert all(st.window == 0 and math.isnan(st.mean_us) for st in s.components.values())
    # Timed again: the samples start from there.
    untimed.timed = True
    for _ in range(20):
        untimed.step(0.0, 1e-3)
    s = untimed.stats()
    assert s.cycle.window == 20 and s.cycle.p50_us > 0.0
    assert all(st.count == 20 and st.window == 20 for st in s.components.values())


class Faulty(Component):
    """Ports: in ``u``, out ``y``: float64[3]; fails at cycle ``fail_at`` (raise or status)."""

    def __init__(self, name: str, fail_at: int, how: str) -> None:
        super().__init__(name)
        self.u = self.declare_input("u", Array(3))
        self.y = self.declare_output("y", Array(3))
        self.fail_at, self.how, self.n = fail_at, how, 0

    def update(self, t: float, dt: float) -> int:
        self.n += 1
        if self.n == self.fail_at:
            if self.how == "raise":
                raise ZeroDivisionError("boom")
            return 7
        self.y.data[:] = self.u.data
        return 0


@pytest.mark.parametrize("how, code, reason", [
    ("raise", STATUS_EXCEPTION, "update raised ZeroDivisionError: boom"),
    ("status", 7, "update returned status 7"),
])
def test_a_failing_component_goes_to_error_and_the_rest_keeps_running(how, code, reason):
    b = GraphBuilder(stats_capacity=1024)
    b.add(Source("src", 1.0))
    b.add(Faulty("f", 3, how))
    b.add(AddOne("after"))
    b.connect("src.y", "f.u")
    b.connect("f.y", "after.u")
    g = b.build()
    g.configure()
    g.start()
    results = [g.step(k * 1e-3, 1e-3) for k in range(6)]
    assert results == [0, 0, 1, 0, 0, 0]
    f = g.component("f")
    assert f.lifecycle is Lifecycle.ERROR and f.fault_reason == reason
    assert f.n == 3  # skipped once in error
    (fault,) = g.faults()
    assert (fault.cycle, fault.slot, fault.component, fault.code) == (2, "f", "f", code)
    assert fault.t == pytest.approx(2e-3)
    assert g.fault_count == 1
    if how == "raise":
        assert isinstance(g.last_exception, ZeroDivisionError)
    s = g.stats()
    assert s.faults == 1
    assert s.components["f"].count == 3 and s.components["f"].lifecycle == "error"
    assert s.components["after"].count == 6
    # downstream keeps the last good value flowing
    np.testing.assert_array_equal(g.output("after.y"), [2.0] * 3)
    # and the fault latches until reset
    g.stop()
    g.reset()
    assert f.lifecycle is Lifecycle.INACTIVE and f.fault_reason is None


class Integrator(Component):
    """Ports: in ``u``: float64[3]; out ``y``: float64[3] = ∫u dt (state)."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.u = self.declare_input("u", Array(3))
        self.y = self.declare_output("y", Array(3))

    def make_state(self) -> np.ndarray:
        return np.zeros(3)

    def update(self, t: float, dt: float) -> int:
        self.state += self.u.data * dt
        self.y.data[:] = self.state
        return 0


def test_reset_replays_a_run_exactly():
    b = GraphBuilder(stats_capacity=1024)
    b.add(Clock("clk"))
    b.add(Source("src", 2.0))
    b.add(Integrator("int"))
    b.add(Accumulate("acc"))
    b.connect("src.y", "int.u")
    b.connect("acc.y", "acc.prev", delay=1)
    g = b.build()
    loop = Loop(g, mode="fast", stats_capacity=1024)

    def record():
        loop.run(cycles=37)
        return (loop.t, g.output("clk.t").value, g.output("int.y").copy(), g.output("acc.y").copy())

    first = record()
    loop.reset()
    assert loop.cycles == 0 and float(g.output("int.y")[0]) == 0.0
    second = record()
    assert first[:2] == second[:2]
    np.testing.assert_array_equal(first[2], second[2])
    np.testing.assert_array_equal(first[3], second[3])
    np.testing.assert_array_equal(first[3], [37.0] * 3)


def test_a_cycle_is_named_even_when_components_hang_below_it():
    b = GraphBuilder(stats_capacity=1024)
    for name in ("x", "y", "b"):
        b.add(AddOne(name))
    b.add(Sink("a"))  # downstream of the cycle and first in alphabetical order
    b.connect("x.y", "y.u")
    b.connect("y.y", "x.u")
    b.connect("y.y", "b.u")
    b.connect("b.y", "a.u")
    with pytest.raises(ConfigurationError) as info:
        b.build()
    msg = str(info.value)
    assert "cycle without delay:" in msg and "x.y -> y.u" in msg and "y.y -> x.u" in msg
    assert "b.y" not in msg
