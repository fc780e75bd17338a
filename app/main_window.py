"""The main window: status band on top, the page rail on the left, STOP and E-STOP at the right
edge on every page (GUI.md). Pages are one click (or Ctrl+1…) away each; Calibrate shows for
the calibration engineer, Users for the administrator."""
from __future__ import annotations

from pathlib import Path
from typing import Any

from PySide6.QtGui import QKeySequence, QShortcut
from PySide6.QtWidgets import (
    QButtonGroup,
    QHBoxLayout,
    QLabel,
    QMainWindow,
    QPushButton,
    QStackedWidget,
    QVBoxLayout,
    QWidget,
)

from app.i18n import tr
from app.idle_lock import IdleWatcher
from app.main_thread_gc import MainThreadGc
from app.pages.prescribe import PrescribePage
from app.pages.review import ReviewPage
from app.pages.run import RunPage
from app.pages.settings_page import SettingsPage
from app.patient_context import PatientContext
from app.rt_link import RtLink
from app.settings import GuiSettings
from app.status_band import StatusBand
from app.stop_panel import StopPanel
from app.style import LARGE_PX

#: The clinic touchscreen (issue 14): everything fits without horizontal scrolling.
SCREEN_SIZE = (1366, 768)
RAIL_WIDTH_PX = 150
#: The pages in rail order (screenshots are named after them); login, patients and users (the
#: admin's) come with a clinical record.
PAGE_KEYS = ("login", "patients", "prescribe", "run", "review", "calibrate", "settings",
             "users")


