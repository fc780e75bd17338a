"""The fused cycle (``rt.components.fused``) against the per-block cycle, bit for bit (issue 16).

Two loops are built alike on their own twins; one runs the estimator → supervisor chain as one
compiled call per cycle, the other runs the five blocks' ``update`` (``Graph.fused = False``,
the reference). They are stepped in lockstep through a position session with controller swaps
(each swap's bumpless fade runs the controller block), a hand-stop trip with its reset, and an
e-stop; and through a force protocol with its tare (force mode runs the hybrid controller's
Python) followed by a position protocol. After every cycle every output port of every slot is
compared byte for byte, as are the safety events, the graph's faults and the twin's state;
the fused run must also actually have fused (and have stopped part-way on the events).
"""
from __future__ import annotations

from collections import Counter
from collections.abc import Callable

import numpy as np
import pytest

from rt.components import fused
from rt.engine import STATUS_EXCEPTION, Array, Component, GraphBuilder
from rt.errors import ConfigurationError
from rt.model import RobotModel
from rt.position_loop import (
    PositionLoop,
    build_protocol_loop,
    build_sim_position_loop,
    sim_devices,
    swap_controller,
)


@pytest.fixture(scope="module")
def model() -> RobotModel:
    return RobotModel.load()


def _events(pl: PositionLoop) -> list[tuple]:
    return [(e.t, e.kind, e.cause, int(e.reaction), e.message, repr(e.values))
            for e in pl.events.snapshot()]


class _Lockstep:
    """A fused loop and a per-block loop built by ``build``, stepped together."""

    def __init__(self, build: Callable[[], PositionLoop]):
        self.f, self.p = build(), build()
        self.p.graph.fused = False
        assert self.f.graph.fused and self.f.graph.segment.why_not == ""
        self.ran: Counter[int] = Counter()
        seg = self.f.graph.segment
        run = seg.run

        def counted(t: float, dt: float, idx: int) -> int:
            n = run(t, dt, idx)
            self.ran[n] += 1
            return n

        seg.run = counted
        self.cycles = 0

    def both(self, act: Callable[[PositionLoop], object]) -> None:
        act(self.f)
        act(self.p)

    def run(self, cycles: int) -> None:
        for _ in range(cycles):
            self.f.loop.run(cycles=1)
            self.p.loop.run(cycles=1)
            self.cycles += 1
            self.compare()

    def compare(self) -> None:
        gf, gp = self.f.graph, self.p.graph
        for slot in gf.order:
            cf, cp = gf.component(slot), gp.component(slot)
            assert cf.name == cp.name, (self.cycles, slot)
            for name, port in cf.outputs.items():
                a = np.asarray(port.data.buf if hasattr(port.data, "buf") else port.data)
                o = cp.outputs[name].data
                b = np.asarray(o.buf if hasattr(o, "buf") else o)
                assert a.tobytes() == b.tobytes(), (self.cycles, slot, name, a, b)
        assert _events(self.f) == _events(self.p), self.cycles
        assert [(x.cycle, x.slot, x.code, x.reason) for x in gf.faults()] == \
            [(x.cycle, x.slot, x.code, x.reason) for x in gp.faults()], self.cycles
        tf, tp = self.f.twin, self.p.twin
        assert tf is not None and tp is not None
        assert repr(tf.true_state()) == repr(tp.true_state()), self.cycles


