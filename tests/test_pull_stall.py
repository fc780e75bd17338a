"""The supervisor's ``pulling`` check is stall-aware (issue 15).

In force control a measured Fz below 0 N for ``max_pull_s`` (20 ms) soft-stops: the platform
pulls the strapped foot. The check integrated the loop's dt, and a realtime loop's dt after a
host stall is the stall (``Loop``: dt = now − prev): one stall of 20 ms while the sensor read
its noise about 0 N counted as 20 ms of pull at once (what made ``tests/test_calibration_rt.py``
need a load retry for ``pulling``). A cycle now adds at most ``PULL_DT_PERIODS`` (2) periods:
a stall is one sample, a real pull is seen on every cycle and still trips after 20 ms. Both
supervisors alike (the compiled kernel and the interpreted reference); on the twin with an
injected clock (no wall-clock dependence).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from rt.engine import Component
from rt.model import RobotModel
from rt.model.dynamics import Payload
from rt.position_loop import PositionLoop, build_protocol_loop, sim_devices
from rt.safety import supervisor_kernel as sk
from rt.safety.events import Reaction
from rt.safety.fault_matrix import FORCE_HOLD_Z_M, ForceHold
from rt.safety.limits import PatientLimits, RobotLimits, effective
from rt.safety.supervisor import InterpretedSupervisor, Supervisor
from rt.twin.environment import patient_foot
from rt.twin.twin import SimClock, Twin

PERIOD_S = 1e-3
STALL_NS = 20_000_000          # a 20 ms host stall: as long as max_pull_s


@pytest.fixture(scope="module")
def model() -> RobotModel:
    return RobotModel.load()


def _pull_time(sup: Supervisor) -> float:
    return float(sup._mem[sk.M_PULL_TIME]) if sup.compiled else sup._pull_time  # type: ignore[attr-defined]


def _cycle(sup: Supervisor, t: float, dt: float, fz: float) -> Reaction:
    z3 = np.zeros(3)
    q = np.full(3, 0.2)
    return sup.check(t, dt, q, 0, z3, z3, True, 0.0, 0.0, 0.0, 0.0, q, z3, z3, abs(fz), False,
                     False, False, False, False, fz_n=fz)


@pytest.mark.parametrize("cls", [Supervisor, InterpretedSupervisor])
def test_a_stalled_cycle_adds_two_periods_of_pull_and_a_real_pull_trips_at_20_ms(cls) -> None:
    sup = cls(effective((0.0, 0.4), RobotLimits(), PatientLimits()), PERIOD_S)
    sup.force_control = True
    t = 0.0
    for _ in range(5):                                   # pushing: nothing counted
        t += PERIOD_S
        _cycle(sup, t, PERIOD_S, 3.0)
    # One stalled cycle (21 ms) that reads the noise below 0 N: 2 periods, no stop.
    t += 0.021
    assert _cycle(sup, t, 0.021, -0.3) == Reaction.NONE
    assert _pull_time(sup) == sk.PULL_DT_PERIODS * PERIOD_S
    t += PERIOD_S
    _cycle(sup, t, PERIOD_S, 0.4)                        # the pull ends: the count restarts
    assert _pull_time(sup) == 0.0
    # A real pull, seen every cycle: soft stop on its 20th cycle (20 ms), not before.
    for k in range(1, 21):
        t += PERIOD_S
        reaction = _cycle(sup, t, PERIOD_S, -40.0)
        assert reaction == (Reaction.SOFT_STOP if k == 20 else Reaction.NONE), k
    assert [e.cause for e in sup.log.snapshot() if e.kind == "fault"] == ["pulling"]
    # A cycle's dt between 1.5 and 2 periods (a late loop, not a stall) counts in full.
    sup2 = cls(effective((0.0, 0.4), RobotLimits(), PatientLimits()), PERIOD_S)
    sup2.force_control = True
    _cycle(sup2, 0.0018, 0.0018, -1.0)
    assert _pull_time(sup2) == 0.0018


def test_both_supervisors_count_a_stalled_pull_alike_bit_for_bit() -> None:
    """A stream of dt (late, stalled, NaN-free) and Fz crossing 0 N: the compiled and the
    interpreted pull counts are the same floats every cycle, and trip on the same cycle."""
    rng = np.random.default_rng(3)
    lim = effective((0.0, 0.4), RobotLimits(), PatientLimits())
    sups = [Supervisor(lim, PERIOD_S), InterpretedSupervisor(lim, PERIOD_S)]
    for s in sups:
        s.force_control = True
    t = 0.0
    tripped = []
    for k in range(3000):
        dt = float(rng.choice([PERIOD_S, 1.3e-3, 0.0017, 0.0021, 0.02, 0.05],
                              p=[0.8, 0.08, 0.04, 0.03, 0.03, 0.02]))
        fz = float(rng.normal(-0.05, 1.0)) if k < 2500 else -30.0
        t += dt
        r = [_cycle(s, t, dt, fz) for s in sups]
        assert r[0] == r[1], k
        a, b = (_pull_time(s) for s in sups)
        assert math.isclose(a, b, rel_tol=0.0, abs_tol=0.0), (k, a, b)
        if r[0] >= Reaction.SOFT_STOP and not tripped:
            tripped.append(k)
    # Only the real pull (from cycle 2500) trips: ≥ 20 ms of it at ≤ 2 periods a cycle.
    assert tripped and 2500 + 9 <= tripped[0] <= 2500 + 20, tripped


class _Stalls(Component):
    """Ports: none. Stalls the loop's injected clock by ``STALL_NS`` after every ``every``-th
    cycle (0: never) and records each cycle's dt and measured push (N)."""

    def __init__(self, clock: _FakeClock, holder: list):
        super().__init__("stalls")
        self.clock = clock
        self.every = 0
        self.k = 0
        self.holder = holder
        self.rows: list[tuple[float, float, float]] = []

    def update(self, t: float, dt: float) -> int:
        pl: PositionLoop = self.holder[0]
        self.rows.append((t, dt, -float(pl.graph.output("force.wrench")[2])))
        self.k += 1
        if self.every and self.k % self.every == 0:
            self.clock.now += STALL_NS
        return 0


