"""The twin as a separate rig process: shared-memory layout and seqlock, the 'twin_shm'
backends, the amplifier watchdog, and the drives dropping to 0 V when the RT process is
SIGKILLed (DESIGN 3: "If the RT process dies, the actuator watchdog ... drops the drive
outputs to zero").

Rig processes are started through the CLI code (``python -m rt.twin.rig_cli rig``) and always
stopped (SIGTERM, then SIGKILL) and their segments removed in ``finally`` blocks. Timing bounds
allow for host stalls of a few ms (PLATFORM.md); the measured figures are printed (``-s``).
"""
from __future__ import annotations

import itertools
import json
import math
import os
import selectors
import signal
import subprocess
import sys
import threading
import time
import uuid
from multiprocessing import shared_memory
from pathlib import Path

import numpy as np
import pytest

from rt.devices import registry
from rt.devices.interfaces import DigitalInputState, Wrench
from rt.drivers.pci1720 import code_to_volts, volts_to_code
from rt.drivers.pcl833 import MIDPOINT
from rt.errors import HardwareError, InputError
from rt.twin import shm as layout
from rt.twin.shm_backends import ShmActuators, ShmEncoders, ShmRig

REPO = Path(__file__).resolve().parents[1]
WATCHDOG_S = 0.02
RIG_PERIOD_S = 0.001
#: Host stalls of 1-5 ms happen on these VMs (PLATFORM.md); timing bounds allow this much.
JITTER_S = 0.010
#: Liveness limit for the handles of tests that are not about liveness: the backends' 50 ms
#: default trips when a loaded machine delays the rig process (it once did, at 81 ms).
RIG_TIMEOUT_S = 10.0


# --------------------------------------------------------------------------- helpers
def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    return env


def _unique_name() -> str:
    return f"talus-test-{os.getpid()}-{uuid.uuid4().hex[:8]}"


def _read_line(proc: subprocess.Popen, timeout: float) -> str:
    sel = selectors.DefaultSelector()
    sel.register(proc.stdout, selectors.EVENT_READ)
    try:
        if not sel.select(timeout):
            raise AssertionError("no output from the subprocess within the timeout")
        return proc.stdout.readline()
    finally:
        sel.close()


