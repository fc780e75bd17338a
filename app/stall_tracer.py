"""What the GUI thread was doing when it stalled (issue 14's ≤ 50 ms target): a measuring
instrument for ``bench/gui.py``, not part of the product's window.

A stall is a gap between two runs of a short Qt timer (:data:`BEAT_MS`) on the GUI thread: the
event loop did not come back for that long. The tracer says *why*, from three sources that do
not depend on guessing:

* **stack samples**: a watchdog thread wakes every :data:`SAMPLE_S`; while the beat is late by
  more than :data:`SAMPLE_AFTER_S` it records the GUI thread's Python stack
  (``sys._current_frames``): the slot, handler or harness code that was running. C++ work
  with no Python on the stack (painting, layout) shows as the event loop's own frame;
* **events**: an application event filter notes each event the GUI thread dispatches (its
  type and the receiver's class), so a paint (``UpdateRequest``/``Paint``), a timer slot
  (``Timer`` on the timer's object) or a queued signal (``MetaCall``) is named;
* **CPU and collector**: the GUI thread's CPU time over the gap (read from the watchdog by
  the thread's CPU clock) tells work from waiting (for a core on a loaded machine, or for the
  GIL another thread held); ``gc.callbacks`` time every collection the GUI thread ran.

Each stall longer than ``threshold_s`` becomes a :class:`Stall`; :meth:`StallTracer.report`
aggregates them by their dominant cause.
"""
from __future__ import annotations

import collections
import gc
import sys
import threading
import time
from dataclasses import dataclass, field
from types import FrameType
from typing import Any

from PySide6.QtCore import QEvent, QObject, QTimer

#: The beat timer's period (ms): the stall resolution.
BEAT_MS = 5
#: Watchdog sampling period (s).
SAMPLE_S = 0.002
#: The watchdog samples the stack once the beat is this late (s).
SAMPLE_AFTER_S = 0.010
#: Frames kept per stack sample (innermost first).
STACK_DEPTH = 6
#: Events kept per stall.
EVENTS_PER_STALL = 40


@dataclass
class Stall:
    """One gap of the GUI thread's beat longer than the tracer's threshold."""

    began_s: float                    # monotonic time of the last beat before the gap
    gap_s: float
    cpu_s: float = float("nan")       # the GUI thread's CPU time during the gap
    stacks: collections.Counter[str] = field(default_factory=collections.Counter)
    events: list[tuple[float, str]] = field(default_factory=list)   # (offset s, what)
    gc_s: float = 0.0                 # time in the cyclic collector during the gap
    gc_runs: list[tuple[int, float]] = field(default_factory=list)  # (generation, s)

    @property
    def cpu_share(self) -> float:
        return self.cpu_s / self.gap_s if self.gap_s > 0 else float("nan")

    def cause(self) -> str:
        """The dominant cause in a few words: the collector, the most sampled stack's
        innermost frame of interest, or the events dispatched when no Python ran."""
        if self.gc_s > 0.5 * self.gap_s:
            return "gc collection"
        if self.stacks:
            top, _ = self.stacks.most_common(1)[0]
            return top.split(" < ")[0]
        kinds = collections.Counter(what for _, what in self.events)
        if kinds:
            return "C++ only: " + ", ".join(k for k, _ in kinds.most_common(3))
        return "no sample (short)"

    def as_dict(self) -> dict[str, Any]:
        return {"at_s": round(self.began_s, 3), "gap_ms": round(1e3 * self.gap_s, 1),
                "gui_cpu_ms": round(1e3 * self.cpu_s, 1), "gc_ms": round(1e3 * self.gc_s, 1),
                "gc_runs": [(g, round(1e3 * s, 1)) for g, s in self.gc_runs],
                "cause": self.cause(),
                "stacks": self.stacks.most_common(4),
                "events": [(round(1e3 * t, 1), what) for t, what in self.events]}


def _stack(frame: FrameType | None) -> str:
    parts: list[str] = []
    while frame is not None and len(parts) < STACK_DEPTH:
        code = frame.f_code
        module = frame.f_globals.get("__name__", "?")
        parts.append(f"{module}.{code.co_name}:{frame.f_lineno}")
        frame = frame.f_back
    return " < ".join(parts)


class _EventNotes(QObject):
    """The application's event filter: the last events dispatched, (monotonic time, what)."""

    def __init__(self) -> None:
        super().__init__()
        self.recent: collections.deque[tuple[float, str]] = collections.deque(maxlen=400)
        self._names: dict[int, str] = {}

    def eventFilter(self, watched: QObject, event: QEvent) -> bool:
        kind = int(event.type().value)
        name = self._names.get(kind)
        if name is None:
            name = self._names[kind] = event.type().name
        self.recent.append((time.monotonic(), f"{name}→{type(watched).__name__}"))
        return False


