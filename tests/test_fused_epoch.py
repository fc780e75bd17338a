"""The fused cycle's fast-path guard as one epoch compare (``rt.epoch``, issue 16).

Every event that may change from outside the cycle what the general path decides from bumps
the process's epoch; the fast path compares one integer. Two layers of tests:

* each event's code bumps the epoch (no loop: quick, one per bump site);
* in lockstep with the per-block cycle (``test_fused_cycle._Lockstep``: every cycle compared
  byte for byte), each event arrives while the plan is in force, and the cycle right after it
  takes the general path; then the plan comes back. ``Graph.fused`` toggled off and on mid
  session with the plan in force is among them.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
from test_fused_cycle import _Lockstep, _short_sine

from rt.epoch import EPOCH
from rt.model import RobotModel
from rt.position_loop import PositionLoop, build_sim_position_loop, swap_controller


def _bumps(act: Callable[[], object]) -> bool:
    before = EPOCH.n
    act()
    return EPOCH.n != before


# ---------------------------------------------------------------- each site bumps (no loop)
def test_the_events_bump_the_epoch_and_a_steady_cycle_does_not():
    from rt.twin.twin import SimClock

    model = RobotModel.load()
    pl = build_sim_position_loop("paden_panja", duration_s=5.0, model=model)
    pl.loop.run(cycles=1100)                      # the approach, then play: steady
    seg = pl.graph.segment
    assert seg._plan_ok
    # The steady cycles bump nothing (else the fast path would never run).
    assert not _bumps(lambda: pl.loop.run(cycles=50)) and seg._plan_ok
    g, sup, ref, tw = pl.graph, pl.supervisor, pl.reference, pl.twin
    enc, force, stops = (g.component(s) for s in ("encoders", "force", "stops"))
    drv = g.component("drive")
    card_b = drv.cards[1]
    assert _bumps(lambda: sup.request_stop())
    assert _bumps(lambda: sup.request_estop("operator"))
    assert _bumps(lambda: sup.request_reset())
    assert _bumps(lambda: setattr(sup, "heartbeat_age", lambda: 0.0))
    assert _bumps(lambda: setattr(sup, "heartbeat_required", True))
    assert _bumps(lambda: setattr(sup, "heartbeat_required", False))
    assert _bumps(lambda: ref.request_abort())
    assert _bumps(lambda: ref.request(_short_sine(model)))
    assert _bumps(lambda: tw.faults.schedule("encoder_jump", tw.t + 10.0, axis=0, counts=2))
    assert _bumps(lambda: setattr(tw, "clock", SimClock()))
    assert _bumps(lambda: force.sensor.stop())
    assert _bumps(lambda: force.sensor.start())
    # A method replaced on a backend or its driver instance, and put back.
    for dev, name in ((enc.encoders, "read_positions_m"), (enc.encoders._driver,
                                                            "read_positions_m"),
                      (force.sensor, "_sample"), (stops.device, "read_array"),
                      (card_b, "write_volts"), (card_b._driver, "write_volts")):
        assert _bumps(lambda dev=dev, name=name: setattr(dev, name, getattr(dev, name))), name
        assert _bumps(lambda dev=dev, name=name: delattr(dev, name)), name
    # Any other attribute of those devices does not bump.
    assert not _bumps(lambda: setattr(enc.encoders, "note", 1))
    assert _bumps(lambda: g.component("recorder").stop())
    assert _bumps(lambda: g.component("recorder").start())
    assert _bumps(lambda: setattr(g, "fused", True))
    assert _bumps(lambda: g.restart_failed(also=("estimator",)))
    law = pl.controller
    assert _bumps(lambda: law.reset())
    assert _bumps(lambda: card_b.close())             # the spare card, closed


def test_the_adaptive_laws_new_gains_bump_the_epoch():
    pl = build_sim_position_loop("adaptive", duration_s=5.0, model=RobotModel.load())
    pl.loop.run(cycles=1100)                      # steady: its cycles bump nothing
    assert not _bumps(lambda: pl.loop.run(cycles=20))
    lam = pl.controller.gains.lambda_per_s
    # Applied in the next cycle (the loop's command queue): a new estimate array.
    assert _bumps(lambda: (pl.loop.set_params("controller", lambda_per_s=1.2 * lam),
                           pl.loop.run(cycles=1)))


# ---------------------------------------------------------------- in lockstep
class _Guarded(_Lockstep):
    """``_Lockstep`` that counts the fused loop's general-path cycles."""

    def __init__(self, build: Callable[[], PositionLoop]):
        super().__init__(build)
        seg = self.f.graph.segment
        general = seg._general
        self.general = 0

        def counted(t: float, dt: float, idx: int) -> int:
            self.general += 1
            return general(t, dt, idx)

        seg._general = counted

    def steady(self, most: int = 400) -> None:
        """Run (compared) until the plan is in force."""
        for _ in range(most):
            if self.f.graph.segment._plan_ok:
                return
            self.run(1)
        raise AssertionError(f"no plan after {most} cycles: {self.f.graph.segment.why_not!r}")

    def event(self, act: Callable[[PositionLoop], object], on_both: bool = True) -> None:
        """``act`` while the plan is in force: the next cycle takes the general path (and,
        compared, equals the per-block cycle)."""
        self.steady()
        before = self.general
        if on_both:
            self.both(act)
        else:
            act(self.f)
        self.run(1)
        assert self.general == before + 1, "the cycle after the event took the fast path"


