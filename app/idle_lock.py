"""Idle lock: after ``timeout_s`` without a key press, click or touch the screen locks (the
login page asks for a password again) — never while a session runs: a clinician whose hands
are on the patient must not find STOP behind a password prompt (STOP and E-STOP stay on top
of the lock anyway).

The clock is injected, so the tests need no waiting.
"""
from __future__ import annotations

import time
from collections.abc import Callable

from PySide6.QtCore import QEvent, QObject, QTimer, Signal

#: Events that count as the user being there.
_ACTIVITY = {QEvent.Type.KeyPress, QEvent.Type.MouseButtonPress, QEvent.Type.TouchBegin,
             QEvent.Type.Wheel}


class IdleWatcher(QObject):
    """Emits ``lock_requested`` once the user was idle for ``timeout_s`` and ``busy()`` is
    False; re-armed by :meth:`reset` (after a new login).

    Args:
        timeout_s: idle time before locking, s.
        busy: True while locking must wait (a session runs).
        clock: monotonic seconds (injected by tests).
        check_period_ms: how often the idle time is checked.
    """

    lock_requested = Signal()

    def __init__(self, timeout_s: float, busy: Callable[[], bool],
                 clock: Callable[[], float] = time.monotonic,
                 check_period_ms: int = 1000, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self.timeout_s = timeout_s
        self.busy = busy
        self.clock = clock
        self.last_activity = clock()
        self.locked = False
        self.timer = QTimer(self)
        self.timer.setInterval(check_period_ms)
        self.timer.timeout.connect(self.check)

    def start(self, app: QObject) -> None:
        """Watch every event of ``app`` (the QApplication) and check periodically."""
        app.installEventFilter(self)
        self.timer.start()

    def eventFilter(self, watched: QObject, event: QEvent) -> bool:
        if event.type() in _ACTIVITY:
            self.last_activity = self.clock()
        return False

    def reset(self) -> None:
        """Unlocked (a new login): count idleness from now."""
        self.locked = False
        self.last_activity = self.clock()

    def check(self) -> None:
        """Lock if idle long enough and nothing forbids it (called by the timer)."""
        if self.locked:
            return
        if self.busy():
            self.last_activity = self.clock()   # a session counts as activity
            return
        if self.clock() - self.last_activity >= self.timeout_s:
            self.locked = True
            self.lock_requested.emit()
