"""STOP (soft) and E-STOP (hard) at the right edge, full height, on every page (GUI.md), each
with its keyboard shortcut printed on it. The shortcuts are application-wide: they work
whatever widget has the focus. Both act even when the connection looks lost (the stop is
sent anyway: it costs nothing, and the link may be back)."""
from __future__ import annotations

from PySide6.QtCore import Qt, Signal
from PySide6.QtGui import QFont, QFontMetrics, QKeySequence, QShortcut
from PySide6.QtWidgets import QPushButton, QSizePolicy, QVBoxLayout, QWidget

from app.i18n import tr

#: Keys: Esc for STOP (the key a hand finds without looking), F12 for E-STOP.
STOP_KEY = "Esc"
ESTOP_KEY = "F12"
#: GUI.md: STOP at least 120 px wide.
STOP_WIDTH_PX = 150


def _fitting_points(text: str, largest: int = 22, smallest: int = 11) -> int:
    """The largest bold point size at which every line of ``text`` fits the button (a
    translation may be longer than "STOP")."""
    for points in range(largest, smallest - 1, -1):
        font = QFont()
        font.setPointSize(points)
        font.setBold(True)
        metrics = QFontMetrics(font)
        if all(metrics.horizontalAdvance(line) <= STOP_WIDTH_PX - 20
               for line in text.splitlines()):
            return points
    return smallest


class StopPanel(QWidget):
    """Emits ``stop_pressed`` / ``estop_pressed(source)`` (source "gui" or "keyboard")."""

    stop_pressed = Signal()
    estop_pressed = Signal(str)

    def __init__(self, shortcut_parent: QWidget, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setFixedWidth(STOP_WIDTH_PX)
        self.stop_button = QPushButton(tr("STOP") + f"\n[{STOP_KEY}]")
        self.stop_button.setObjectName("stopButton")
        self.estop_button = QPushButton(tr("E-STOP") + f"\n[{ESTOP_KEY}]")
        self.estop_button.setObjectName("estopButton")
        for b, colour in ((self.stop_button, "#d08a00"), (self.estop_button, "#c0262d")):
            b.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Expanding)
            b.setMinimumHeight(120)
            b.setFocusPolicy(Qt.FocusPolicy.TabFocus)
            b.setStyleSheet(f"QPushButton {{ background: {colour}; color: white; "
                            f"font-size: {_fitting_points(b.text())}pt; font-weight: bold; "
                            f"border-radius: 8px; }}")
        self.stop_button.clicked.connect(self.stop_pressed.emit)
        self.estop_button.clicked.connect(lambda: self.estop_pressed.emit("gui"))
        layout = QVBoxLayout(self)
        layout.setContentsMargins(4, 4, 4, 4)
        layout.addWidget(self.stop_button, 3)
        layout.addWidget(self.estop_button, 2)
        self.shortcuts = []
        for key, slot in ((STOP_KEY, self.stop_pressed.emit),
                          (ESTOP_KEY, lambda: self.estop_pressed.emit("keyboard"))):
            sc = QShortcut(QKeySequence(key), shortcut_parent)
            sc.setContext(Qt.ShortcutContext.ApplicationShortcut)
            sc.activated.connect(slot)
            self.shortcuts.append(sc)
