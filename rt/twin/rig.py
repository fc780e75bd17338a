"""The twin as a separate "rig" process: hardware that lives outside the RT process.

On the real rig the encoders, DACs, force sensor and amplifiers keep existing when the RT
process dies; in particular a hardware watchdog on the amplifiers drops the drives to zero
when the loop stops feeding it. ``RigProcess`` gives the twin that shape: it owns a ``Twin``
and the shared-memory segment (``rt.twin.shm``), runs in real time at ``rate_hz`` (default
1 kHz), and each period:

1. reads the command block (card enables, DAC codes, watchdog feed and re-arm counters);
2. runs the **amplifier watchdog**: the drives are off until the first feed; once fed, if
   the feed counter has not changed for longer than ``watchdog_timeout_s`` (20 ms) the
   amplifiers are disabled (inputs forced to 0 V) and stay so (latched) until the re-arm
   counter changes while feeding has resumed;
3. advances the physics to the instant the new commands took effect: the RT process stamps
   every card write with its ``time.monotonic()``, so a write between two rig periods is
   applied at its own instant (zero-order hold, as a DAC); a watchdog decision (trip,
   re-arm) takes effect at the period it is taken, never earlier. Then it applies the gated
   commands to the twin's ``FakeComedi`` doubles and card enables, and advances the physics
   to now;
4. publishes the sensor block (counters, ATI sample, inputs, amplifier state, heartbeat).

So physics sees 0 V from the rig period in which the watchdog trips. Rig time 0 is
``epoch_monotonic_s`` (header); both processes use ``time.monotonic`` (CLOCK_MONOTONIC,
system-wide on Linux), so rig times convert to the RT process's clock by adding the epoch.

Timing: sleep until ``spin_s`` before each deadline, then spin (never a whole period,
PLATFORM.md); gc paused while running; a period later than two periods re-phases instead of
bursting (the physics catches up in one ``sync``).
"""
from __future__ import annotations

import math
import os
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any, Self

from rt.engine import rt_hygiene
from rt.errors import ConfigurationError, TalusError
from rt.twin import shm as layout
from rt.twin.environment import parse_environment
from rt.twin.twin import Twin, port_counts

DEFAULT_RATE_HZ = 1000.0
DEFAULT_WATCHDOG_TIMEOUT_S = 0.02
DEFAULT_SPIN_S = 150e-6


@dataclass
class RigSummary:
    """What a run did: periods, timing (ms), watchdog trips and IPC health."""

    shm: str
    periods: int = 0
    duration_s: float = 0.0
    late_max_ms: float = 0.0
    misses: int = 0
    rephases: int = 0
    trips: int = 0
    command_read_failures: int = 0
    error: str | None = None

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


