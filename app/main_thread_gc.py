"""Python's cyclic garbage collector run on the GUI thread only, while a window is open.

The GUI's work runs on worker threads (record calls, fits, reports). Left automatic, the cyclic
collector runs in whichever thread happens to allocate when a generation fills; if it then
frees a Qt object there, ``QObject::~QObject`` takes Qt's connection mutex and calls back into
Python for the GIL, while the GUI thread (holding the GIL) waits for that mutex to delete
another widget: a deadlock, seen in the test suite with the calibration wizard's fit on a
worker. The cure Qt applications use (pyqtgraph's ``GarbageCollector`` does the same): turn
automatic collection off and collect on a timer of the GUI thread, generation by generation
with the interpreter's own thresholds. Reference counting still frees everything acyclic at
once; only cycles wait for the next tick.
"""
from __future__ import annotations

import gc

from PySide6.QtCore import QObject, QTimer

#: Period of the GUI-thread collection (ms): cycles live at most this long. Short, so each
#: collection walks few young objects: at 500 ms the Run page's half-second of allocations
#: made generation-1 collections of 47 ms of CPU (109-440 ms of stall on a loaded machine:
#: bench/gui.py --synthetic, the stall tracer); the check itself costs microseconds.
COLLECT_PERIOD_MS = 100


class MainThreadGc(QObject):
    """Holds automatic collection off from ``start`` to ``stop`` (windows may nest: the last
    ``stop`` collects once, on this thread, and turns automatic collection back on if it was
    on before the first ``start``)."""

    _holders = 0
    _was_enabled = False
    _epoch = 0          # release_all() starts a new one: older holders' stop() does nothing

    def __init__(self, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self._held = False
        self._timer = QTimer(self)
        self._timer.setInterval(COLLECT_PERIOD_MS)
        self._timer.timeout.connect(collect_by_generation)

    def start(self) -> None:
        if self._held:
            return
        if MainThreadGc._holders == 0:
            MainThreadGc._was_enabled = gc.isenabled()
            gc.disable()
        MainThreadGc._holders += 1
        self._held = True
        self._epoch = MainThreadGc._epoch
        self._timer.start()

    def freeze_built(self) -> None:
        """Called once the window is built: what exists now (modules, Qt wrappers, the
        pages) lives as long as the window; frozen (``gc.freeze``), the collector no longer
        walks it, so a full collection on the GUI thread walks only what was made since (one
        took 143 ms on a loaded machine: bench/gui.py --synthetic, the stall tracer).
        ``stop`` of the last window unfreezes."""
        if self._held:
            gc.collect()
            gc.freeze()

    def stop(self) -> None:
        if not self._held:
            return
        self._timer.stop()
        self._held = False
        if self._epoch != MainThreadGc._epoch:
            return
        MainThreadGc._holders -= 1
        if MainThreadGc._holders == 0:
            gc.unfreeze()
            gc.collect()
            if MainThreadGc._was_enabled:
                gc.enable()

    @classmethod
    def holders(cls) -> int:
        return cls._holders

    @classmethod
    def release_all(cls) -> None:
        """Give collection back whatever windows are still open (call on the GUI thread: a
        test's teardown, an application's exit)."""
        if cls._holders == 0:
            return
        cls._holders = 0
        cls._epoch += 1
        gc.unfreeze()
        gc.collect()
        if cls._was_enabled:
            gc.enable()


def collect_by_generation() -> None:
    """What the automatic collector would have done by now, on the calling (GUI) thread."""
    t0, t1, t2 = gc.get_threshold()
    c0, c1, c2 = gc.get_count()
    if c0 > t0:
        gc.collect(2 if (c1 > t1 and c2 > t2) else 1 if c1 > t1 else 0)
