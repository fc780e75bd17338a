"""Log in with the clinical record's users (``ClinicalRecord.authenticate``: Argon2, lockout
after repeated failures — checked on a worker, never on the GUI thread). Also the idle-lock
screen: the same page, asking again."""
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
        self.button = QPushButton(tr("Log in"))
        self.message = QLabel()
        self.message.setWordWrap(True)
        self.message.setStyleSheet("color: #c0262d;")
        for w in (self.user, self.password, self.button):
            w.setMinimumHeight(TARGET_PX)
        form = QFormLayout()
        form.addRow(tr("User name"), self.user)
        form.addRow(tr("Password"), self.password)
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
        self.user.returnPressed.connect(self.password.setFocus)

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
        self.button.setEnabled(False)
        self.message.setText(tr("Checking…"))
        self.worker.call("login", lambda: self.record.authenticate(user, password))

    def _done(self, tag: str, actor: object, error: str) -> None:
        self.button.setEnabled(True)
        self.password.clear()
        if error:
            self.message.setText(error)
            return
        self.message.setText("")
        self.logged_in.emit(actor)