class RigProcess:
    """A ``Twin`` served as hardware through the shared-memory segment ``shm_name``.

    Creates (and at :meth:`close`, unlinks) the segment. Call :meth:`run` in the process that
    should play the rig, or :meth:`step` with explicit times (tests of the watchdog logic).

    Parameters: ``environment`` (``Environment`` or its CLI text: ``free``, ``payload:KG[@S]``,
    ``plate[:HEIGHT_M]``, ``ankle``), ``seed`` (sensor noise), ``rate_hz`` (rig periods per
    second, 100-5000), ``watchdog_timeout_s`` (longest gap between feeds, s, 1 ms-1 s),
    ``twin`` (an existing twin instead of a new one), ``clock`` (monotonic seconds),
    ``description`` (the robot the new twin simulates; default the nominal one).
    """

    def __init__(self, shm_name: str, environment: Any = "free", seed: int = 0,
                 rate_hz: float = DEFAULT_RATE_HZ,
                 watchdog_timeout_s: float = DEFAULT_WATCHDOG_TIMEOUT_S,
                 twin: Twin | None = None, clock: Callable[[], float] = time.monotonic,
                 truth=None, imperfections=None):
        layout.check_shm_name(shm_name)
        if not 100.0 <= rate_hz <= 5000.0:
            raise ConfigurationError(f"rig rate must be 100-5000 Hz, got {rate_hz}")
        if not 0.001 <= watchdog_timeout_s <= 1.0:
            raise ConfigurationError(
                f"watchdog timeout must be 1 ms to 1 s, got {watchdog_timeout_s} s")
        if isinstance(environment, str):
            environment = parse_environment(environment)
        self.rate_hz = float(rate_hz)
        self.period_s = 1.0 / self.rate_hz
        self.watchdog_timeout_s = float(watchdog_timeout_s)
        self.clock = clock
        # The twin first (≈ 1 s): the segment appears only when the rig can serve it.
        self.twin = twin if twin is not None else Twin(truth, environment, seed=seed,
                                                       imperfections=imperfections)
        self.twin.home_encoders()             # the rig's counters read absolute positions
        self.summary = RigSummary(shm=shm_name)
        self._stop = False
        self.seg = layout.create_segment(shm_name)
        try:
            self._init_segment(shm_name, clock)
        except BaseException:
            self.seg.close()                  # never leave a half-made segment in /dev/shm
            raise

    def _init_segment(self, shm_name: str, clock: Callable[[], float]) -> None:
        self.name = shm_name
        self.epoch_s = clock()

        # Watchdog and command-tracking state (rig side, private).
        self.wd_state = layout.WD_WAITING
        self._feed_seen = 0
        self._feed_seen_t = -math.inf          # monotonic s when the feed last changed
        self._rearm_seen = 0
        self._write_count_seen = 0
        self._trip_t = -math.inf
        self._cmd_enabled = [False, False]
        self._cmd_codes = [layout.NO_CODE] * 6

        h = self.seg.header
        h.version[0] = layout.LAYOUT_VERSION
        h.size[0] = layout.TOTAL_SIZE
        h.rig_pid[0] = os.getpid()
        h.epoch_monotonic_s[0] = self.epoch_s
        h.period_s[0] = self.period_s
        h.watchdog_timeout_s[0] = self.watchdog_timeout_s
        h.m_per_count[0] = self.twin.m_per_count
        h.command_limit_v[0] = self.twin.command_limit_v
        h.rig_state[0] = layout.RIG_RUNNING
        s = self.seg.sensors.local
        s.trip_rig_time_s[0] = math.nan
        s.trip_monotonic_s[0] = math.nan
        s.feed_seen_monotonic_s[0] = math.nan
        # One period now, so the first snapshot already holds an ATI sample.
        self.step(clock())
        h.magic[:] = tuple(layout.MAGIC)      # last: attachers now see a complete segment

    # ------------------------------------------------------------------ one period
    def step(self, now: float) -> None:
        """One rig period at monotonic time ``now`` (s): commands, watchdog, physics, publish."""
        cmd = self.seg.commands
        if not cmd.read():
            # A writer stuck mid-write (killed or preempted): keep the last commands. The
            # feed counter is then unchanged, so the watchdog trips if this persists.
            self.summary.command_read_failures += 1
        c = cmd.local
        wd_before = self.wd_state
        self._watchdog(now, int(c.feed[0]), int(c.rearm[0]))

        twin = self.twin
        t_apply = now
        write_count = int(c.write_count[0])
        if write_count != self._write_count_seen:
            self._write_count_seen = write_count
            stamp = float(c.write_monotonic_s[0])
            # A watchdog decision taken now must not act before now: then the new codes
            # wait for it (at most one period late).
            if math.isfinite(stamp) and self.wd_state == wd_before:
                t_apply = min(now, stamp)
            enabled, codes = self._cmd_enabled, self._cmd_codes
            for k in range(2):
                enabled[k] = bool(c.card_enabled[k])
            for i in range(6):
                codes[i] = int(c.dac_codes[i])
        # Hold the old inputs up to the instant the new ones took effect (never backwards).
        twin.sync(max(twin.t, t_apply - self.epoch_s))
        self._apply_commands()
        twin.sync(now - self.epoch_s)
        self._publish(now)

    def _watchdog(self, now: float, feed: int, rearm: int) -> None:
        timeout = self.watchdog_timeout_s
        if feed != self._feed_seen:
            self._feed_seen = feed
            self._feed_seen_t = now
            if self.wd_state == layout.WD_WAITING:
                self.wd_state = layout.WD_FED
        if self.wd_state == layout.WD_FED and now - self._feed_seen_t > timeout:
            self.wd_state = layout.WD_TRIPPED
            self._trip_t = now
            self.summary.trips += 1
            s = self.seg.sensors.local
            s.trip_monotonic_s[0] = now
            s.trip_rig_time_s[0] = now - self.epoch_s
            s.trips[0] = self.summary.trips
        if rearm != self._rearm_seen:
            # A re-arm counts only while feeding has resumed (a feed seen after the trip and
            # recent); otherwise it is consumed and ignored, never remembered for later.
            self._rearm_seen = rearm
            if (self.wd_state == layout.WD_TRIPPED and self._feed_seen_t > self._trip_t
                    and now - self._feed_seen_t <= timeout):
                self.wd_state = layout.WD_FED

    def _apply_commands(self) -> None:
        """Codes into the twin's DAC doubles; card enables gated by the watchdog."""
        twin = self.twin
        allowed = self.wd_state == layout.WD_FED
        codes = self._cmd_codes
        for k in range(2):
            # Into the double's code array (``FakeComedi.codes3``; NO_CODE: never written).
            ao = twin.dac_libs[k].codes3
            for ch in range(3):
                code = codes[3 * k + ch]
                ao[ch] = code if code >= 0 else layout.NO_CODE
            twin.set_card_enabled(k, allowed and self._cmd_enabled[k])
        # Now, not at the next sync: the published amplifier state is what physics applies.
        twin._update_amplifier_input()

    def _publish(self, now: float) -> None:
        twin = self.twin
        s = self.seg.sensors.local
        s.heartbeat[0] += 1
        s.rig_time_s[0] = twin.t
        s.rig_monotonic_s[0] = now
        delayed, sample = twin.delayed()
        counts = delayed if delayed is not None else port_counts(twin.encoder_port)
        for i in range(3):
            s.counts[i] = counts[i]
        if sample is None:
            s.ft_valid[0] = 0
        else:
            w = sample.wrench
            for i in range(6):
                s.wrench[i] = w[i]
            s.ft_status[0] = sample.status
            s.ft_sequence[0] = sample.ft_sequence
            s.ft_valid[0] = 1
        s.hardware_estop[0] = twin.inputs.hardware_estop
        s.hand_stop[0] = twin.inputs.hand_stop
        for i in range(3):
            s.amp_volts[i] = twin.amp_volts[i]
        s.drives_enabled[0] = twin.drives_enabled
        s.watchdog_state[0] = self.wd_state
        s.watchdog_tripped[0] = self.wd_state == layout.WD_TRIPPED
        s.feed_seen[0] = self._feed_seen
        s.feed_seen_monotonic_s[0] = self._feed_seen_t if self._feed_seen else math.nan
        s.rearm_seen[0] = self._rearm_seen
        s.command_read_failures[0] = self.summary.command_read_failures
        self.seg.sensors.publish()

    # ------------------------------------------------------------------ real time
    def request_stop(self) -> None:
        """Ask :meth:`run` to return at the next period (safe from a signal handler)."""
        self._stop = True

    def run(self, seconds: float | None = None, stop: Any = None,
            spin_s: float = DEFAULT_SPIN_S, fifo_priority: int | None = None,
            on_ready: Callable[[RigProcess], None] | None = None) -> RigSummary:
        """Run periods in real time until ``seconds`` elapse, ``stop.is_set()``, or
        :meth:`request_stop`. ``fifo_priority`` asks for SCHED_FIFO (tried, not required).
        ``on_ready(self)`` is called once the loop is set up (gc collected, ≈ 70 ms) and
        the snapshot is fresh, right before the first period: clients attaching then find
        the rig publishing.

        A ``TalusError`` from the physics (the mechanism left its assembly range) ends the run
        with ``rig_state`` failed and the error in the summary.
        """
        clock_ns = time.monotonic_ns
        sleep = time.sleep
        period_ns = round(1e9 / self.rate_hz)
        spin_ns = min(round(spin_s * 1e9), period_ns // 2)
        tol_ns = period_ns // 5
        behind_ns = 2 * period_ns
        summary = self.summary
        late_max = 0
        with rt_hygiene.realtime_thread(priority=fifo_priority, lock_memory=False,
                                        timer_slack_ns=1, switch_interval_s=None), \
                rt_hygiene.gc_paused():
            start_ns = clock_ns()
            end_ns = start_ns + round(seconds * 1e9) if seconds is not None else None
            deadline = start_ns
            try:
                if on_ready is not None:
                    self.step(start_ns * 1e-9)
                    on_ready(self)
                    deadline = clock_ns()
                while not self._stop:
                    if end_ns is not None and deadline >= end_ns:
                        break
                    # An mp.Event costs a semaphore call: look every 16 periods (16 ms).
                    if stop is not None and (summary.periods & 15) == 0 and stop.is_set():
                        break
                    now = clock_ns()
                    if deadline - now > spin_ns:
                        sleep((deadline - now - spin_ns) * 1e-9)
                        now = clock_ns()
                    while now < deadline:
                        now = clock_ns()
                    late = now - deadline
                    late_max = max(late_max, late)
                    if late > tol_ns:
                        summary.misses += 1
                        if late > behind_ns:
                            summary.rephases += 1
                            deadline = now
                    self.step(now * 1e-9)
                    summary.periods += 1
                    deadline += period_ns
            except TalusError as exc:
                summary.error = str(exc)
                self.seg.header.rig_state[0] = layout.RIG_FAILED
        summary.duration_s = (clock_ns() - start_ns) * 1e-9
        summary.late_max_ms = late_max * 1e-6
        return summary

    # ------------------------------------------------------------------ teardown
    def close(self) -> None:
        """Mark the rig stopped, then unmap and unlink the segment. Safe to call twice."""
        seg = self.seg
        if seg.closed:
            return
        if int(seg.header.rig_state[0]) != layout.RIG_FAILED:
            seg.header.rig_state[0] = layout.RIG_STOPPED
        seg.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def run_rig(shm_name: str, environment: Any = "free", seed: int = 0,
            rate_hz: float = DEFAULT_RATE_HZ,
            watchdog_timeout_s: float = DEFAULT_WATCHDOG_TIMEOUT_S,
            seconds: float | None = None, stop: Any = None,
            on_ready: Callable[[RigProcess], None] | None = None,
            fifo_priority: int | None = None) -> RigSummary:
    """Create the rig on ``shm_name``, call ``on_ready(rig)``, run until stopped, unlink.

    Usable as a ``multiprocessing`` target (pass ``stop``, an ``mp.Event``) or from the CLI
    (``talus twin rig``). Returns the run's :class:`RigSummary`.
    """
    with RigProcess(shm_name, environment, seed, rate_hz, watchdog_timeout_s) as rig:
        return rig.run(seconds=seconds, stop=stop, fifo_priority=fifo_priority,
                       on_ready=on_ready)
