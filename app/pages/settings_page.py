"""Settings: RT endpoint, database URL, recordings folder, clinic name and logo (for reports),
language, idle lock and RT timeout. Saved atomically; a field the model refuses is named next
to Save and nothing is written."""
from __future__ import annotations

from pathlib import Path

from pydantic import ValidationError
from PySide6.QtCore import Signal
from PySide6.QtWidgets import (
    QComboBox,
    QFormLayout,
    QLabel,
    QLineEdit,
    QPushButton,
    QVBoxLayout,
    QWidget,
)

from app import settings as settings_io
from app.i18n import LANGUAGES, tr
from app.settings import GuiSettings
from app.style import TARGET_PX


class SettingsPage(QWidget):
    """Emits ``saved(settings)`` after a successful save."""

    saved = Signal(object)

    def __init__(self, current: GuiSettings, path: Path | None,
                 parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.path = path
        self.current = current
        self.endpoint = QLineEdit(current.rt_endpoint)
        self.database = QLineEdit(current.database_url)
        self.database.setPlaceholderText(tr("default: the local SQLite clinical record"))
        self.recordings = QLineEdit(current.recordings_dir)
        self.clinic = QLineEdit(current.clinic_name)
        self.logo = QLineEdit(current.clinic_logo)
        self.language = QComboBox()
        for code, name in LANGUAGES.items():
            self.language.addItem(name, code)
        self.language.setCurrentIndex(list(LANGUAGES).index(current.language))
        self.idle = QLineEdit(f"{current.idle_lock_s / 60:g}")
        self.timeout = QLineEdit(f"{current.rt_timeout_s:g}")
        form = QFormLayout()
        rows = ((tr("RT process endpoint"), self.endpoint),
                (tr("Clinical record database URL"), self.database),
                (tr("Recordings folder"), self.recordings),
                (tr("Clinic name (reports)"), self.clinic),
                (tr("Clinic logo file (reports)"), self.logo),
                (tr("Language"), self.language),
                (tr("Lock the screen after idle (minutes)"), self.idle),
                (tr("RT reply timeout (s)"), self.timeout))
        for label, widget in rows:
            widget.setMinimumHeight(TARGET_PX)
            form.addRow(label, widget)
        self.save_button = QPushButton(tr("Save"))
        self.save_button.setMinimumHeight(TARGET_PX)
        self.save_button.clicked.connect(self.save)
        self.result = QLabel()
        self.result.setWordWrap(True)
        layout = QVBoxLayout(self)
        layout.addLayout(form)
        layout.addWidget(self.save_button)
        layout.addWidget(self.result)
        layout.addStretch(1)

    def save(self) -> bool:
        """Validate and write; True when saved."""
        try:
            idle_min = float(self.idle.text().replace(",", "."))
            timeout = float(self.timeout.text().replace(",", "."))
        except ValueError:
            self.result.setText(tr("Idle lock and timeout must be numbers."))
            return False
        try:
            new = GuiSettings(
                rt_endpoint=self.endpoint.text().strip(),
                database_url=self.database.text().strip(),
                recordings_dir=self.recordings.text().strip(),
                clinic_name=self.clinic.text().strip(), clinic_logo=self.logo.text().strip(),
                language=self.language.currentData(), idle_lock_s=idle_min * 60.0,
                rt_timeout_s=timeout)
        except ValidationError as exc:
            err = exc.errors()[0]
            self.result.setText(tr("Not saved: %1").replace(
                "%1", f"{'.'.join(str(p) for p in err['loc'])}: {err['msg']}"))
            return False
        if self.path is not None:
            settings_io.save(new, self.path)
        self.current = new
        self.result.setText(tr("Saved. A new endpoint or language applies when the GUI "
                               "is started again."))
        self.saved.emit(new)
        return True