@pytest.fixture(scope="module")
def h() -> _Guarded:
    h = _Guarded(lambda: build_sim_position_loop("paden_panja", duration_s=30.0,
                                                 model=RobotModel.load()))
    h.run(1100)                                          # the approach, then play
    assert h.planned > 100
    return h


def test_a_block_stopped_and_started_takes_the_general_path(h):
    h.event(lambda pl: pl.graph.component("recorder").stop())
    h.run(5)
    h.both(lambda pl: pl.graph.component("recorder").start())
    before = h.general
    h.run(1)
    assert h.general == before + 1
    h.steady()


def test_a_reset_estimator_takes_the_general_path(h):
    h.event(lambda pl: pl.graph.restart_failed(also=("estimator",)))
    h.run(20)


def test_a_backend_method_replaced_takes_the_general_path(h):
    def wrap(pl: PositionLoop) -> None:
        dev = pl.graph.component("stops").device
        dev.read_array = lambda out, dev=dev: type(dev).read_array(dev, out)

    h.event(wrap)
    h.run(5)
    assert h.f.graph.segment.why_not_sensor[2] != ""       # the stops' block reads it
    h.both(lambda pl: delattr(pl.graph.component("stops").device, "read_array"))
    h.steady()
    planned = h.planned
    h.run(20)
    assert h.planned == planned + 20


def test_the_force_sensor_stopped_and_started_takes_the_general_path(h):
    h.event(lambda pl: pl.graph.component("force").sensor.stop())
    h.run(3)
    h.both(lambda pl: pl.graph.component("force").sensor.start())
    h.steady()


def test_a_scheduled_twin_fault_takes_the_general_path(h):
    h.event(lambda pl: pl.twin.faults.schedule("encoder_jump", pl.twin.t + 60.0, axis=2,
                                               counts=4))
    h.run(5)
    h.both(lambda pl: pl.twin.faults.faults.clear())
    h.steady()


def test_no_plan_is_made_while_a_twin_fault_is_scheduled(h):
    """Why the fast path does not look at the twin's faults (approach9 dropped that check):
    scheduling one bumps the epoch (the cycle after it is general), and while any is in the
    list no general cycle makes a plan (the encoders' stage is the block's: their counts may
    be delayed), so no cycle takes the fast path while it is there. Here a latency fault
    active from the next millisecond for 50 ms, compared with the per-block cycle byte for
    byte, then the plan back once it is cleared."""
    seg = h.f.graph.segment
    h.event(lambda pl: pl.twin.faults.schedule("latency", pl.twin.t + 1e-3, pl.twin.t + 0.05,
                                               seconds=0.003))
    planned = h.planned
    for _ in range(80):
        h.run(1)
        assert not seg._plan_ok and h.planned == planned
        assert seg.why_not_sensor[0] != ""
    assert h.f.supervisor.latched() == []
    h.both(lambda pl: pl.twin.faults.clear())
    h.steady()


def test_the_twin_clock_set_again_takes_the_general_path(h):
    h.event(lambda pl: setattr(pl.twin, "clock", pl.twin.clock))


def test_graph_fused_toggled_mid_session_takes_the_general_path(h):
    """``Graph.fused`` off for some cycles (the fused loop runs every block then) and on
    again with the plan in force; and off and on between two cycles."""
    g = h.f.graph
    h.steady()
    before, planned = h.general, h.planned
    g.fused = False
    h.expect_fused = False
    h.run(10)                                    # every block, compared
    assert h.general == before and h.planned == planned
    g.fused = True
    h.expect_fused = True
    h.run(1)
    assert h.general == before + 1
    h.event(lambda pl: (setattr(pl.graph, "fused", False), setattr(pl.graph, "fused", True)),
            on_both=False)
    h.steady()


def test_the_adaptive_laws_new_gains_take_the_general_path(h):
    h.both(lambda pl: swap_controller(pl, "adaptive"))
    h.run(2900)                       # the swap's fade (to 1e-6 of the offset: 2.8 s), then fused
    lam = h.f.controller.gains.lambda_per_s
    h.event(lambda pl: pl.loop.set_params("controller", lambda_per_s=1.1 * lam))
    h.run(20)


def test_the_sequencers_and_supervisors_requests_take_the_general_path(h):
    h.event(lambda pl: setattr(pl.supervisor, "heartbeat_age", lambda: 0.0))
    h.event(lambda pl: setattr(pl.supervisor, "heartbeat_required", True))
    h.run(5)
    assert not h.f.graph.segment._plan_ok                # its age is checked every cycle
    h.both(lambda pl: setattr(pl.supervisor, "heartbeat_required", False))
    h.event(lambda pl: pl.supervisor.request_stop())
    h.run(100)
    assert h.f.supervisor.latched() != []
    h.event(lambda pl: pl.supervisor.request_reset())
    h.run(50)
    h.event(lambda pl: pl.reference.request_abort())
    for _ in range(100):                                 # the return, then rest
        if not h.f.reference.busy:
            break
        h.run(100)
    h.event(lambda pl: pl.supervisor.request_estop("operator"))
    h.run(30)
    assert h.f.supervisor.latched() != []
    h.both(lambda pl: pl.supervisor.request_reset())     # drives off: no plan until then
    h.steady(1500)                                       # the brakes, enabled again
    assert np.all(h.f.graph.component("drive").failed.data == 0.0)
