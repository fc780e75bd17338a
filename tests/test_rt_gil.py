"""The RT loop and the threads it shares the GIL with (issues 14, 16; branch rtloop3).

* the loop's GIL guard: it wakes ``gil_guard_us`` before its deadline, and waits the rest in C
  *with* the GIL, the switch interval long while it is awake and short while it sleeps;
* ``sleep_holding_gil`` really keeps every other Python thread out;
* a deferred IPC reply is answered on its notification, not by polling every millisecond;
* a prepared session's arrays travel through shared memory, unchanged and uncopied.
"""
from __future__ import annotations

import mmap
import os
import sys
import threading
import time
from typing import Any

import numpy as np
import pytest

from rt.engine import Component, GraphBuilder, Loop
from rt.engine.rt_hygiene import sleep_holding_gil
from rt.errors import ConfigurationError, InputError

NO_RT = {"rt_priority": None, "lock_memory": False, "switch_interval_s": None}


class FakeClock:
    """ns clock: 1 µs per read, the requested time per sleep (both kinds)."""

    def __init__(self) -> None:
        self.now = 1_000_000_000

    def __call__(self) -> int:
        self.now += 1_000
        return self.now


class Recorder(Component):
    def __init__(self, clock: FakeClock, seen: list[tuple[int, float]]) -> None:
        super().__init__("probe")
        self.clock, self.seen = clock, seen

    def update(self, t: float, dt: float) -> int:
        self.seen.append((self.clock.now, sys.getswitchinterval()))
        return 0


def test_the_guard_sleeps_with_the_gil_released_until_the_guard_then_holds_it() -> None:
    """Per cycle: a GIL-releasing sleep until 400 µs before the deadline (short interval),
    then a GIL-holding sleep until the spin (the hold interval), and the cycle starts at its
    deadline; 1 µs per clock read is the fake clock's only lateness."""
    clock = FakeClock()
    sleeps: list[tuple[str, int, int, float]] = []     # (kind, start ns, length ns, interval)

    def sleep(s: float) -> None:
        sleeps.append(("released", clock.now, round(s * 1e9), sys.getswitchinterval()))
        clock.now += round(s * 1e9)

    def hold_sleep(ns: int) -> None:
        sleeps.append(("held", clock.now, ns, sys.getswitchinterval()))
        clock.now += ns

    seen: list[tuple[int, float]] = []
    b = GraphBuilder()
    b.add(Recorder(clock, seen))
    g = b.build()
    before = sys.getswitchinterval()
    try:
        sys.setswitchinterval(0.0002)
        loop = Loop(g, rate_hz=1000.0, mode="realtime", clock=clock, sleep=sleep,
                    hold_sleep=hold_sleep, spin_us=150.0, gil_hold_s=0.001,
                    gil_guard_us=400.0, **NO_RT)
        loop.run(cycles=20)
        assert sys.getswitchinterval() == pytest.approx(0.0002, abs=2e-6)
    finally:
        sys.setswitchinterval(before)
    assert len(seen) == 20
    # Cycles after a sleep hold the GIL; the first one, run at once (no sleep, no room for
    # the guard), shares it by the short interval as a late cycle does.
    assert seen[0][1] == pytest.approx(0.0002, abs=2e-6)
    assert all(iv == pytest.approx(0.001, abs=2e-6) for _, iv in seen[1:])
    released = [s for s in sleeps if s[0] == "released"]
    held = [s for s in sleeps if s[0] == "held"]
    assert len(released) == len(held) == 19                  # the first cycle is at once
    assert all(iv == pytest.approx(0.0002, abs=2e-6) for *_, iv in released)
    assert all(iv == pytest.approx(0.001, abs=2e-6) for *_, iv in held)
    for (_, r0, rn, _), (_, h0, hn, _) in zip(released, held, strict=True):
        deadline = r0 + rn + 400_000 - 1_000                    # the read before the sleep
        assert h0 + hn == pytest.approx(deadline - 150_000, abs=3_000)
    lat = loop.stats().lateness
    assert loop.stats().misses == 0 and lat.max_all_us < 10.0


