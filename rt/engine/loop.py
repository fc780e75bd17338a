"""The one periodic activity that runs the graph (DESIGN 5; CONVENTIONS 4).

``Loop(graph, rate_hz, mode)`` runs ``graph.step(t, dt)`` once per period, in the calling
thread (:meth:`Loop.run`) or in a dedicated thread (:meth:`Loop.start` / :meth:`Loop.stop`).

* ``mode="realtime"``: waits for each deadline the way PLATFORM.md measured best on these
  VMs — gc frozen and disabled, ``time.sleep`` until ``spin_us`` (150 µs) before the deadline,
  then a busy wait on the clock (never a whole period: a spinning SCHED_FIFO thread gets
  throttled). ``t`` is the time since the loop's first cycle and ``dt`` the *measured* time
  since the previous cycle's start (s). A cycle starting later than ``deadline + tolerance``
  (20 % of the period by default) is a miss; lateness is kept in a ring for percentiles. If
  the loop falls more than ``max_behind_periods`` periods behind (a host stall), it re-phases
  (the next deadline is counted from now) instead of bursting cycles back-to-back to catch up,
  which would hand the controllers a series of tiny ``dt``.
* ``mode="fast"``: cycles back-to-back on simulated time; ``t`` advances by exactly the
  period and ``dt`` is the period (lockstep with the digital twin, tests, benchmarks,
  pre-flight).

Commands queued from any thread (rate, parameters, component swap; see
:mod:`rt.engine.commands`) are applied at the start of a cycle, before any component runs.
"""
from __future__ import annotations

import contextlib
import functools
import math
import os
import select
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from rt.engine import rt_hygiene
from rt.engine.commands import Call, CommandQueue, CommandResult, SetParams, SetRate, Swap
from rt.engine.component import Component
from rt.engine.graph import Graph
from rt.engine.stats import (
    DEFAULT_CAPACITY,
    Fault,
    GraphStats,
    TimingStats,
    check_capacity,
    new_ring,
    summarize,
)
from rt.errors import ConfigurationError, InputError, TalusError

MIN_RATE_HZ = 100.0
MAX_RATE_HZ = 2000.0
MODES = ("realtime", "fast")


def check_rate(rate_hz: float) -> float:
    """Return ``rate_hz`` as a float if within 100-2000 Hz, else ConfigurationError."""
    try:
        rate = float(rate_hz)
    except (TypeError, ValueError):
        raise ConfigurationError(f"loop rate must be a number of Hz, got {rate_hz!r}") from None
    if not (MIN_RATE_HZ <= rate <= MAX_RATE_HZ):  # also refuses NaN
        raise ConfigurationError(
            f"loop rate {rate_hz!r} Hz is outside the supported {MIN_RATE_HZ:g}-{MAX_RATE_HZ:g} Hz "
            f"(period {1e3 / MAX_RATE_HZ:g}-{1e3 / MIN_RATE_HZ:g} ms)")
    return rate


@dataclass(frozen=True)
class LoopStats:
    """``Loop.stats()``: timing of the loop and of its graph.

    ``lateness`` (µs) is how late each cycle started after its deadline (realtime mode only;
    empty in fast mode); ``misses`` counts cycles later than ``miss_tolerance_us``;
    ``rephases`` counts re-phasings after falling behind and ``skipped_periods`` the periods
    they dropped. ``graph`` has per-slot and whole-cycle execution times and the fault count.
    """

    mode: str
    rate_hz: float
    cycles: int
    t: float
    misses: int
    miss_tolerance_us: float
    rephases: int
    skipped_periods: int
    lateness: TimingStats
    graph: GraphStats
    hygiene: rt_hygiene.HygieneReport | None

    @property
    def miss_ratio(self) -> float:
        """Misses per cycle counted in lateness (0 when none ran)."""
        return self.misses / self.lateness.count if self.lateness.count else 0.0

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)

    def summary(self) -> str:
        """Human-readable multi-line summary."""
        lines = [f"{self.mode} loop at {self.rate_hz:g} Hz: {self.cycles} cycles, t = {self.t:.3f} s"]
        if self.lateness.count:
            lat = self.lateness
            lines.append(f"lateness p50 {lat.p50_us:.1f} µs, p99 {lat.p99_us:.1f} µs, "
                         f"max {lat.max_all_us:.1f} µs; misses {self.misses}/{lat.count} "
                         f"(> {self.miss_tolerance_us:.0f} µs late, {100 * self.miss_ratio:.3f} %), "
                         f"re-phased {self.rephases}x ({self.skipped_periods} periods skipped)")
        lines.append(self.graph.table())
        if self.graph.faults:
            lines.append(f"component faults: {self.graph.faults}")
        return "\n".join(lines)