class StallTracer:
    """Start on the GUI thread (``start``), stop with ``stop``; ``stalls`` then holds every
    gap longer than ``threshold_s`` with its attribution (module docstring)."""

    def __init__(self, threshold_s: float = 0.025, events: bool = True) -> None:
        self.threshold_s = threshold_s
        self.stalls: list[Stall] = []
        self.gaps: list[float] = []
        self._events = _EventNotes() if events else None
        self._timer = QTimer()
        self._timer.setInterval(BEAT_MS)
        self._timer.timeout.connect(self._beat)
        self._gui = threading.get_ident()
        self._cpu_clock = time.pthread_getcpuclockid(self._gui)
        self._last = time.monotonic()
        self._last_cpu = 0.0
        self._samples: collections.Counter[str] = collections.Counter()
        self._lock = threading.Lock()
        self._gc: list[tuple[float, float, int]] = []   # (start, end, generation), GUI thread
        self._gc_began: float | None = None
        self._quit = threading.Event()
        self._watchdog = threading.Thread(target=self._watch, name="stall-tracer", daemon=True)

    def start(self) -> None:
        from PySide6.QtCore import QCoreApplication

        app = QCoreApplication.instance()
        if self._events is not None and app is not None:
            app.installEventFilter(self._events)
        gc.callbacks.append(self._on_gc)
        self._last = time.monotonic()
        self._last_cpu = time.clock_gettime(self._cpu_clock)
        self._timer.start()
        self._watchdog.start()

    def stop(self) -> None:
        from PySide6.QtCore import QCoreApplication

        self._timer.stop()
        self._quit.set()
        self._watchdog.join(timeout=1.0)
        if self._on_gc in gc.callbacks:
            gc.callbacks.remove(self._on_gc)
        app = QCoreApplication.instance()
        if self._events is not None and app is not None:
            app.removeEventFilter(self._events)

    # ------------------------------------------------------------------ GUI thread

    def _on_gc(self, phase: str, info: dict[str, Any]) -> None:
        if threading.get_ident() != self._gui:
            return
        now = time.monotonic()
        if phase == "start":
            self._gc_began = now
        elif self._gc_began is not None:
            self._gc.append((self._gc_began, now, int(info.get("generation", -1))))
            self._gc_began = None

    def _beat(self) -> None:
        now = time.monotonic()
        cpu = time.clock_gettime(self._cpu_clock)
        gap = now - self._last
        self.gaps.append(gap)
        if gap > self.threshold_s:
            with self._lock:
                samples, self._samples = self._samples, collections.Counter()
            stall = Stall(self._last, gap, cpu - self._last_cpu, samples)
            began = self._last
            if self._events is not None:
                stall.events = [(t - began, what) for t, what in self._events.recent
                                if began <= t <= now][:EVENTS_PER_STALL]
            for g0, g1, gen in self._gc:
                if g1 >= began and g0 <= now:
                    stall.gc_s += g1 - g0
                    stall.gc_runs.append((gen, g1 - g0))
            self.stalls.append(stall)
        else:
            with self._lock:
                self._samples.clear()
        self._gc = [g for g in self._gc if g[1] >= now - 1.0]
        self._last, self._last_cpu = now, cpu

    # ------------------------------------------------------------------ watchdog thread

    def _watch(self) -> None:
        while not self._quit.wait(SAMPLE_S):
            if time.monotonic() - self._last < SAMPLE_AFTER_S:
                continue
            frame = sys._current_frames().get(self._gui)
            text = _stack(frame)
            with self._lock:
                self._samples[text] += 1

    # ------------------------------------------------------------------ report

    def report(self, top: int = 8) -> dict[str, Any]:
        """The longest stalls with their attribution, and the stalls grouped by cause
        (count, longest, total)."""
        by_cause: dict[str, list[float]] = collections.defaultdict(list)
        for s in self.stalls:
            by_cause[s.cause()].append(s.gap_s)
        longest = sorted(self.stalls, key=lambda s: s.gap_s, reverse=True)[:top]
        cpu = [s.cpu_s for s in self.stalls if s.cpu_s == s.cpu_s]
        return {"stalls_over_threshold": len(self.stalls),
                # The GUI thread's own work in a stall (its CPU time), which a quiet machine
                # would not hide: the longest, and how many stalls had more than the
                # threshold of it (the rest of a long gap is waiting for a core or the GIL).
                "max_gui_cpu_in_a_stall_ms": round(1e3 * max(cpu, default=0.0), 1),
                "stalls_with_gui_cpu_over_threshold": sum(c > self.threshold_s for c in cpu),
                "threshold_ms": round(1e3 * self.threshold_s, 1),
                "causes": sorted(([c, len(v), round(1e3 * max(v), 1), round(1e3 * sum(v), 1)]
                                  for c, v in by_cause.items()),
                                 key=lambda r: -float(r[2])),
                "longest": [s.as_dict() for s in longest]}