def test_the_guard_is_refused_without_the_hold_and_out_of_range() -> None:
    b = GraphBuilder()
    b.add(Recorder(FakeClock(), []))
    g = b.build()
    with pytest.raises(ConfigurationError, match="gil_guard_us needs gil_hold_s"):
        Loop(g, gil_guard_us=400.0, **NO_RT)
    with pytest.raises(ConfigurationError, match="gil_guard_us must be in"):
        Loop(g, gil_hold_s=0.001, gil_guard_us=900.0, **NO_RT)


def test_sleep_holding_gil_keeps_other_python_threads_out() -> None:
    """A thread stamping the clock in Python, as fast as it can, is stopped for the whole of
    a 100 ms ``sleep_holding_gil`` (the GIL is not released around the C call): its stamps
    show a gap of at least the sleep. Load-proof: a loaded machine can only add gaps, and a
    sleep that released the GIL would leave none of that length to a thread that has a CPU
    (the check that it ran at all is that it stamped before and after)."""
    stamps: list[int] = []
    stop = threading.Event()
    clock = time.perf_counter_ns

    def stamp() -> None:
        while not stop.is_set():
            stamps.append(clock())
    t = threading.Thread(target=stamp, daemon=True)
    before = sys.getswitchinterval()
    sys.setswitchinterval(0.0002)
    try:
        t.start()
        while len(stamps) < 1000:
            time.sleep(0.001)
        a = clock()
        sleep_holding_gil(100_000_000)
        b = clock()
        end = clock() + 5_000_000_000          # only a guard against a hang
        while clock() < end and (not stamps or stamps[-1] <= b):
            time.sleep(0.001)
    finally:
        stop.set()
        t.join(5.0)
        sys.setswitchinterval(before)
    assert b - a >= 99_000_000
    around = np.asarray([x for x in stamps if a - 10**9 <= x <= b + 10**9], dtype=np.int64)
    assert around.min() < a and around.max() > b          # it ran before and after
    assert np.diff(around).max() >= 99_000_000


def test_sleep_holding_gil_sleeps_about_as_long_as_asked() -> None:
    t0 = time.perf_counter_ns()
    sleep_holding_gil(3_000_000)
    assert time.perf_counter_ns() - t0 >= 2_900_000
    sleep_holding_gil(0)
    sleep_holding_gil(-5)


# ------------------------------------------------------------------------------ IPC
def test_a_notified_deferred_is_answered_at_once_and_not_polled_every_millisecond() -> None:
    """A deferred reply with a 30 s poll interval: the server polls it when it arrives and
    when notified, not in between; the client has its reply right after the notification."""
    from rt.ipc.client import RtClient
    from rt.ipc.server import HANDLER_METHODS, Deferred, RtServer

    polls = [0]
    outcome: dict[str, Any] = {}

    def poll() -> dict[str, Any] | None:
        polls[0] += 1
        return outcome.get("reply")
    deferred = Deferred(poll, timeout_s=60.0, what="session_start", poll_interval_s=30.0)

    class Handler:
        def __getattr__(self, cmd: str) -> Any:
            if cmd not in HANDLER_METHODS:
                raise AttributeError(cmd)
            return lambda client, **kw: deferred if cmd == "reset" else {}
    any_port = "tcp://127.0.0.1:*"
    with RtServer(Handler(), any_port, any_port) as srv, \
            RtClient(srv.endpoint, client_id="owner", timeout_s=20.0) as owner:
        result: dict[str, Any] = {}
        t = threading.Thread(target=lambda: result.update(owner.reset([1])))
        t.start()
        end = time.monotonic() + 30.0       # only a guard against a hang
        while polls[0] < 1 and time.monotonic() < end:
            time.sleep(0.01)
        time.sleep(0.3)                                   # 300 polls at the old 1 ms
        assert polls[0] == 1 and t.is_alive()
        outcome["reply"] = {"reset": True}
        deferred.notify()
        t.join(timeout=10.0)
        assert result == {"reset": True} and polls[0] == 2


