"""Log in with the clinical record's users (``ClinicalRecord.authenticate``: Argon2, lockout
after repeated failures — checked on a worker, never on the GUI thread). Also the idle-lock
screen: the same page, asking again.

On a database with no user yet (a fresh installation) the page sets up the first
administrator instead (``ClinicalRecord.init_admin``: refused once any user exists, so a
second window cannot do it twice), and logs them in."""
from __future__ import annotations

from typing import Any

from PySide6.QtCore import Signal
from PySide6.QtWidgets import QFormLayout, QLabel, QLineEdit, QPushButton, QVBoxLayout, QWidget

from app.background import Background
from app.i18n import tr
from app.style import TARGET_PX


class LoginPage(QWidget):
    """Emits ``logged_in(actor)`` (a ``patients.service.Actor``)."""

    logged_in = Signal(object)

    def __init__(self, record: Any, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.record = record
        self.worker = Background("gui-login", self)
        self.worker.done.connect(self._done)
        self.title = QLabel(tr("Log in to use the robot"))
        font = self.title.font()
        font.setPointSize(16)
        self.title.setFont(font)
        self.user = QLineEdit()
        self.user.setObjectName("username")
        self.password = QLineEdit()
        self.password.setObjectName("password")
        self.password.setEchoMode(QLineEdit.EchoMode.Password)
        self.password2 = QLineEdit()
        self.password2.setObjectName("password2")
        self.password2.setEchoMode(QLineEdit.EchoMode.Password)
        self.button = QPushButton(tr("Log in"))
        #: True while the page creates the first administrator (the record has no user)
        self.first_admin = False
        #: the record answered whether it has users
        self.checked_users = False
        self.message = QLabel()
        self.message.setWordWrap(True)
        self.message.setStyleSheet("color: #c0262d;")
        for w in (self.user, self.password, self.password2, self.button):
            w.setMinimumHeight(TARGET_PX)
        form = QFormLayout()
        form.addRow(tr("User name"), self.user)
        form.addRow(tr("Password"), self.password)
        self.password2_label = QLabel(tr("Password again"))
        form.addRow(self.password2_label, self.password2)
        self.password2.hide()
        self.password2_label.hide()
        box = QWidget()
        box.setMaximumWidth(520)
        inner = QVBoxLayout(box)
        inner.addWidget(self.title)
        inner.addLayout(form)
        inner.addWidget(self.button)
        inner.addWidget(self.message)
        layout = QVBoxLayout(self)
        layout.addStretch(1)
        layout.addWidget(box)
        layout.addStretch(2)
        self.button.clicked.connect(self.submit)
        self.password.returnPressed.connect(self.submit)
        self.password2.returnPressed.connect(self.submit)
        self.user.returnPressed.connect(self.password.setFocus)
        self.worker.call("has_users", record.has_users)

    def _setup_mode(self, on: bool) -> None:
        was, self.first_admin = self.first_admin, on
        self.password2.setVisible(on)
        self.password2_label.setVisible(on)
        if on:
            self.title.setText(tr("Create the first administrator"))
            self.button.setText(tr("Create administrator"))
        if on and not was:
            self.message.setText(tr("This database has no users yet. The administrator "
                                    "creates the other accounts (Users page)."))
        if not on:
            self.title.setText(tr("Log in to use the robot"))
            self.button.setText(tr("Log in"))

    def ask(self, why: str = "") -> None:
        """Show the page empty (after a logout or the idle lock), with the reason."""
        self.password.clear()
        self.message.setText(why)
        self.user.setFocus()

    def submit(self) -> None:
        user, password = self.user.text().strip(), self.password.text()
        if not user or not password:
            self.message.setText(tr("Enter your user name and password."))
            return
        record = self.record
        if self.first_admin:
            if password != self.password2.text():
                self.message.setText(tr("The two passwords differ."))
                return
            self.button.setEnabled(False)
            self.message.setText(tr("Creating…"))
            self.worker.call("init_admin", lambda: record.init_admin(user, password))
            return
        self.button.setEnabled(False)
        self.message.setText(tr("Checking…"))
        self.worker.call("login", lambda: record.authenticate(user, password))

    def _done(self, tag: str, actor: object, error: str) -> None:
        if tag == "has_users":
            self.checked_users = True
            self._setup_mode(not error and actor is False)
            return
        self.button.setEnabled(True)
        self.password.clear()
        self.password2.clear()
        if error:
            self.message.setText(error)
            if tag == "init_admin":    # e.g. another window created one meanwhile
                self.worker.call("has_users", self.record.has_users)
            return
        if tag == "init_admin":
            self._setup_mode(False)
        self.message.setText("")
        self.logged_in.emit(actor)
