"""Users (admin role): the accounts with their role and state; create a user with a role, change
a role, deactivate or reactivate an account, reset a password (which also unlocks it).

The record checks the role and audits every change (``patients.service``,
``patients.user_roles``); the page only shows what the admin may do. Every call runs on a
worker. Passwords are typed twice and never shown.
"""
from __future__ import annotations

import datetime as dt
from typing import Any

from PySide6.QtCore import Qt
from PySide6.QtWidgets import (
    QComboBox,
    QFormLayout,
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QListWidget,
    QListWidgetItem,
    QPushButton,
    QVBoxLayout,
    QWidget,
)

from app.background import Background
from app.i18n import tr
from app.style import TARGET_PX


def role_words(role: str) -> str:
    return {"admin": tr("administrator"), "clinician": tr("clinician"),
            "engineer": tr("calibration engineer"), "viewer": tr("viewer")}.get(role, role)


def locked_now(user: dict[str, Any], now: dt.datetime | None = None) -> bool:
    """Whether the account is locked (after wrong passwords) at ``now`` (default: UTC now)."""
    until = user.get("locked_until")
    if not until:
        return False
    t = dt.datetime.fromisoformat(str(until))
    if t.tzinfo is None:
        t = t.replace(tzinfo=dt.UTC)
    return t > (now or dt.datetime.now(dt.UTC))


def _role_combo() -> QComboBox:
    combo = QComboBox()
    for role in ("clinician", "engineer", "viewer", "admin"):
        combo.addItem(role_words(role), role)
    return combo


def _password_edit(name: str) -> QLineEdit:
    edit = QLineEdit()
    edit.setObjectName(name)
    edit.setEchoMode(QLineEdit.EchoMode.Password)
    return edit


