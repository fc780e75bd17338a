"""One "write a PDF report" action for any page: ask where (Qt's dialog, replaceable in tests),
refuse an existing file or a missing folder with a message (never overwrite), write on a worker
(reading a recording and drawing the figures takes seconds), remember the file written and
offer to open it. Review's session report and Patients' progress report both go through it;
the Calibrate wizard's certificate shares :func:`app.report_export.choose_report_target`.
"""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from PySide6.QtCore import QObject, Signal
from PySide6.QtWidgets import QPushButton, QWidget

from app.background import Background
from app.i18n import tr
from app.report_export import ask_pdf_path, choose_report_target, open_file
from app.settings import GuiSettings
from app.style import TARGET_PX
from rt.errors import TalusError

#: Writes the report to the path (new file) with the reports' settings; returns at least
#: ``{"out": str, "pages": int}`` (``app.report_export.write_session_report`` and friends).
ReportJob = Callable[[Path, Any], dict[str, Any]]


class ReportAction(QObject):
    """The report action of one page (module docstring).

    Signals: ``message(str)`` — what to tell the user (writing, written, refused, failed);
    ``busy_changed(bool)`` — a report is being written (the page disables its button).
    """

    message = Signal(str)
    busy_changed = Signal(bool)

    def __init__(self, parent: QWidget, name: str, settings: GuiSettings) -> None:
        super().__init__(parent)
        self.settings = settings
        #: where to save: (title, suggested path) → the chosen path, None to cancel
        self.ask_path: Callable[[str, Path], Path | None] = \
            lambda title, suggested: ask_pdf_path(parent, title, suggested)
        #: the folder the next report is suggested in (the last one's)
        self.folder = Path.home()
        #: the last report written, and its job's result
        self.last: Path | None = None
        self.last_result: dict[str, Any] | None = None
        self.busy = False
        self._worker = Background(name, self)
        self._worker.done.connect(self._done)
        self.open_button = QPushButton(tr("Open the report"))
        self.open_button.setMinimumHeight(TARGET_PX)
        self.open_button.setEnabled(False)
        self.open_button.clicked.connect(lambda: open_file(self.last))

    def write(self, title: str, file_name: str, job: ReportJob) -> None:
        """Ask where to save (``file_name`` suggested in the last folder), then run ``job``
        on the worker. Cancelled: nothing happens; a refused path: its message, nothing
        written."""
        if self.busy:
            return
        try:
            target = choose_report_target(self.ask_path, title, self.folder / file_name,
                                          self.settings)
        except TalusError as exc:
            self.message.emit(str(exc))
            return
        if target is None:
            return
        out, settings = target
        self.folder = out.parent
        self._set_busy(True)
        self.message.emit(tr("Writing the report…"))
        self._worker.call("report", lambda: job(out, settings))

    def _set_busy(self, busy: bool) -> None:
        self.busy = busy
        self.busy_changed.emit(busy)

    def _done(self, _tag: str, result: Any, error: str) -> None:
        self._set_busy(False)
        if error:
            self.message.emit(tr("No report: %1").replace("%1", error))
            return
        self.last = Path(result["out"])
        self.last_result = result
        self.open_button.setEnabled(True)
        self.message.emit(tr("Report written: %1 (%2 pages)").replace("%1", result["out"])
                          .replace("%2", str(result["pages"])))

    def close(self) -> None:
        self._worker.close()