def test_a_position_session_with_swaps_and_trips_is_the_per_block_cycle_bit_for_bit(model):
    # Each loop its own model: the FK warm start lives in the model's kinematics.
    h = _Lockstep(lambda: build_sim_position_loop("paden_panja", duration_s=2.5,
                                                  model=RobotModel.load()))
    h.run(400)                                          # approach, play (Paden-Panja)
    for law in ("pd_g0", "adaptive", "pid", "computed_torque"):
        h.both(lambda pl, law=law: swap_controller(pl, law))
        h.run(250)                                      # the swap, its fade, then fused
        if law == "adaptive":                           # new gains replace its estimate
            lam = h.f.controller.gains.lambda_per_s
            h.both(lambda pl, lam=lam: pl.loop.set_params("controller", lambda_per_s=1.2 * lam))
            h.run(100)
    h.both(lambda pl: setattr(pl.twin.inputs, "hand_stop", True))   # a trip in the kernel
    h.run(60)
    h.both(lambda pl: setattr(pl.twin.inputs, "hand_stop", False))
    h.run(20)
    h.both(lambda pl: pl.supervisor.request_reset())
    h.run(200)
    h.both(lambda pl: pl.supervisor.request_estop("operator"))      # Python's trip
    h.run(50)
    h.both(lambda pl: pl.supervisor.request_reset())
    h.run(300)
    assert h.f.events.first("hand_stop") is not None
    assert h.f.events.first("estop_operator") is not None
    # Fused whole on steady cycles, stopped part-way on the others: before the reference
    # (approach and return: ruckig; events) and before the controller (the fades).
    assert h.ran[5] > 0.2 * h.cycles and h.ran[2] > 0 and h.ran[3] > 0, h.ran


def test_a_force_then_a_position_protocol_are_the_per_block_cycle_bit_for_bit(model):
    from protocols.generators import make_generator
    from protocols.library import LIBRARY_DIR, parse_protocol_text
    from rt.references.sequencer import Phase
    from rt.twin.environment import CompliantAnkle
    from rt.twin.twin import SimClock, Twin

    def protocol(name: str, *replace: tuple[str, str]):
        text = (LIBRARY_DIR / name).read_text()
        for old, new in replace:
            assert old in text
            text = text.replace(old, new)
        gen = make_generator(parse_protocol_text(text), dt=1e-3, kinematics=model.kin)
        assert gen.validate().ok
        return gen

    def sine():
        return protocol("sine_fz.yaml", ("cycles: 20", "cycles: 1"),
                        ("ramp_in_s: 2.0", "ramp_in_s: 0.3"),
                        ("ramp_out_s: 2.0", "ramp_out_s: 0.3"))

    proto_z = parse_protocol_text((LIBRARY_DIR / "sine_fz.yaml").read_text()).pose.z_m
    sensor_z = proto_z + model.description.sensor.offset_m[2]

    def build() -> PositionLoop:
        clock = SimClock()
        twin = Twin(model.description, CompliantAnkle(neutral_z_m=sensor_z, limb_weight_n=0.0),
                    clock=clock)
        twin.place(model.kin.ik(proto_z, 0.0, 0.0).q)
        return build_protocol_loop(sim_devices(twin, clock), sine(), RobotModel.load())

    h = _Lockstep(build)
    for _ in range(40):                                 # approach, tare, force play
        h.run(100)
        if h.f.reference.current_phase == Phase.PLAY:
            break
    assert h.f.reference.current_phase == Phase.PLAY
    h.run(1500)
    for _ in range(60):                                 # to its end and the return
        if not h.f.reference.busy:
            break
        h.run(100)
    assert not h.f.reference.busy
    rom = ("ankle_rom.yaml", ("repetitions: 3", "repetitions: 1"),
           ("sequence: [dorsi_plantar, inversion_eversion]", "sequence: [dorsi_plantar]"),
           ("dorsiflexion: 10.0", "dorsiflexion: 3.0"),
           ("plantarflexion: 10.0", "plantarflexion: 3.0"), ("hold_s: 1.0", "hold_s: 0.1"))
    h.both(lambda pl: pl.reference.request(protocol(*rom)))
    h.run(1500)
    assert h.f.reference.epoch == 2
    assert h.ran[5] > 0.3 * h.cycles and h.ran[2] + h.ran[3] > 0, h.ran


def test_the_fused_chain_refuses_what_it_does_not_cover(model):
    """A non-standard law in the controller slot keeps the per-block cycle (named), and the
    environment flag turns fusion off."""
    from rt.control.base import Controller

    class MyPid(type(__import__("rt.control.laws", fromlist=["Pid"]).Pid(model))):
        pass

    pl = build_sim_position_loop("paden_panja", duration_s=1.0, model=model)
    assert pl.graph.fused and pl.graph.segment.why_not == ""
    from rt.components.blocks import ControllerBlock
    law = MyPid(model)
    assert isinstance(law, Controller)
    pl.loop.swap("controller", ControllerBlock("controller_mine", law))
    pl.loop.run(cycles=5)
    assert "no fused path" in pl.graph.segment.why_not
    ran = []
    run = pl.graph.segment.run
    pl.graph.segment.run = lambda t, dt, idx: ran.append(run(t, dt, idx)) or ran[-1]
    pl.loop.run(cycles=5)
    assert ran == [0] * 5
    stats = pl.graph.stats().components
    assert all(stats[s].count > 0 for s in fused.CHAIN)