def _start_rig(name: str, *extra: str) -> subprocess.Popen:
    proc = subprocess.Popen(
        [sys.executable, "-m", "rt.twin.rig_cli", "rig", "--shm", name, *extra],
        cwd=REPO, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = _read_line(proc, 30.0)
        ready = json.loads(line) if line else {}
        assert ready.get("rig", {}).get("shm") == name, (line, proc.stderr.read())
        assert ready["rig"]["pid"] == proc.pid
    except BaseException:
        _kill(proc)
        raise
    return proc


def _stop_rig(proc: subprocess.Popen) -> tuple[int, str, str]:
    """SIGTERM, wait; returns (exit code, stdout rest, stderr)."""
    proc.send_signal(signal.SIGTERM)
    try:
        out, err = proc.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        _kill(proc)
        raise AssertionError("the rig did not exit within 10 s of SIGTERM")
    return proc.returncode, out, err


def _kill(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.kill()
    try:
        proc.communicate(timeout=30)
    except (subprocess.TimeoutExpired, ValueError):
        pass


def _remove_segment(name: str) -> None:
    try:
        os.unlink(f"/dev/shm/{name}")
    except FileNotFoundError:
        pass


def _wait_for(predicate, timeout: float, what: str, poll_s: float = 0.0005):
    # A hang guard, not a speed requirement: a loaded machine gets at least 30 s.
    timeout = max(timeout, 30.0)
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(poll_s)


def _quantized(volts) -> tuple[float, float, float]:
    """What the amplifiers receive for ``volts`` (V): the PCI-1720's 12-bit ±10 V codes."""
    return tuple(code_to_volts(volts_to_code(float(v))) for v in volts)  # type: ignore


class Feeder(threading.Thread):
    """Feeds the watchdog every ``period_s`` (the RT loop's job) until stopped."""

    def __init__(self, rig: ShmRig, period_s: float = 0.001):
        super().__init__(daemon=True)
        self.rig = rig
        self.period_s = period_s
        self.last_feed = math.nan
        self.feeds = 0
        self._halt = threading.Event()

    def run(self) -> None:
        nxt = time.monotonic()
        while not self._halt.is_set():
            self.rig.feed_watchdog()
            self.last_feed = time.monotonic()
            self.feeds += 1
            nxt += self.period_s
            delay = nxt - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            else:
                nxt = time.monotonic()

    def stop(self) -> float:
        """Stop feeding; returns the monotonic time of the last feed (s)."""
        self._halt.set()
        self.join(5.0)
        return self.last_feed


# --------------------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def hold_volts() -> np.ndarray:
    """Amplifier commands (V) that hold the twin at home against gravity."""
    from rt.twin.serve import holding_volts
    from rt.twin.twin import Twin

    return holding_volts(Twin())


@pytest.fixture(scope="module")
def rig_name():
    """A rig process (free environment) shared by the tests that only need one running."""
    name = _unique_name()
    proc = _start_rig(name)
    try:
        yield name
    finally:
        code, _out, err = _stop_rig(proc) if proc.poll() is None else (proc.returncode, "", "")
        leaked = os.path.exists(f"/dev/shm/{name}")
        _remove_segment(name)
        assert code == 0, err
        assert not leaked, "the rig left its shared memory behind"


# --------------------------------------------------------------------------- layout, seqlock
def test_layout_fields_are_aligned_disjoint_and_inside_their_blocks():
    blocks = ((layout.HEADER_FIELDS, layout.HEADER_OFFSET, layout.HEADER_SIZE, 0),
              (layout.SENSOR_FIELDS, layout.SENSOR_OFFSET, layout.SENSOR_SIZE, 8),
              (layout.COMMAND_FIELDS, layout.COMMAND_OFFSET, layout.COMMAND_SIZE, 8))
    end = 0
    for specs, offset, size, first in blocks:
        assert offset % 64 == 0 and offset == end
        end = offset + size
        used = []
        for name, off, dtype, count in specs:
            nbytes = np.dtype(dtype).itemsize * count
            assert off % 8 == 0, name
            assert first <= off and off + nbytes <= size, name
            used.append((off, off + nbytes, name))
        used.sort()
        for (a0, a1, a), (b0, b1, b) in itertools.pairwise(used):
            assert a1 <= b0, f"{a} overlaps {b}"
    assert end == layout.TOTAL_SIZE
    # The module docstring documents every field at its offset.
    doc_lines = layout.__doc__.splitlines()
    for specs, prefix in ((layout.HEADER_FIELDS, ""), (layout.SENSOR_FIELDS, "+"),
                          (layout.COMMAND_FIELDS, "+")):
        for name, off, _dtype, _count in specs:
            assert any(line.split()[:1] == [f"{prefix}{off}"] and name in line.split()
                       for line in doc_lines), f"{name} at {prefix}{off} is not documented"


_TEAR_WRITER = r"""
import sys, time
from rt.twin import shm as layout
seg = layout.attach_segment(sys.argv[1])
block = seg.sensors
s = block.local
print("go", flush=True)
end = time.monotonic() + float(sys.argv[2])
k = 0
while time.monotonic() < end:
    k += 1
    s.heartbeat[0] = k
    s.counts[:] = k
    s.wrench[:] = k
    s.amp_volts[:] = k
    s.feed_seen_monotonic_s[0] = k
    block.publish()
seg.close()
print(k, flush=True)
"""


def test_seqlock_snapshots_never_tear_across_processes():
    """A writer process publishes blocks whose fields all hold the same number; every
    snapshot the reader accepts must be uniform."""
    name = _unique_name()
    seg = layout.create_segment(name)
    writer = None
    try:
        seg.header.version[0] = layout.LAYOUT_VERSION
        seg.header.magic[:] = tuple(layout.MAGIC)
        writer = subprocess.Popen([sys.executable, "-c", _TEAR_WRITER, name, "1.0"], cwd=REPO,
                                  env=_env(), stdout=subprocess.PIPE, text=True)
        assert _read_line(writer, 60.0).strip() == "go"
        block = seg.sensors
        s = block.local
        good = distinct = 0
        last = -1
        while writer.poll() is None:
            if block.read():
                k = int(s.heartbeat[0])
                assert (s.counts == k).all() and (s.wrench == k).all(), k
                assert (s.amp_volts == k).all() and s.feed_seen_monotonic_s[0] == k, k
                good += 1
                distinct += k != last
                last = k
        writes = int(writer.stdout.read().split()[-1])
    finally:
        if writer is not None:
            _kill(writer)
        seg.close()
    assert not os.path.exists(f"/dev/shm/{name}")
    print(f"\nseqlock: {writes} writes, {good} consistent reads ({distinct} distinct)")
    assert good > 1000 and distinct > 1     # overlap depends on the host; tearing does not


def test_a_writer_killed_mid_write_neither_hangs_readers_nor_blocks_the_next_writer():
    name = _unique_name()
    seg = layout.create_segment(name)
    try:
        seg.header.version[0] = layout.LAYOUT_VERSION
        seg.header.magic[:] = tuple(layout.MAGIC)
        cmd = seg.commands
        cmd.begin_write()                       # a writer that never finishes
        assert cmd.sequence & 1
        assert cmd.read(timeout_s=0.002) is False      # returns (a hang would hang the test)
        assert cmd.failed_reads == 1
        with ShmRig(name) as rig:
            rig.feed_watchdog()                 # repairs the odd word, then writes
        assert cmd.sequence % 2 == 0
        assert cmd.read() and int(cmd.local.feed[0]) == 1
    finally:
        seg.close()


# --------------------------------------------------------------------------- watchdog logic
def test_watchdog_logic_step_by_step(hold_volts):
    """RigProcess driven with explicit times: waiting -> fed -> tripped (latched) -> re-armed,
    and physics sees 0 V in the period the watchdog trips."""
    from rt.twin.rig import RigProcess

    name = _unique_name()
    rig = RigProcess(name, "free", seed=1, watchdog_timeout_s=WATCHDOG_S)
    try:
        handle = ShmRig(name)
        card = ShmActuators(handle, 0)
        twin = rig.twin
        t = rig.epoch_s

        def step(dt: float = RIG_PERIOD_S):
            nonlocal t
            t += dt
            rig.step(t)
            return handle.amplifier_state()

        card.enable()
        card.write_volts(hold_volts)
        st = step()
        assert st.watchdog == "waiting" and st.volts == (0.0, 0.0, 0.0)
        assert not st.drives_enabled and not twin.drives_enabled

        handle.feed_watchdog()
        st = step()
        expected = _quantized(hold_volts)
        assert st.watchdog == "fed" and st.drives_enabled and st.volts == expected
        assert tuple(twin.amp_volts) == expected
        for _ in range(5):
            handle.feed_watchdog()
            step()
        fed_at = t
        # Starved: still on just before the timeout, off in the first period past it.
        assert step(WATCHDOG_S - RIG_PERIOD_S / 2).watchdog == "fed"
        st = step(RIG_PERIOD_S)
        assert t - fed_at > WATCHDOG_S
        assert st.tripped and st.watchdog == "tripped" and st.volts == (0.0, 0.0, 0.0)
        assert not st.drives_enabled and tuple(twin.amp_volts) == (0.0, 0.0, 0.0)
        assert st.trip_monotonic_s == t and st.trips == 1
        assert math.isclose(st.trip_rig_time_s, t - rig.epoch_s)
        assert twin.t == pytest.approx(t - rig.epoch_s)

        handle.rearm()                           # not fed: ignored, not remembered
        assert step().tripped
        handle.feed_watchdog()                   # fed again, but latched until a re-arm
        assert step().tripped
        handle.feed_watchdog()
        handle.rearm()
        st = step()
        assert st.watchdog == "fed" and st.volts == expected and st.trips == 1

        # New codes take effect at their write instant: the physics is advanced to the
        # write's time stamp with the old inputs first, then to now with the new ones.
        handle.feed_watchdog()
        time.sleep(max(0.0, t - time.monotonic()) + 0.002)   # the write comes after rig time t
        card.write_volts([0.0, 0.0, 0.0])
        stamp = float(rig.seg.commands.shared.write_monotonic_s[0])
        assert stamp > t
        t = stamp + RIG_PERIOD_S / 2
        synced = []
        sync = twin.sync
        twin.sync = lambda t_s=None: (synced.append((t_s, tuple(twin.amp_volts))), sync(t_s))
        try:
            rig.step(t)
        finally:
            del twin.sync
        assert synced[0] == (pytest.approx(stamp - rig.epoch_s), expected)
        assert synced[-1][0] == pytest.approx(t - rig.epoch_s)
        assert handle.amplifier_state().volts == _quantized([0.0, 0.0, 0.0])
        card.close()
        card.close()
        handle.close()
        handle.close()
    finally:
        rig.close()
    rig.close()
    assert not os.path.exists(f"/dev/shm/{name}")


def test_applied_volts_answer_only_readings_newer_than_the_last_command(hold_volts):
    """The loop's amplifier monitor over the rig: a snapshot the rig published before it read
    this cycle's commands is no reading (None), so a late rig process is never taken for a
    DAC channel that disagrees with its command; once read, the applied volts are answered."""
    from rt.twin.rig import RigProcess

    name = _unique_name()
    rig = RigProcess(name, "free", seed=1, watchdog_timeout_s=WATCHDOG_S)
    try:
        handle = ShmRig(name, RIG_TIMEOUT_S)
        card = ShmActuators(handle, 0)
        t = rig.epoch_s
        card.enable()
        card.write_volts(hold_volts)
        handle.feed_watchdog()                   # the loop's cycle: write, then feed
        assert handle.applied_volts() is None    # the rig has not run since
        t += RIG_PERIOD_S
        rig.step(t)
        assert handle.applied_volts() == _quantized(hold_volts)
        card.write_volts([0.0, 0.0, 0.0])        # the next cycle, the rig late for it
        handle.feed_watchdog()
        assert handle.applied_volts() is None
        t += RIG_PERIOD_S
        rig.step(t)
        assert handle.applied_volts() == _quantized([0.0, 0.0, 0.0])
        card.close()
        handle.close()
    finally:
        rig.close()


def test_a_tripped_watchdog_faults_the_feed_block_and_its_restart_rearms_it(hold_volts):
    """The loop's WatchdogFeed over the rig: a stall past the watchdog's timeout faults the
    block (the supervisor then hard-stops naming it) and the drive monitor reads nothing (no
    DAC channel is blamed); restarting the block (the operator's reset) re-arms the watchdog."""
    from rt.position_loop import WatchdogFeed
    from rt.twin.rig import RigProcess

    name = _unique_name()
    rig = RigProcess(name, "free", seed=1, watchdog_timeout_s=WATCHDOG_S)
    try:
        handle = ShmRig(name, RIG_TIMEOUT_S)
        card = ShmActuators(handle, 0)
        block = WatchdogFeed("watchdog", handle.feed_watchdog, handle.watchdog_tripped,
                             handle.rearm)
        t = rig.epoch_s
        card.enable()
        card.write_volts(hold_volts)
        assert block.update(0.0, 0.001) == 0
        t += RIG_PERIOD_S
        rig.step(t)
        assert not handle.watchdog_tripped() and handle.applied_volts() is not None
        t += WATCHDOG_S + RIG_PERIOD_S                  # the loop stalls past the timeout
        rig.step(t)
        assert handle.watchdog_tripped()
        with pytest.raises(HardwareError, match="watchdog dropped the drives"):
            block.update(0.03, 0.03)
        t += RIG_PERIOD_S
        rig.step(t)
        assert handle.applied_volts() is None           # the watchdog's doing, not a channel's
        block.on_start()                                # the restart: feed, then re-arm
        assert not handle.watchdog_tripped()            # the re-arm is on its way: no verdict
        t += RIG_PERIOD_S
        rig.step(t)
        assert not handle.watchdog_tripped()
        assert block.update(0.04, 0.001) == 0
        t += RIG_PERIOD_S
        rig.step(t)
        assert handle.applied_volts() == _quantized(hold_volts)
        card.close()
        handle.close()
    finally:
        rig.close()


def test_run_rig_serves_until_its_stop_event_and_unlinks():
    """``run_rig`` as a multiprocessing-style target (here in a thread, to stay fast)."""
    from rt.twin.rig import run_rig

    name = _unique_name()
    ready, stop = threading.Event(), threading.Event()
    result = {}
    thread = threading.Thread(target=lambda: result.setdefault("summary", run_rig(
        name, "free", seed=2, stop=stop, on_ready=lambda rig: ready.set())), daemon=True)
    thread.start()
    try:
        assert ready.wait(30.0)
        with ShmRig(name) as rig:
            h = rig.heartbeat()
            _wait_for(lambda: rig.heartbeat() > h + 5, 2.0, "rig periods")
            assert rig.amplifier_state().watchdog == "waiting"
    finally:
        stop.set()
        thread.join(10.0)
        leaked = os.path.exists(f"/dev/shm/{name}")
        _remove_segment(name)
    assert not thread.is_alive() and not leaked
    summary = result["summary"]
    assert summary.periods > 5 and summary.error is None and summary.trips == 0


# --------------------------------------------------------------------------- over a rig process
def test_encoders_force_sensor_and_inputs_through_a_rig_process(rig_name):
    with ShmRig(rig_name, RIG_TIMEOUT_S) as rig:
        assert rig.rig_state == "running" and rig.period_s == pytest.approx(RIG_PERIOD_S)
        assert rig.watchdog_timeout_s == pytest.approx(WATCHDOG_S)
        enc = registry.create("encoders", "twin_shm", rig=rig)
        q = np.zeros(3)
        enc.read_positions_m(q)
        # The twin's home is 0.2 m per slider; unpowered it is held by stiction.
        assert np.allclose(q, 0.2, atol=1e-3), q
        counts = enc.read_counts()
        assert all(abs(c - (MIDPOINT + 10000)) < 50 for c in counts), counts
        enc.reset()
        enc.read_positions_m(q)
        assert np.allclose(q, 0.0, atol=1e-4), q
        enc.close()
        enc.close()

        ft = registry.create("force_torque", "twin_shm", rig=rig_name,   # own handle
                             rig_timeout_s=RIG_TIMEOUT_S)
        ft.start()
        w = Wrench()
        t_asked = time.monotonic()
        _wait_for(lambda: not ft.read(w).stale, 30.0, "a fresh ATI sample")
        assert not w.stale and all(math.isfinite(v) for v in w.as_tuple())
        assert abs(w.fz) < 5.0 and w.sequence > 0
        # Stamped on this process's monotonic clock (not rig-relative time, which would be
        # seconds since the rig started, far below t_asked).
        assert t_asked - 1.0 < w.t <= time.monotonic()
        ft.close()
        ft.close()

        inputs = registry.create("digital_inputs", "twin_shm", rig=rig)
        state = inputs.read(DigitalInputState())
        assert not state.hardware_estop and not state.hand_stop
        inputs.close()

        t1 = rig.rig_time()
        h1 = rig.heartbeat()
        time.sleep(0.05)
        assert rig.rig_time() > t1 and rig.heartbeat() > h1


def test_volts_applied_then_watchdog_trips_and_rearms(rig_name, hold_volts):
    rig = ShmRig(rig_name, RIG_TIMEOUT_S)
    card = ShmActuators(rig, 0)
    feeder = Feeder(rig)
    try:
        expected = _quantized(hold_volts)
        feeder.start()
        card.enable()
        card.write_volts(hold_volts)
        assert tuple(card.last_volts) == expected
        st = _wait_for(lambda: (s := rig.amplifier_state()).volts == expected and s,
                       2.0, "the rig to apply the volts")
        assert st.drives_enabled and st.watchdog == "fed" and not st.tripped
        trips_before = st.trips
        time.sleep(0.1)                                       # held at home while powered
        with ShmEncoders(rig) as enc:
            assert np.allclose(enc.read_positions_m(np.zeros(3)), 0.2, atol=1e-3)

        last_feed = feeder.stop()
        observed = []

        def tripped():
            s = rig.amplifier_state()
            observed.append(s)
            return s.tripped and s

        st = _wait_for(tripped, 1.0, "the watchdog to trip", poll_s=0.0002)
        # Physics and the published state see 0 V in the very snapshot that shows the trip.
        assert all(s.volts == (0.0, 0.0, 0.0) and not s.drives_enabled
                   for s in observed if s.tripped)
        assert st.trips == trips_before + 1
        rig_side = st.trip_monotonic_s - st.feed_seen_monotonic_s
        since_feed = st.trip_monotonic_s - last_feed
        print(f"\nwatchdog: trip {rig_side * 1e3:.2f} ms after the rig last saw a feed, "
              f"{since_feed * 1e3:.2f} ms after the last feed")
        # Never early (1 ms of slack: the feeder stamps its time just after feeding). How
        # late is a figure on the real clock (printed above, and by 'talus faults matrix');
        # "within one rig period of the timeout" is asserted with an injected clock in
        # test_watchdog_logic_step_by_step, where load cannot move it.
        assert WATCHDOG_S < rig_side
        assert since_feed > WATCHDOG_S - 0.001

        rig.rearm()                                          # not being fed: ignored
        time.sleep(0.03)
        assert rig.amplifier_state().tripped
        card.disable()                                       # what the supervisor does
        feeder = Feeder(rig)
        feeder.start()
        time.sleep(0.03)
        assert rig.amplifier_state().tripped                 # fed again, still latched
        rig.rearm()
        st = _wait_for(lambda: (s := rig.amplifier_state()).watchdog == "fed" and s, 1.0,
                       "the re-arm")
        assert not st.drives_enabled and st.volts == (0.0, 0.0, 0.0)   # card disabled
        card.enable()
        card.write_volts(hold_volts)
        _wait_for(lambda: rig.amplifier_state().volts == expected, 1.0, "volts after re-arm")
    finally:
        feeder.stop()
        card.close()
        card.close()
        rig.close()
        rig.close()


_RT_STAND_IN = r"""
import sys, time
from rt.twin.shm_backends import ShmActuators, ShmRig
name = sys.argv[1]
volts = [float(v) for v in sys.argv[2:5]]
rig = ShmRig(name)
card = ShmActuators(rig, 0)
rig.feed_watchdog()
rig.rearm()
card.enable()
print("ready", flush=True)
nxt = time.monotonic()
while True:                      # the RT loop: write the outputs, feed the watchdog, 1 kHz
    card.write_volts(volts)
    rig.feed_watchdog()
    nxt += 0.001
    delay = nxt - time.monotonic()
    if delay > 0:
        time.sleep(delay)
    else:
        nxt = time.monotonic()
"""


def test_sigkill_of_the_rt_process_drops_the_drives(hold_volts):
    name = _unique_name()
    rig_proc = stand_in = None
    handle = None
    try:
        rig_proc = _start_rig(name, "--watchdog-ms", str(WATCHDOG_S * 1e3))
        handle = ShmRig(name)
        stand_in = subprocess.Popen(
            [sys.executable, "-c", _RT_STAND_IN, name, *(repr(float(v)) for v in hold_volts)],
            cwd=REPO, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        assert _read_line(stand_in, 60.0).strip() == "ready"
        expected = _quantized(hold_volts)
        _wait_for(lambda: (s := handle.amplifier_state()).volts == expected
                  and s.drives_enabled, 5.0, "the stand-in's volts on the amplifiers")
        time.sleep(0.2)
        st = handle.amplifier_state()
        assert st.watchdog == "fed" and st.volts == expected

        t_kill = time.monotonic()
        os.kill(stand_in.pid, signal.SIGKILL)
        st = _wait_for(lambda: (s := handle.amplifier_state()).volts == (0.0, 0.0, 0.0)
                       and s, 2.0, "0 V after the SIGKILL", poll_s=0.0001)
        t_seen = time.monotonic()
        stand_in.wait(5)
        assert stand_in.returncode == -signal.SIGKILL
        assert st.tripped and not st.drives_enabled
        rig_latency = st.trip_monotonic_s - t_kill
        seen_latency = t_seen - t_kill
        print(f"\nSIGKILL -> 0 V applied: {rig_latency * 1e3:.1f} ms (rig's trip time), "
              f"{seen_latency * 1e3:.1f} ms (seen by the test process); "
              f"watchdog {WATCHDOG_S * 1e3:.0f} ms")
        # The stand-in fed ≤ ~1 ms before the kill, so the trip cannot come much earlier
        # than the timeout; the target is 50 ms.
        # Not before the watchdog could trip; how soon after is a figure (printed above; the
        # fault matrix's rt_process_loss entry), not asserted on a possibly loaded machine.
        assert rig_latency > WATCHDOG_S - RIG_PERIOD_S - JITTER_S
        # The rig lives on, its physics running at 0 V.
        h = handle.heartbeat()
        time.sleep(0.02)
        assert handle.heartbeat() > h

        code, out, err = _stop_rig(rig_proc)
        assert code == 0, err
        stopped = json.loads(out.splitlines()[-1])["stopped"]
        assert stopped["trips"] == 1 and stopped["error"] is None
        assert not os.path.exists(f"/dev/shm/{name}")        # unlinked at exit
        assert handle.rig_state == "stopped"
        with pytest.raises(HardwareError, match="stopped"):
            ShmEncoders(handle)
    finally:
        for proc in (stand_in, rig_proc):
            if proc is not None:
                _kill(proc)
        if handle is not None:
            handle.close()
        _remove_segment(name)


# --------------------------------------------------------------------------- errors, cleanup
@pytest.mark.parametrize("bad", ["", "a/b", "../etc", "-x", "x" * 101, "sp ace", 5, None])
def test_a_malformed_name_is_a_clear_input_error(bad):
    with pytest.raises(InputError, match="malformed"):
        ShmRig(bad)  # type: ignore[arg-type]


def test_a_missing_or_foreign_segment_is_a_clear_hardware_error():
    missing = _unique_name()
    with pytest.raises(HardwareError, match="start the rig first"):
        ShmRig(missing)
    with pytest.raises(HardwareError, match="start the rig first"):
        registry.create("encoders", "twin_shm", rig=missing)
    with pytest.raises(HardwareError, match="start the rig first"):
        ShmActuators(missing, 0)

    foreign = shared_memory.SharedMemory(name=_unique_name(), create=True,
                                         size=layout.TOTAL_SIZE)
    small = shared_memory.SharedMemory(name=_unique_name(), create=True, size=64)
    try:
        with pytest.raises(HardwareError, match="not a talus rig segment"):
            ShmRig(foreign.name)
        with pytest.raises(HardwareError, match="too small"):
            ShmRig(small.name)
    finally:
        for seg in (foreign, small):
            seg.close()
            seg.unlink()


def test_closing_twice_is_safe_and_closed_handles_refuse_work(rig_name):
    rig = ShmRig(rig_name, RIG_TIMEOUT_S)
    enc = ShmEncoders(rig)
    card = ShmActuators(rig, 1)
    rig.close()
    rig.close()
    assert rig.closed
    with pytest.raises(HardwareError, match="closed"):
        rig.feed_watchdog()
    with pytest.raises(HardwareError, match="closed"):
        enc.read_positions_m(np.zeros(3))
    card.close()                      # the card's handle is gone: closing still works
    card.close()
    enc.close()
    enc.close()
    with pytest.raises(HardwareError, match="closed"):
        enc.read_counts()


def test_the_cli_refuses_a_bad_or_taken_name(rig_name):
    bad = subprocess.run([sys.executable, "-m", "rt.twin.rig_cli", "rig", "--shm", "a/b"],
                         cwd=REPO, env=_env(),
                         check=False, capture_output=True, text=True, timeout=30)
    assert bad.returncode == 2 and "malformed" in json.loads(bad.stdout)["error"]
    taken = subprocess.run([sys.executable, "-m", "rt.twin.rig_cli", "rig", "--shm", rig_name],
                           cwd=REPO, env=_env(),
                           check=False, capture_output=True, text=True, timeout=30)
    assert taken.returncode == 2 and "already exists" in json.loads(taken.stdout)["error"]
    assert os.path.exists(f"/dev/shm/{rig_name}")    # the running rig's segment is untouched