class _FakeClock:
    """ns clock: 1 µs per read, the requested time per sleep (``tests/test_engine_loop``)."""

    def __init__(self) -> None:
        self.now = 1_000_000_000

    def __call__(self) -> int:
        self.now += 1_000
        return self.now

    def sleep(self, s: float) -> None:
        self.now += round(s * 1e9)


def test_a_host_stall_on_the_twin_is_not_a_pull_and_a_real_pull_still_stops(model) -> None:
    """A force hold of 0.3 N on the twin's strapped foot (no preload: the sensor reads its
    noise about it, 15 % of samples below 0 N) in a realtime loop on an injected clock that
    stalls 20 ms every 97 cycles: stalled cycles that read a pull (dt 21 ms ≥ ``max_pull_s``,
    each one a soft stop before) pass; then 565 kg land and the foot is really pulled: the
    soft stop comes after 20 ms of pull, at the same cycles as without the cap."""
    clock, fake, holder = SimClock(), _FakeClock(), []
    twin = Twin(None, patient_foot(model.kin, FORCE_HOLD_Z_M, 0.0, 0.0), seed=0, clock=clock)
    twin.place(model.kin.ik(FORCE_HOLD_Z_M, 0.0, 0.0).q)
    stalls = _Stalls(fake, holder)
    pl = build_protocol_loop(sim_devices(twin, clock),
                             ForceHold(model.kin, FORCE_HOLD_Z_M, 0.3, 60.0, PERIOD_S), model,
                             force_gains={"preload_n": 0.0}, extra_blocks=[stalls],
                             mode="realtime", clock=fake, sleep=fake.sleep, rt_priority=None,
                             lock_memory=False, switch_interval_s=None)
    holder.append(pl)
    pl.loop.run(cycles=1500)                             # approach, tare, into the hold
    start = len(stalls.rows)
    stalls.every = 97
    pl.loop.run(cycles=3000)
    rows = np.array(stalls.rows[start:])
    stalled = rows[rows[:, 1] > 0.01]
    assert len(stalled) >= 25 and float(stalled[:, 1].min()) >= 0.02
    # Stalled cycles that read a pull (measured: 5): each was a 21 ms pull to the old check.
    assert int((stalled[:, 2] < 0.0).sum()) >= 2, stalled[:, 2]
    assert float((rows[:, 2] < 0.0).mean()) > 0.05
    assert [e.cause for e in pl.events.snapshot() if e.kind == "fault"] == []
    # A real pull: 565 kg land (no stalls); the stop when 20 cycles of it have been seen.
    stalls.every = 0
    t_land = twin.plant.t
    twin.plant.set_payload(Payload(565.0, (0.0, 0.0, 0.10)))
    start = len(stalls.rows)
    pl.loop.run(cycles=300)
    faults = [e for e in pl.events.snapshot() if e.kind == "fault"]
    assert (faults[0].cause, faults[0].reaction) == ("pulling", Reaction.SOFT_STOP), faults
    rows = np.array(stalls.rows[start:])
    stop = int(np.argmax(rows[:, 0] >= faults[0].t - 1e-9))
    pulled = rows[:stop + 1, 2] < 0.0
    run = len(pulled) - int(np.argmin(pulled[::-1])) if not pulled.all() else len(pulled)
    assert pulled[-20:].all() and run in (20, 21), (run, faults[0].t - t_land)