def test_the_deferred_poll_interval_is_checked() -> None:
    from rt.ipc.server import Deferred

    with pytest.raises(ConfigurationError, match="poll_interval_s"):
        Deferred(lambda: None, timeout_s=1.0, what="x", poll_interval_s=0.0)


# ------------------------------------------------------------------------------ transfer
def test_a_prepared_generator_travels_through_shared_memory_unchanged() -> None:
    """The sine's reference table (> 64 KB) crosses as a view of a mapped segment whose name
    is gone once mapped, the kinematics as a name the receiver resolves to its own (refused,
    the segment removed, when it has none); small arrays stay inside the pickle; every
    sample is identical."""
    from protocols.generators import make_generator
    from protocols.library import LIBRARY_DIR
    from protocols.rt_session import SHARED_MIN_BYTES, from_shared, protocol_document, to_shared
    from protocols.schema import validate_protocol_data
    from rt.model import RobotModel

    model = RobotModel.load()
    doc = protocol_document(LIBRARY_DIR / "sine_fz.yaml")
    doc.update(cycles=5, ramp_in_s=1.0, ramp_out_s=1.0)
    gen = make_generator(validate_protocol_data(doc, "test"), dt=1e-3, kinematics=model.kin,
                         patient_weight_kg=70.0, base_dir=LIBRARY_DIR)
    assert gen.validate().ok
    big = [k for k, v in vars(gen).items()
           if isinstance(v, np.ndarray) and v.nbytes >= SHARED_MIN_BYTES]
    assert big, "the sine should carry a reference table worth sharing"
    payload = to_shared(gen, references={"kinematics": model.kin})
    assert payload.segment is not None and payload.references == ("kinematics",)
    assert os.path.exists(f"/dev/shm/{payload.segment.lstrip('/')}")
    assert len(payload.pickled) < 64 * 1024           # the table is not in the pickle
    with pytest.raises(InputError, match="kinematics"):     # the receiver must supply it
        from_shared(to_shared(gen, references={"kinematics": model.kin}))
    back = from_shared(payload, {"kinematics": model.kin})
    assert back.kinematics is model.kin                  # by reference, not rebuilt
    assert not os.path.exists(f"/dev/shm/{payload.segment.lstrip('/')}")
    for k in big:
        arr = getattr(back, k)
        np.testing.assert_array_equal(arr, getattr(gen, k))
        base = arr
        while isinstance(base, np.ndarray) and base.base is not None:
            base = base.base
        assert isinstance(base, memoryview) and isinstance(base.obj, mmap.mmap)
    want, got = gen.samples(), back.samples()
    assert want.keys() == got.keys()
    for k in want:
        np.testing.assert_array_equal(got[k], want[k])
    small = to_shared({"x": np.ones(3)})
    assert small.segment is None and from_shared(small)["x"].tolist() == [1.0, 1.0, 1.0]


# ------------------------------------------------------------------------------ cycle signal
def test_a_cycle_signal_fires_every_n_cycles_and_stops_when_closed() -> None:
    """Fired after every 4th cycle: a waiter wakes once per 4 cycles (a wait clears it), not
    at all once closed; the loop keeps running without it."""
    fired: list[int] = []
    b = GraphBuilder()
    loop_ref: list[Loop] = []

    class Check(Component):
        def update(self, t: float, dt: float) -> int:
            loop = loop_ref[0]
            if loop.cycles and sig.wait(0.0):
                fired.append(loop.cycles)
            return 0
    b.add(Check("check"))
    loop = Loop(b.build(), rate_hz=1000.0, mode="fast", **NO_RT)
    loop_ref.append(loop)
    sig = loop.cycle_signal(4)
    loop.run(cycles=20)
    assert fired == [4, 8, 12, 16]                # seen at the start of the next cycle
    sig.close()
    assert not sig.wait(0.0)
    loop.run(cycles=8)
    assert fired == [4, 8, 12, 16] and loop.cycles == 28
    with pytest.raises(ConfigurationError, match="every"):
        loop.cycle_signal(0)