class CycleSignal:
    """Set by the loop after every ``every``-th cycle; another thread waits on it to run its
    Python right after a cycle, in the loop's sleep, instead of at a random time when its
    first bytecode may be the one that delays the loop's next cycle (the loop shares the GIL
    with it). A pipe, not a ``threading.Event``: firing is one non-blocking ``write`` with no
    lock the loop could wait on. Waiting clears it. :meth:`close` removes it from the loop."""

    def __init__(self, loop: Loop, every: int) -> None:
        self.every = every
        self._loop = loop
        self._r, self._w = os.pipe()
        os.set_blocking(self._r, False)
        os.set_blocking(self._w, False)
        self.closed = False

    def fire(self) -> None:
        """The loop's side (any thread may call it): never blocks."""
        try:
            os.write(self._w, b"\0")
        except OSError:
            pass               # the pipe is full (the waiter is behind: one pending is enough)

    def wait(self, timeout: float) -> bool:
        """Wait until fired or ``timeout`` s; True when fired (and cleared)."""
        if self.closed:
            return False
        ready, _, _ = select.select([self._r], [], [], max(0.0, timeout))
        if not ready:
            return False
        try:
            while os.read(self._r, 4096):
                pass
        except (BlockingIOError, InterruptedError):
            pass
        return True

    def close(self) -> None:
        """No more firing. The pipe is closed when the last reference goes (``__del__``): the
        loop may be firing it from the tuple it read a moment ago, and a closed descriptor's
        number can be reused by another file."""
        if self.closed:
            return
        self.closed = True
        self._loop._remove_signal(self)

    def __del__(self) -> None:
        for fd in (getattr(self, "_r", None), getattr(self, "_w", None)):
            if fd is not None:
                with contextlib.suppress(OSError):
                    os.close(fd)