class UsersPage(QWidget):
    """The accounts of the clinical record (admin only)."""

    def __init__(self, record: Any, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.record = record
        self.actor: Any = None
        self.users: list[dict[str, Any]] = []
        self.worker = Background("gui-users", self)
        self.worker.done.connect(self._done)

        self.list = QListWidget()
        self.list.setStyleSheet("QListWidget::item { min-height: 40px; }")
        self.list.currentItemChanged.connect(lambda *_: self._enable())

        # new user
        self.new_name = QLineEdit()
        self.new_name.setObjectName("newUser")
        self.new_role = _role_combo()
        self.new_password = _password_edit("newPassword")
        self.new_password2 = _password_edit("newPassword2")
        self.create_button = QPushButton(tr("Create user"))
        self.create_button.clicked.connect(self.create_user)
        new_box = QGroupBox(tr("New user"))
        new_form = QFormLayout(new_box)
        new_form.addRow(tr("User name"), self.new_name)
        new_form.addRow(tr("Role"), self.new_role)
        new_form.addRow(tr("Password"), self.new_password)
        new_form.addRow(tr("Password again"), self.new_password2)
        new_form.addRow(self.create_button)

        # the chosen user
        self.role = _role_combo()
        self.role_button = QPushButton(tr("Change role"))
        self.role_button.clicked.connect(self.change_role)
        self.disable_button = QPushButton(tr("Deactivate"))
        self.disable_button.clicked.connect(self.toggle_disabled)
        self.reset_password = _password_edit("resetPassword")
        self.reset_password2 = _password_edit("resetPassword2")
        self.reset_button = QPushButton(tr("Reset password"))
        self.reset_button.clicked.connect(self.set_password)
        chosen_box = QGroupBox(tr("Chosen user"))
        chosen_form = QFormLayout(chosen_box)
        role_row = QHBoxLayout()
        role_row.addWidget(self.role, 1)
        role_row.addWidget(self.role_button)
        chosen_form.addRow(tr("Role"), role_row)
        chosen_form.addRow(self.disable_button)
        chosen_form.addRow(tr("New password"), self.reset_password)
        chosen_form.addRow(tr("Password again"), self.reset_password2)
        chosen_form.addRow(self.reset_button)

        self.message = QLabel()
        self.message.setWordWrap(True)
        for w in (self.new_name, self.new_role, self.new_password, self.new_password2,
                  self.create_button, self.role, self.role_button, self.disable_button,
                  self.reset_password, self.reset_password2, self.reset_button):
            w.setMinimumHeight(TARGET_PX)
        left = QVBoxLayout()
        left.addWidget(QLabel(tr("Users")))
        left.addWidget(self.list, 1)
        right = QVBoxLayout()
        right.addWidget(chosen_box)
        right.addWidget(new_box)
        right.addWidget(self.message)
        right.addStretch(1)
        layout = QHBoxLayout(self)
        layout.addLayout(left, 1)
        layout.addLayout(right, 1)
        self._enable()

    def set_actor(self, actor: Any) -> None:
        """Who is logged in; the list is loaded for an admin and cleared otherwise."""
        self.actor = actor
        self.users = []
        self.list.clear()
        self.message.setText("")
        if actor is not None and getattr(actor.role, "value", actor.role) == "admin":
            self.reload()
        self._enable()

    def chosen(self) -> dict[str, Any] | None:
        item = self.list.currentItem()
        if item is None:
            return None
        name = item.data(Qt.ItemDataRole.UserRole)
        return next((u for u in self.users if u["username"] == name), None)

    def _enable(self) -> None:
        user = self.chosen()
        mine = user is not None and self.actor is not None \
            and user["username"] == self.actor.username
        for w in (self.role, self.role_button, self.disable_button):
            w.setEnabled(user is not None and not mine)   # the record refuses it anyway
        for e in (self.reset_password, self.reset_password2, self.reset_button):
            e.setEnabled(user is not None)
        self.disable_button.setText(tr("Reactivate") if user and user["disabled"]
                                    else tr("Deactivate"))
        if user is not None:
            self.role.setCurrentIndex(max(0, self.role.findData(user["role"])))

    # ------------------------------------------------------------------ record calls

    def reload(self, select: str | None = None) -> None:
        actor, record = self.actor, self.record
        self.worker.call(f"list:{select or ''}", lambda: record.list_users(actor))

    def _passwords(self, a: QLineEdit, b: QLineEdit) -> str | None:
        if a.text() != b.text():
            self.message.setText(tr("The two passwords differ."))
            return None
        return a.text()

    def create_user(self) -> None:
        name = self.new_name.text().strip()
        password = self._passwords(self.new_password, self.new_password2)
        if password is None:
            return
        role = self.new_role.currentData()
        actor, record = self.actor, self.record
        self.worker.call("create", lambda: record.add_user(actor, name, role, password))

    def change_role(self) -> None:
        user = self.chosen()
        if user is None:
            return
        from patients.user_roles import set_user_role

        role, name = self.role.currentData(), user["username"]
        actor, record = self.actor, self.record
        self.worker.call("role", lambda: set_user_role(record, actor, name, role))

    def toggle_disabled(self) -> None:
        user = self.chosen()
        if user is None:
            return
        name, disable = user["username"], not user["disabled"]
        actor, record = self.actor, self.record

        def change() -> dict[str, Any]:
            record.set_user_disabled(actor, name, disable)
            return {"username": name}
        self.worker.call("disabled", change)

    def set_password(self) -> None:
        user = self.chosen()
        if user is None:
            return
        password = self._passwords(self.reset_password, self.reset_password2)
        if password is None:
            return
        name = user["username"]
        actor, record = self.actor, self.record

        def change() -> dict[str, Any]:
            record.set_password(actor, name, password)
            return {"username": name}
        self.worker.call("password", change)

    # ------------------------------------------------------------------ results

    def _done(self, tag: str, result: Any, error: str) -> None:
        if error:
            self.message.setText(error)
            return
        if tag.startswith("list:"):
            self.users = list(result)
            self._fill(tag[len("list:"):] or None)
            return
        name = result["username"]
        self.message.setText({
            "create": tr("User %1 created."), "role": tr("Role of %1 changed."),
            "disabled": tr("Account %1 changed."),
            "password": tr("Password of %1 reset (the account is unlocked)."),
        }[tag].replace("%1", name))
        for edit in (self.new_password, self.new_password2, self.reset_password,
                     self.reset_password2):
            edit.clear()
        if tag == "create":
            self.new_name.clear()
        self.reload(select=name)

    def _fill(self, select: str | None) -> None:
        current = self.chosen()
        select = select or (current["username"] if current else None)
        self.list.blockSignals(True)
        self.list.clear()
        for u in self.users:
            state = tr("deactivated") if u["disabled"] else (
                tr("locked") if locked_now(u) else tr("active"))
            item = QListWidgetItem(f"{u['username']} — {role_words(u['role'])} — {state}")
            item.setData(Qt.ItemDataRole.UserRole, u["username"])
            self.list.addItem(item)
            if u["username"] == select:
                self.list.setCurrentItem(item)
        self.list.blockSignals(False)
        self._enable()
