"""The band across the top of every page: robot state in words and colour, the connection,
who owns the robot, the patient; an alarm the staff must act on (the RT status's ``alarms``:
a pull the robot cannot end) on whichever page is open; a latched fault's cause with a Reset
that says what it clears and asks for acknowledgement (inline, never a modal dialog that could
hide STOP)."""
from __future__ import annotations

from typing import Any

from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import QHBoxLayout, QLabel, QPushButton, QVBoxLayout, QWidget

from app.i18n import tr
from app.style import TARGET_PX
from app.words import (
    STATE_COLOURS,
    alarm_instruction,
    cause_words,
    display_state,
    state_words,
)

# The alarm's own look inside the band, whatever the state's colour (the band's style sheet
# carries it: a label's own sheet would lose to the band's ``QLabel`` rule).
ALARM_STYLE = ("#statusBand QLabel#staffAlarm { background: #b00020; font-size: 16pt; "
               "font-weight: bold; padding: 8px; }")


def _set_text(label: QLabel, text: str) -> None:
    """Set ``text`` unless the label shows it already (no relayout for nothing)."""
    if label.text() != text:
        label.setText(text)


def _set_visible(widget: QWidget, visible: bool) -> None:
    if widget.isHidden() == visible:
        widget.setVisible(visible)