class MainWindow(QMainWindow):
    """Composes the pages around one :class:`RtLink` (None: no robot, e.g. docs screenshots)."""

    def __init__(self, link: RtLink | None, settings: GuiSettings,
                 settings_path: Path | None = None, record: Any = None,
                 idle_clock: Any = None) -> None:
        super().__init__()
        # Cyclic garbage collection only on this (GUI) thread while the window is open: see
        # app/main_thread_gc.py for the deadlock it prevents.
        self.gc = MainThreadGc(self)
        self.gc.start()
        self.setWindowTitle(tr("talus — rehabilitation robot"))
        self.link = link
        self.settings = settings
        self.patient: PatientContext | None = None
        self.band = StatusBand()
        self.stops = StopPanel(self)
        rec_dir = Path(settings.recordings_dir) if settings.recordings_dir else None
        self.prescribe = PrescribePage(link)
        self.run = RunPage(link)
        self.review = ReviewPage(rec_dir, settings=settings, record=record,
                                 actor=lambda: self.actor)
        self.settings_page = SettingsPage(settings, settings_path)
        from app.pages.calibrate import CalibratePage
        self.calibrate = CalibratePage(settings=settings, record=record,
                                       actor=lambda: self.actor, link=link)
        self.pages: dict[str, QWidget] = {}
        self.stack = QStackedWidget()
        self.rail = QVBoxLayout()
        self.rail_group = QButtonGroup(self)
        self.rail_buttons: dict[str, QPushButton] = {}
        self.record = record
        self.actor: Any = None
        entries: list[tuple[str, str, QWidget]] = []
        if record is not None:
            from app.pages.login import LoginPage
            from app.pages.patients import PatientsPage
            self.login = LoginPage(record)
            self.patients = PatientsPage(record, settings=settings)
            entries += [("login", tr("Log in"), self.login),
                        ("patients", tr("Patients"), self.patients)]
        entries += [("prescribe", tr("Prescribe"), self.prescribe),
                   ("run", tr("Run"), self.run),
                   ("review", tr("Review"), self.review),
                   ("calibrate", tr("Calibrate"), self.calibrate),
                   ("settings", tr("Settings"), self.settings_page)]
        if record is not None:
            from app.pages.users import UsersPage
            self.users = UsersPage(record)
            entries.append(("users", tr("Users"), self.users))
        for key, label, page in entries:
            self.add_page(key, label, page)
        self.rail.addStretch(1)
        self.who = QLabel()
        self.who.setWordWrap(True)
        self.logout_button = QPushButton(tr("Log out"))
        self.logout_button.setMinimumHeight(LARGE_PX)
        self.logout_button.clicked.connect(lambda: self.lock(tr("Logged out.")))
        self.rail.addWidget(self.who)
        self.rail.addWidget(self.logout_button)
        self.logout_button.setVisible(record is not None)
        self.idle: IdleWatcher | None = None
        if record is not None:
            from app.journal import SessionJournal
            self.run.journal = SessionJournal(record, lambda: self.actor)
            self.login.logged_in.connect(self._logged_in)
            self.patients.patient_chosen.connect(self._patient_chosen)
            kwargs = {} if idle_clock is None else {"clock": idle_clock}
            self.idle = IdleWatcher(settings.idle_lock_s, self.session_running, **kwargs,
                                    parent=self)
            from PySide6.QtWidgets import QApplication
            self.idle.start(QApplication.instance())  # type: ignore[arg-type]
            self.idle.lock_requested.connect(lambda: self.lock(
                tr("Locked after %1 min without use.").replace(
                    "%1", f"{settings.idle_lock_s / 60:g}")))

        rail_widget = QWidget()
        rail_widget.setFixedWidth(RAIL_WIDTH_PX)
        rail_widget.setLayout(self.rail)
        body = QHBoxLayout()
        body.setContentsMargins(0, 0, 0, 0)
        body.addWidget(rail_widget)
        body.addWidget(self.stack, 1)
        body.addWidget(self.stops)
        central = QWidget()
        outer = QVBoxLayout(central)
        outer.setContentsMargins(0, 0, 0, 0)
        outer.setSpacing(0)
        outer.addWidget(self.band)
        outer.addLayout(body, 1)
        self.setCentralWidget(central)
        self.resize(*SCREEN_SIZE)

        self.prescribe.start_requested.connect(self._prescribed)
        self.run.session_ended.connect(lambda _s: self.review.refresh())
        self.band.reset_confirmed.connect(self.reset)
        self.stops.stop_pressed.connect(self.stop)
        self.stops.estop_pressed.connect(self.estop)
        if link is not None:
            link.status_changed.connect(self._status)
            link.connection_changed.connect(self._connection)
            link.event_received.connect(self.band.remember_event)
            link.replied.connect(self._replied)
        self.show_page(next(iter(self.pages)))
        if record is not None:
            self._apply_role()
        self.gc.freeze_built()

    # ------------------------------------------------------------------ users

    def _logged_in(self, actor: Any) -> None:
        self.actor = actor
        self.who.setText(f"{actor.username}\n({actor.role.value})")
        self.patients.set_actor(actor)
        self.users.set_actor(actor)
        if self.idle is not None:
            self.idle.reset()
        self._apply_role()
        self.show_page("patients")

    def lock(self, why: str) -> None:
        """Back to the login page (logout or idle lock); STOP and E-STOP stay."""
        if self.record is None:
            return
        if self.actor is not None:
            self.record.logout(self.actor)
        self.actor = None
        self.who.setText("")
        self.patients.set_actor(None)
        self.users.set_actor(None)
        self._apply_role()
        self.login.ask(why)
        self.show_page("login")

    def may(self, action: str) -> bool:
        """Whether the logged-in role may ``action`` (``patients.roles``); no record: yes."""
        if self.record is None:
            return True
        if self.actor is None:
            return False
        from patients.roles import Action, allowed
        return allowed(self.actor.role, Action(action))

    def _apply_role(self) -> None:
        logged_in = self.actor is not None
        for key, button in self.rail_buttons.items():
            button.setEnabled(key == "login" or logged_in)
        self.rail_buttons["login"].setVisible(not logged_in)
        self.rail_buttons["users"].setVisible(self.may("users.manage"))
        # The calibration engineer's wizard (the record stores what it certifies).
        self.rail_buttons["calibrate"].setVisible(self.may("calibration.write"))
        self.logout_button.setVisible(logged_in)
        self.run.may_run = self.may("session.run")
        self.run.update_buttons()

    def _patient_chosen(self, patient: PatientContext) -> None:
        self.set_patient(patient)
        self.show_page("prescribe")

    # ------------------------------------------------------------------ pages

    def add_page(self, key: str, label: str, page: QWidget) -> None:
        """Add a page and its rail button (Ctrl+<n> jumps to the n-th page)."""
        index = self.stack.addWidget(page)
        self.pages[key] = page
        button = QPushButton(label)
        button.setObjectName(f"rail:{key}")
        button.setCheckable(True)
        button.setMinimumHeight(LARGE_PX)
        self.rail_group.addButton(button, index)
        button.clicked.connect(lambda _c=False, k=key: self.show_page(k))
        self.rail.insertWidget(index, button)
        self.rail_buttons[key] = button
        if index < 9:
            sc = QShortcut(QKeySequence(f"Ctrl+{index + 1}"), self)
            sc.activated.connect(lambda k=key: self.show_page(k))

    def show_page(self, key: str) -> None:
        page = self.pages[key]
        self.stack.setCurrentWidget(page)
        self.rail_buttons[key].setChecked(True)

    def set_patient(self, patient: PatientContext | None) -> None:
        """The patient every session page works for."""
        self.patient = patient
        self.band.set_patient(None if patient is None else patient.code)
        self.prescribe.set_patient(patient)
        self.run.set_patient(patient)

    def _prescribed(self, document: dict[str, Any]) -> None:
        self.run.prescribe(document)
        self.show_page("run")

    # ------------------------------------------------------------------ robot

    def stop(self) -> None:
        if self.link is not None:
            self.link.stop()

    def estop(self, source: str) -> None:
        if self.link is not None:
            self.link.estop(source)

    def reset(self, ids: list[int]) -> None:
        if self.link is not None:
            self.link.call("reset", lambda c: c.reset(list(ids)))

    def _replied(self, tag: str, result: object, error: str) -> None:
        if tag == "reset" and error:
            self.band.detail_label.setText(tr("Reset refused: %1").replace("%1", error))
            self.band.detail_label.show()

    def _status(self, status: dict[str, Any]) -> None:
        assert self.link is not None
        self.band.update_status(status, self.link.connected)

    def _connection(self, connected: bool, reason: str) -> None:
        self.band.update_status(self.link.last_status if self.link else None, connected, reason)
        self.run.update_buttons()

    def session_running(self) -> bool:
        """True while the robot runs a session (the idle lock waits for its end)."""
        st = None if self.link is None else self.link.last_status
        return bool(st and st.get("session"))

    def closeEvent(self, event: Any) -> None:
        if self.link is not None:
            self.link.close()
        self.gc.stop()
        super().closeEvent(event)