def test_the_environment_flag_turns_fusion_off(model, monkeypatch):
    monkeypatch.setenv(fused.ENV_FLAG, "0")
    pl = build_sim_position_loop("paden_panja", duration_s=1.0, model=model)
    assert pl.graph.segment is not None and not pl.graph.fused


class _Count(Component):
    """Ports: out ``y``: float64[1] — how many times its ``update`` ran."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.y = self.declare_output("y", Array(1))

    def update(self, t: float, dt: float) -> int:
        self.y.data[0] += 1.0
        return 0


class _Segment:
    """A fake fused segment over b, c, d: runs ``n`` of them (by hand), then ``pending``."""

    slots = ("b", "c", "d")

    def __init__(self) -> None:
        self.n = 0
        self.pending = None
        self.others_ns = 0
        self.prepared = 0

    def attach(self, graph, rings) -> None:
        self.graph = graph
        self.rings = rings

    def prepare(self) -> None:
        self.prepared += 1

    def prepare_swap(self, slot, new) -> None:
        pass

    def run(self, t: float, dt: float, idx: int) -> int:
        for s in self.slots[:self.n]:
            self.graph.component(s).y.data[0] += 10.0
        return self.n


def _counting_graph():
    """Five counting blocks a-e in a chain, configured."""
    b = GraphBuilder()
    for s in "abcde":
        b.add(_Count(s))
    g = b.build()
    g.configure()
    return g


def test_the_graph_runs_a_fused_segment_then_the_blocks_it_left():
    g = _counting_graph()
    seg = _Segment()
    with pytest.raises(ConfigurationError, match="not consecutive"):
        bad = _Segment()
        bad.slots = ("b", "d")
        g.fuse(bad)
    g.fuse(seg)
    g.start()
    assert g.fused and seg.prepared == 1

    def counts() -> list[float]:
        return [float(g.component(s).y.data[0]) for s in "abcde"]

    g.step(0.0, 1e-3)                             # the segment runs none: every block
    assert counts() == [1, 1, 1, 1, 1]
    seg.n = 2
    g.step(0.0, 1e-3)                             # b, c by the segment, d its own update
    assert counts() == [2, 11, 11, 2, 2]
    seg.n = 3

    def refuse(t: float, dt: float) -> int:
        raise RuntimeError("no FK there")

    seg.pending = refuse                          # d's completion raises: d's fault
    g.step(0.0, 1e-3)
    assert counts() == [3, 21, 21, 12, 3]
    assert [(f.slot, f.code, f.reason) for f in g.faults()] == [
        ("d", STATUS_EXCEPTION, "update raised RuntimeError: no FK there")]
    seg.pending = lambda t, dt: 10               # a status: the slot's fault, as update's
    g.step(0.0, 1e-3)
    assert g.faults()[-1].reason == "update returned status 10"
    g.fused = False                               # the per-block reference
    g.step(0.0, 1e-3)
    assert counts() == [5, 32, 32, 22, 5]
    assert all(g.stats().components[s].count == 5 for s in "abce")


def test_a_segment_that_raises_leaves_the_blocks_to_run():
    g = _counting_graph()
    seg = _Segment()

    def broken(t: float, dt: float, idx: int) -> int:
        raise RuntimeError("bug")

    seg.run = broken  # type: ignore[method-assign]
    g.fuse(seg)
    g.start()
    assert g.step(0.0, 1e-3) == 0
    assert [float(g.component(s).y.data[0]) for s in "abcde"] == [1, 1, 1, 1, 1]
    assert not g.fused and isinstance(g.last_exception, RuntimeError)