class Loop:
    """One periodic activity running a :class:`Graph`.

    Parameters (times in µs or as fractions of the period):

    * ``rate_hz`` — 100-2000 Hz, else ConfigurationError.
    * ``mode`` — ``"realtime"`` or ``"fast"`` (see the module docstring).
    * ``clock`` — monotonic clock in integer ns (default ``time.perf_counter_ns``) and ``sleep``
      (default ``time.sleep``, seconds): realtime mode only; a fake pair makes lateness
      handling testable (a fake clock must advance when read or slept on).
    * ``spin_us`` — busy-wait this long before each deadline (capped at half a period).
    * ``miss_tolerance`` — a cycle starting later than this fraction of the period is a miss.
    * ``max_behind_periods`` — re-phase when a cycle starts more than this many periods late.
    * ``rt_priority``, ``cpus``, ``lock_memory``, ``switch_interval_s`` — real-time hygiene
      tried in realtime mode (:func:`rt_hygiene.realtime_thread`); None/False skips one.
    * ``cpu_latency_us`` — realtime mode: bound every CPU's wake-up latency through the
      kernel's PM QoS while the loop runs (:func:`rt_hygiene.try_cpu_latency_bound`; 0: idle
      CPUs poll instead of halting). None: not requested.
    * ``manage_gc`` — freeze and disable gc while running (both modes; the collection before
      freezing is only done in realtime mode, where its tens of ms at start-up do not matter).
    * ``gil_hold_s`` — realtime mode: the GIL switch interval while a cycle runs (``None``, the
      default: unchanged; 0.001 is the value studied). Between cycles the interval is
      ``switch_interval_s``. Off by default until a quiet machine shows it helps: on a loaded
      one single runs were inconclusive (closing note of branch rtsession).

    * ``gil_guard_us`` — with ``gil_hold_s``: wake this long before each deadline (instead of
      ``spin_us``) and wait the rest in C *keeping* the GIL (``hold_sleep``, default
      :data:`rt_hygiene.sleep_holding_gil`; injectable with a fake clock), so that the cycle
      starts on time whoever wanted the GIL when the loop woke. None: off.
    * :meth:`cycle_signal` — a pipe fired every N cycles, for threads that should run right
      after a cycle (telemetry, the session pump) rather than at random times.

    A cycle with no room to sleep before its deadline (late, or the first) shares the GIL by
    the short interval: holding it from cycle to cycle would leave the other threads only
    forced switches after ``gil_hold_s``, each stalling the loop as long.

    Why the two intervals: the loop shares the GIL with the process's other threads (IPC,
    telemetry, sessions, the recorder). A thread that asks for the GIL waits one switch
    interval, then forces its holder to drop it; with one short interval (0.2 ms) any busy
    thread took the GIL from the loop in the middle of a cycle, and the loop waited as long
    again to get it back: cycles stretched from 0.2 to 0.8 ms and 4 % of them started late
    during a recorded session (bench/rt_deadlines.py, loaded machine). While a cycle runs the
    interval is long (1 ms, longer than a cycle's 0.2-0.4 ms), so the others wait for the
    loop's sleep, which releases the GIL; while the loop sleeps it is short again, so that the
    loop, waking 150 µs before its deadline, takes the GIL back within it from whoever holds
    it. Not longer than 1 ms: a cycle that releases the GIL itself (a contended lock when a
    safety event is published) waits up to one interval to get it back.
    """

    def __init__(self, graph: Graph, rate_hz: float = 1000.0, mode: str = "realtime",
                 clock: Callable[[], int] | None = None, *,
                 sleep: Callable[[float], None] | None = None,
                 spin_us: float = 150.0, miss_tolerance: float = 0.2,
                 max_behind_periods: float = 1.0,
                 rt_priority: int | None = 80, cpus: Iterable[int] | None = None,
                 lock_memory: bool = True, switch_interval_s: float | None = 0.0002,
                 cpu_latency_us: int | None = None,
                 manage_gc: bool = True, gil_hold_s: float | None = None,
                 gil_guard_us: float | None = None,
                 hold_sleep: Callable[[int], None] | None = None,
                 command_capacity: int = 64,
                 stats_capacity: int = DEFAULT_CAPACITY) -> None:
        if not isinstance(graph, Graph):
            raise ConfigurationError(f"Loop needs a built Graph, got {graph!r}")
        if mode not in MODES:
            raise ConfigurationError(f"loop mode {mode!r} is not one of {', '.join(MODES)}")
        if not (spin_us >= 0.0):
            raise ConfigurationError(f"spin_us must be ≥ 0, got {spin_us!r}")
        if not (0.0 < miss_tolerance <= 1.0):
            raise ConfigurationError(
                f"miss_tolerance is a fraction of the period in (0, 1], got {miss_tolerance!r}")
        if not (max_behind_periods >= 1.0):
            raise ConfigurationError(f"max_behind_periods must be ≥ 1, got {max_behind_periods!r}")
        self.graph = graph
        self.mode = mode
        self._clock = clock or time.perf_counter_ns
        self._sleep = sleep or time.sleep
        self._spin_us = float(spin_us)
        self._miss_tolerance = float(miss_tolerance)
        self._max_behind = float(max_behind_periods)
        cpu_list = None if cpus is None else list(cpus)
        # Bound now, entered in the thread that runs the cycles (FIFO/affinity are per thread).
        self._hygiene = functools.partial(
            rt_hygiene.realtime_thread, priority=rt_priority, cpus=cpu_list,
            lock_memory=lock_memory, switch_interval_s=switch_interval_s,
            cpu_latency_us=cpu_latency_us)
        self._manage_gc = manage_gc
        if gil_hold_s is not None and not (0.0 < gil_hold_s <= 0.1):
            raise ConfigurationError(f"gil_hold_s must be in (0, 0.1] s, got {gil_hold_s!r}")
        self._gil_hold_s = gil_hold_s
        if gil_guard_us is not None and not (0.0 <= gil_guard_us <= 500.0):
            raise ConfigurationError(f"gil_guard_us must be in [0, 500] µs, got {gil_guard_us!r}")
        if gil_guard_us is not None and gil_hold_s is None:
            raise ConfigurationError("gil_guard_us needs gil_hold_s (the guard keeps the GIL "
                                     "only if no other thread can force it off meanwhile)")
        self._guard_us = gil_guard_us
        self._hold_sleep = hold_sleep or rt_hygiene.sleep_holding_gil
        self._queue = CommandQueue(command_capacity)
        self._signals: tuple[CycleSignal, ...] = ()
        self._capacity = check_capacity(stats_capacity)
        self._lat_ring = new_ring(self._capacity)
        self._set_period(check_rate(rate_hz))
        self._run_lock = threading.Lock()
        self._in_run = False
        self._thread: threading.Thread | None = None
        self._thread_error: BaseException | None = None
        self._stop_requested = False
        self.hygiene: rt_hygiene.HygieneReport | None = None
        self._reset_counters()

    # ------------------------------------------------------------------ state
    def _reset_counters(self) -> None:
        self._cycles = 0
        self._t = 0.0
        self._dt = self._period_s
        self._anchor_t = 0.0  # fast mode: t = anchor_t + (cycle - anchor_cycle) * period
        self._anchor_cycle = 0
        self._t_current = 0.0
        self._epoch_ns: int | None = None
        self._misses = 0
        self._rephases = 0
        self._skipped = 0
        self._lat_ring.fill(-1)
        self._lat_idx = 0
        self._lat_count = 0
        self._lat_max = 0

    def _set_period(self, rate: float) -> None:
        self._rate_hz = rate
        self._period_s = 1.0 / rate
        self._period_ns = round(1e9 / rate)
        self._spin_ns = min(round(self._spin_us * 1e3), self._period_ns // 2)
        guard = self._spin_us if self._guard_us is None else max(self._guard_us, self._spin_us)
        self._guard_ns = min(round(guard * 1e3), self._period_ns // 2)
        self._tol_ns = round(self._miss_tolerance * self._period_ns)
        self._behind_ns = round(self._max_behind * self._period_ns)

    def _apply_rate(self, rate_hz: float) -> None:
        """Loop thread, at a boundary: the new period follows the current cycle."""
        rate = check_rate(rate_hz)
        if self.mode == "fast":
            self._anchor_t = self._t_current
            self._anchor_cycle = self._cycles
        self._set_period(rate)

    @property
    def rate_hz(self) -> float:
        """Current rate (Hz)."""
        return self._rate_hz

    @property
    def period_s(self) -> float:
        """Current nominal period (s)."""
        return self._period_s

    @property
    def cycles(self) -> int:
        """Cycles run so far (since construction or :meth:`reset`)."""
        return self._cycles

    @property
    def t(self) -> float:
        """Loop time of the last cycle (s)."""
        return self._t

    @property
    def running(self) -> bool:
        """True while a ``run`` or the dedicated thread is executing cycles."""
        return self._in_run

    def reset(self) -> None:
        """Stopped loop only: graph back to its initial condition (``Graph.reset``), time and
        counters to zero, so the same inputs replay the same run."""
        if self._in_run:
            raise InputError("Loop.reset(): stop the loop first")
        if self.graph.running:
            self.graph.stop()
        self.graph.reset()
        self._reset_counters()

    # ------------------------------------------------------------------ running
    def _prepare_graph(self) -> None:
        if not self.graph.running:
            self.graph.configure()
            self.graph.start()

    @contextlib.contextmanager
    def _running(self) -> Iterator[None]:
        with self._run_lock:
            if self._in_run:
                raise InputError("the loop is already running")
            self._in_run = True
        try:
            with contextlib.ExitStack() as stack:
                if self.mode == "realtime":
                    self.hygiene = stack.enter_context(self._hygiene())
                if self._manage_gc:
                    stack.enter_context(rt_hygiene.gc_paused(collect=self.mode == "realtime"))
                yield
        finally:
            self._in_run = False

    def run(self, cycles: int | None = None, seconds: float | None = None) -> int:
        """Run in the calling thread for ``cycles`` cycles or ``seconds`` (wall time in
        realtime mode, simulated time in fast mode); configures and starts the graph if it is
        not running, and leaves it running. Returns the number of cycles run (statistics:
        :meth:`stats`)."""
        if (cycles is None) == (seconds is None):
            raise InputError("run() takes exactly one of cycles= or seconds=")
        if cycles is not None and (not isinstance(cycles, int) or cycles < 0):
            raise InputError(f"cycles must be a non-negative int, got {cycles!r}")
        if seconds is not None and not (seconds >= 0.0 and math.isfinite(seconds)):
            raise InputError(f"seconds must be finite and ≥ 0, got {seconds!r}")
        if self._thread is not None and self._thread.is_alive():
            raise InputError("the loop runs in its thread; stop() it before run()")
        self._prepare_graph()
        self._stop_requested = False
        before = self._cycles
        with self._running():
            self._cycle_loop(cycles, seconds)
        return self._cycles - before

    def start(self) -> None:
        """Run in a dedicated thread until :meth:`stop` (configures/starts the graph here)."""
        if self._in_run or (self._thread is not None and self._thread.is_alive()):
            raise InputError("the loop is already running")
        self._prepare_graph()
        self._stop_requested = False
        self._thread_error = None
        ready = threading.Event()
        self._thread = threading.Thread(target=self._thread_main, args=(ready,),
                                        name="talus-rt-loop", daemon=True)
        self._thread.start()
        ready.wait(5.0)

    def _thread_main(self, ready: threading.Event) -> None:
        try:
            with self._running():
                ready.set()
                self._cycle_loop(None, None)
        # Reported by stop(); a thread cannot raise to anyone.
        except BaseException as exc:  # noqa: BLE001
            self._thread_error = exc
        finally:
            ready.set()

    def request_stop(self) -> None:
        """Ask the loop to stop before its next cycle (any thread, or a component; no wait)."""
        self._stop_requested = True  # a bool store is atomic under the GIL; read every cycle

    def stop(self, timeout: float = 5.0) -> None:
        """Stop the dedicated thread and join it (components stay active: ``graph.stop()``
        stops them). Raises TimeoutError if it does not end within ``timeout`` (s), and
        re-raises (as TalusError) an error that ended the thread."""
        self._stop_requested = True
        thread = self._thread
        if thread is not None:
            thread.join(timeout)
            if thread.is_alive():
                raise TimeoutError(f"the loop thread did not stop within {timeout} s")
            self._thread = None
        err, self._thread_error = self._thread_error, None
        if err is not None:
            raise TalusError(f"the loop thread ended with {type(err).__name__}: {err}") from err

    def _cycle_loop(self, cycles: int | None, seconds: float | None) -> None:
        if self.mode == "fast":
            self._run_fast(cycles, seconds)
        else:
            self._run_realtime(cycles, seconds)

    def _run_fast(self, cycles: int | None, seconds: float | None) -> None:
        step = self.graph.step
        queue = self._queue
        pending = queue._dq
        # The time base in locals, read again after a command (a new rate re-anchors it): the
        # cycle's Python is pre-flight's overhead (issue 16), and the same floats result.
        anchor_t, anchor_cycle, period = self._anchor_t, self._anchor_cycle, self._period_s
        t_end = math.inf
        if seconds is not None:
            t_first = anchor_t + (self._cycles - anchor_cycle) * period
            # Half a period of slack so that float rounding cannot add or drop a cycle.
            t_end = t_first + seconds - 0.5 * period
        last = self._cycles + cycles if cycles is not None else None
        cycle = self._cycles
        while not self._stop_requested and cycle != last:
            t = anchor_t + (cycle - anchor_cycle) * period
            if t > t_end:
                break
            dt = period           # the period over the interval that ends at this cycle
            self._t_current = t
            if pending:
                queue.drain(self, cycle)  # a new rate re-anchors at (t, cycle)
                anchor_t, anchor_cycle, period = (self._anchor_t, self._anchor_cycle,
                                                  self._period_s)
            self._t = t
            self._dt = dt
            step(t, dt)
            cycle += 1
            self._cycles = cycle
            if self._signals:
                for sig in self._signals:
                    if cycle % sig.every == 0:
                        sig.fire()

    def _run_realtime(self, cycles: int | None, seconds: float | None) -> None:
        hold = self._gil_hold_s
        if hold is None:
            self._realtime_cycles(cycles, seconds, None, None)
            return
        between = sys.getswitchinterval()      # the hygiene's (0.2 ms), or the process's
        sys.setswitchinterval(hold)
        try:
            self._realtime_cycles(cycles, seconds, hold, between)
        finally:
            sys.setswitchinterval(between)

    def _realtime_cycles(self, cycles: int | None, seconds: float | None,
                         hold: float | None, between: float | None) -> None:
        clock, sleep = self._clock, self._sleep
        set_interval = sys.setswitchinterval
        step = self.graph.step
        queue = self._queue
        pending = queue._dq
        ring, mask = self._lat_ring, self._capacity - 1
        period_ns, spin_ns, tol_ns, behind_ns = (self._period_ns, self._spin_ns, self._tol_ns,
                                                 self._behind_ns)
        guard_ns = self._guard_ns
        hold_sleep = self._hold_sleep
        now = clock()
        if self._epoch_ns is None:
            self._epoch_ns = now
        epoch = self._epoch_ns
        end_ns = now + round(seconds * 1e9) if seconds is not None else None
        deadline = now
        prev = -1
        k = 0
        while not self._stop_requested and (cycles is None or k < cycles):
            if end_ns is not None and deadline >= end_ns:
                break
            now = clock()
            if deadline - now > guard_ns:
                if between is not None:
                    set_interval(between)     # sleeping: take the GIL back quickly on waking
                sleep((deadline - now - guard_ns) * 1e-9)
                if hold is not None:
                    set_interval(hold)        # awake: keep it until the next sleep
                now = clock()
            elif between is not None:
                # No room to sleep (a late or long cycle): the loop would keep the GIL from
                # cycle to cycle and the others could take it only after ``hold``, each time
                # stalling the loop as long. Share it by the short interval until it sleeps.
                set_interval(between)
            if deadline - now > spin_ns:
                # The guard: wait the rest in C *with* the GIL (nobody else runs Python), so
                # the cycle starts on time whoever wanted the GIL meanwhile.
                hold_sleep(deadline - now - spin_ns)
                now = clock()
            while now < deadline:
                now = clock()
            late = now - deadline
            li = self._lat_idx
            ring[li] = late
            self._lat_idx = (li + 1) & mask
            self._lat_count += 1
            self._lat_max = max(self._lat_max, late)
            if late > tol_ns:
                self._misses += 1
                if late > behind_ns:
                    # Re-phase instead of bursting: the next deadline is one period from now.
                    self._rephases += 1
                    self._skipped += late // period_ns
                    deadline = now
            dt = (now - prev) * 1e-9 if prev >= 0 else self._period_s
            prev = now
            cycle = self._cycles
            if pending:
                queue.drain(self, cycle)
                period_ns, spin_ns, tol_ns, behind_ns = (self._period_ns, self._spin_ns,
                                                         self._tol_ns, self._behind_ns)
                guard_ns = self._guard_ns
            t = (now - epoch) * 1e-9
            self._t = t
            self._dt = dt
            step(t, dt)
            self._cycles = cycle + 1
            k += 1
            if self._signals:
                for sig in self._signals:
                    if (cycle + 1) % sig.every == 0:
                        sig.fire()
            deadline += period_ns

    # ------------------------------------------------------------------ signals
    def cycle_signal(self, every: int) -> CycleSignal:
        """A :class:`CycleSignal` fired after every ``every``-th cycle (≥ 1), in both modes."""
        if not isinstance(every, int) or every < 1:
            raise ConfigurationError(f"cycle_signal needs every ≥ 1 cycles, got {every!r}")
        sig = CycleSignal(self, every)
        self._signals = (*self._signals, sig)    # one tuple swap: the loop reads it lock-free
        return sig

    def _remove_signal(self, sig: CycleSignal) -> None:
        self._signals = tuple(x for x in self._signals if x is not sig)

    # ------------------------------------------------------------------ commands
    def set_rate(self, rate_hz: float) -> CommandResult:
        """Change the rate (100-2000 Hz) at the next cycle boundary: the period after the cycle
        that applies it is the new one (so ``dt`` changes one cycle later)."""
        cmd = SetRate(rate_hz)
        try:
            check_rate(rate_hz)
        except ConfigurationError as exc:
            return cmd.result._complete(False, str(exc))
        return self._queue.submit(cmd)

    def set_param(self, slot: str, name: str, value: Any) -> CommandResult:
        """Set one parameter of the component in ``slot`` at the next boundary."""
        return self.set_params(slot, **{name: value})

    def set_params(self, slot: str, /, **values: Any) -> CommandResult:
        """Set parameters of the component in ``slot`` at the next boundary, all or nothing
        (the component validates; a refusal changes nothing). Value: the new params object."""
        cmd = SetParams(slot, values)
        if slot not in self.graph.order:
            return cmd.result._complete(
                False, f"no slot {slot!r} (slots: {', '.join(self.graph.order)})")
        return self._queue.submit(cmd)

    def swap(self, slot: str, component: Component) -> CommandResult:
        """Replace the component in ``slot`` at the next boundary (bumpless switch support).

        Checked and prepared now, in the caller's thread (ports compatible, inputs bound,
        outputs adopting the old buffers, ``configure()`` if needed); at the boundary the new
        component is started, gets ``handover(old)``, takes the slot, and the old one is
        stopped. Value: the new component."""
        try:
            plan = self.graph.prepare_swap(slot, component)
        except InputError as exc:
            return CommandResult(f"swap({slot!r}, {getattr(component, 'name', component)!r})"
                                 )._complete(False, str(exc))
        result = self._queue.submit(Swap(plan))
        if result.done() and not result.ok:  # queue full: release the reservation
            component._graph = None
        return result

    def call(self, fn: Callable[[Loop], Any], description: str) -> CommandResult:
        """Run ``fn(loop)`` in the loop's thread at the next boundary (or at once when the loop
        is not running); returns the command's result."""
        cmd = Call(fn, description)
        if not self.running:
            self._queue.submit(cmd)
            self._queue.drain(self, self._cycles)
            return cmd.result
        return self._queue.submit(cmd)

    # ------------------------------------------------------------------ reporting
    def lateness_samples(self) -> np.ndarray:
        """Copy of the lateness ring (ns), oldest first, over the last min(cycles counted,
        capacity) realtime cycles (empty in fast mode): for benchmarks that need histograms,
        not only the summaries. Call it between runs (``run`` returns) for an exact copy."""
        n = min(self._lat_count, self._capacity)
        idx = np.arange(self._lat_idx - n, self._lat_idx) % self._capacity
        return self._lat_ring[idx].copy()

    def stats(self) -> LoopStats:
        """Current statistics (safe to call from another thread while running)."""
        lateness = summarize(self._lat_ring, self._lat_count, self._lat_max)
        return LoopStats(self.mode, self._rate_hz, self._cycles, self._t, self._misses,
                         self._tol_ns / 1e3, self._rephases, self._skipped, lateness,
                         self.graph.stats(), self.hygiene)

    def faults(self) -> list[Fault]:
        """Component faults recorded by the graph (most recent last)."""
        return self.graph.faults()