class StatusBand(QWidget):
    """Shows the latest ``status`` and connection; emits ``reset_confirmed(ids)`` once the
    user acknowledged exactly the faults listed."""

    reset_confirmed = Signal(list)

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self._colour = ""        # the band's colour now (its style sheet is set on a change)
        self.setObjectName("statusBand")
        self.setAttribute(Qt.WidgetAttribute.WA_StyledBackground, True)
        self.state = "disconnected"
        self.latched: list[dict[str, Any]] = []
        self._events: dict[int, dict[str, Any]] = {}
        self.state_label = QLabel()
        self.state_label.setObjectName("stateLabel")
        font = self.state_label.font()
        font.setPointSize(16)
        font.setBold(True)
        self.state_label.setFont(font)
        self.detail_label = QLabel()
        self.detail_label.setWordWrap(True)
        self.alarm_label = QLabel()
        self.alarm_label.setObjectName("staffAlarm")
        self.alarm_label.setWordWrap(True)
        self.alarm_label.hide()
        self.connection_label = QLabel()
        self.owner_label = QLabel()
        self.patient_label = QLabel()
        for label in (self.state_label, self.connection_label, self.owner_label,
                      self.patient_label):
            label.setWordWrap(True)   # a long reason must never widen the window
        self.reset_button = QPushButton(tr("Reset…"))
        self.reset_button.setMinimumHeight(TARGET_PX)
        self.reset_button.clicked.connect(self._ask_acknowledge)
        self.ack_label = QLabel()
        self.ack_label.setWordWrap(True)
        self.ack_button = QPushButton(tr("Patient checked: clear"))
        self.cancel_button = QPushButton(tr("Cancel"))
        for b in (self.ack_button, self.cancel_button):
            b.setMinimumHeight(TARGET_PX)
        self.ack_button.clicked.connect(self._acknowledge)
        self.cancel_button.clicked.connect(self._hide_acknowledge)

        top = QHBoxLayout()
        top.addWidget(self.state_label, 3)
        info = QVBoxLayout()
        info.addWidget(self.connection_label)
        info.addWidget(self.owner_label)
        info.addWidget(self.patient_label)
        top.addLayout(info, 2)
        top.addWidget(self.reset_button)
        ack = QHBoxLayout()
        ack.addWidget(self.ack_label, 1)
        ack.addWidget(self.ack_button)
        ack.addWidget(self.cancel_button)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(12, 6, 12, 6)
        layout.addWidget(self.alarm_label)
        layout.addLayout(top)
        layout.addWidget(self.detail_label)
        layout.addLayout(ack)
        self._hide_acknowledge()
        self.set_patient(None)
        self.update_status(None, False, tr("not connected yet"))

    # ------------------------------------------------------------------ updates

    def set_patient(self, code: str | None) -> None:
        self.patient_label.setText(tr("Patient: %1").replace("%1", code) if code
                                   else tr("No patient selected"))

    def remember_event(self, event: dict[str, Any]) -> None:
        """Keep a published fault event (its values say by how much a limit was passed); an
        alarm's warning is shown at once, before the next status carries it."""
        if isinstance(event.get("id"), int):
            self._events[event["id"]] = event
        if event.get("kind") == "warn" and event.get("cause") == "pull_in_stop":
            values = event.get("values") or {}
            self.show_alarms([{"cause": "pull_in_stop", "fz_n": values.get("fz_n")}])

    def show_alarms(self, alarms: list[dict[str, Any]]) -> None:
        """Show the alarms as instructions to the staff, or hide the alarm when there is none."""
        text = "\n".join(alarm_instruction(a) for a in alarms if isinstance(a, dict))
        _set_text(self.alarm_label, text)
        _set_visible(self.alarm_label, bool(text))

    def update_status(self, status: dict[str, Any] | None, connected: bool,
                      reason: str = "") -> None:
        """Show a ``status`` reply (four a second while connected). Only what changed is
        touched: a style sheet set again re-polishes the band and every label in it, and a
        label's text set again asks the window for a new layout — the GUI thread's stalls
        traced to this on the Run page (bench/gui.py --synthetic)."""
        self.state = display_state(status, connected)
        colour = STATE_COLOURS[self.state]
        if colour != self._colour:
            self._colour = colour
            self.setStyleSheet(f"#statusBand {{ background: {colour}; }} "
                               f"#statusBand QLabel {{ color: white; font-size: 12pt; }} "
                               + ALARM_STYLE)
        _set_text(self.state_label, state_words(self.state))
        _set_text(self.connection_label, tr("Robot connected") if connected
                  else tr("Robot NOT connected: %1").replace("%1", reason))
        owner = (status or {}).get("owner")
        _set_text(self.owner_label, tr("Controlled by: %1").replace("%1", owner["name"])
                  if isinstance(owner, dict) else tr("Nobody controls the robot"))
        alarms = (status or {}).get("alarms")
        if isinstance(alarms, list):
            # A status without the field (an older RT process) or none at all (the link
            # lost) leaves what is shown: the pull it was about is most likely still there.
            self.show_alarms(alarms)
        self.latched = list((status or {}).get("latched") or [])
        if self.latched:
            _set_text(self.detail_label, tr("Why: %1").replace("%1", "; ".join(
                self._fault_text(f) for f in self.latched)))
        else:
            _set_text(self.detail_label, "")
            if not self.ack_button.isHidden():
                self._hide_acknowledge()
        _set_visible(self.detail_label, bool(self.latched))
        _set_visible(self.reset_button, bool(self.latched) and connected)
        if not self.ack_button.isHidden() and [int(f["id"]) for f in self.latched] != \
                getattr(self, "_pending", []):
            self._ask_acknowledge()   # what Reset clears changed: show the new list

    def _fault_text(self, fault: dict[str, Any]) -> str:
        from app.words import event_words
        event = self._events.get(fault.get("id", -1))
        return event_words(event) if event else cause_words(str(fault.get("cause", "")))

    # ------------------------------------------------------------------ acknowledgement

    def _ask_acknowledge(self) -> None:
        self._pending = [int(f["id"]) for f in self.latched]
        lines = [f"• {self._fault_text(f)}" for f in self.latched]
        text = tr("Reset will clear:") + "\n" + "\n".join(lines)
        if not self.alarm_label.isHidden():
            # Reset hands the load back to the drives (after a hard stop it releases the
            # brakes): under a load they cannot hold, the platform sinks and pulls harder.
            text = tr("The strap is still pulling and the drives cannot hold this load: after "
                      "Reset the platform may sink and pull harder. Release the strap "
                      "first.") + "\n" + text
        self.ack_label.setText(text)
        for w in (self.ack_label, self.ack_button, self.cancel_button):
            w.show()
        self.ack_button.setFocus(Qt.FocusReason.OtherFocusReason)

    def _acknowledge(self) -> None:
        ids = getattr(self, "_pending", [])
        self._hide_acknowledge()
        if ids:
            self.reset_confirmed.emit(ids)

    def _hide_acknowledge(self) -> None:
        for w in (self.ack_label, self.ack_button, self.cancel_button):
            w.hide()
