"""PDF reports from the GUI: the session report (Review) and the progress report (Patients).

Qt-free except :func:`ask_pdf_path`; the jobs run on a worker thread (reading a recording and
drawing the figures takes seconds). The file is the user's: the path they chose is refused if
it exists (never overwritten; the report is written to a temporary file and renamed by
``reports.document.write_pdf``). The clinic's name and logo come from the GUI's settings.
"""
from __future__ import annotations

import datetime as dt
from collections.abc import Callable
from pathlib import Path
from typing import Any

from app.settings import GuiSettings
from rt.errors import InputError


def report_settings(settings: GuiSettings) -> Any:
    """The reports' settings (``reports.settings.ReportSettings``) for the GUI's clinic name
    and logo (empty: the reports' defaults).

    Raises:
        ConfigurationError: the logo is set but not a readable PNG/JPEG file.
    """
    from reports.settings import ReportSettings

    values: dict[str, Any] = {}
    if settings.clinic_name.strip():
        values["clinic_name"] = settings.clinic_name.strip()
    if settings.clinic_logo.strip():
        values["logo_path"] = Path(settings.clinic_logo.strip())
    out = ReportSettings(**values)
    out.check_logo()
    return out


def pdf_target(chosen: str | Path) -> Path:
    """The file to write for the path the user chose: ``.pdf`` added when missing.

    Raises:
        InputError: the file exists (reports never overwrite one) or its folder does not.
    """
    path = Path(chosen).expanduser()
    if path.suffix.lower() != ".pdf":
        path = path.with_name(path.name + ".pdf")
    if path.exists():
        raise InputError(f"{path} already exists: choose another name (a report never "
                         "replaces a file)")
    if not path.parent.is_dir():
        raise InputError(f"{path}: folder {path.parent} does not exist")
    return path


def choose_report_target(ask: Callable[[str, Path], Path | None], title: str,
                         suggested: Path, settings: GuiSettings) -> tuple[Path, Any] | None:
    """Ask where to write a report (``ask(title, suggested)``; None: cancelled) and check it:
    the file to write (:func:`pdf_target`) and the reports' settings (:func:`report_settings`).

    Raises:
        InputError: the chosen file exists or its folder does not.
        ConfigurationError: the clinic's logo is not a readable image.
    """
    chosen = ask(title, suggested)
    if chosen is None:
        return None
    return pdf_target(chosen), report_settings(settings)


def session_uid_for_recording(record: Any, actor: Any, recording: Path) -> str | None:
    """The clinical record's session whose recording is ``recording`` (None: not in it)."""
    want = recording.resolve()
    for s in reversed(record.list_sessions(actor)):
        path = s.get("recording_path")
        if path and Path(path).resolve() == want:
            return str(s["uid"])
    return None


def write_session_report(recording: Path, out: Path, settings: Any, record: Any = None,
                         actor: Any = None) -> dict[str, Any]:
    """Write the session report of ``recording`` to ``out``: from the clinical record's
    session when it holds one for this recording (its limits snapshot, clinician, stored
    summary, the recording's hash checked), from the recording alone otherwise.

    Returns ``{"out", "pages", "session"}`` (session: the record's id or None).
    """
    from reports.session_data import session_input_from_recording
    from reports.session_report import render_session_report

    uid = None
    if record is not None and actor is not None:
        uid = session_uid_for_recording(record, actor, recording)
    if uid is not None:
        from reports.from_record import session_input
        inp = session_input(record, actor, uid)
    else:
        inp = session_input_from_recording(recording)
    pages = render_session_report(inp, out, settings)
    return {"out": str(out), "pages": pages, "session": uid}


def write_progress_report(record: Any, actor: Any, code: str, out: Path, settings: Any,
                          since: dt.date | None = None,
                          until: dt.date | None = None) -> dict[str, Any]:
    """Write patient ``code``'s progress report (sessions in [since, until]) to ``out``."""
    from reports.from_record import progress_input
    from reports.progress import render_progress_report

    inp = progress_input(record, actor, code, since, until)
    pages = render_progress_report(inp, out, settings, date_from=since, date_to=until)
    return {"out": str(out), "pages": pages, "session": None}


def ask_pdf_path(parent: Any, title: str, suggested: Path) -> Path | None:
    """Ask where to save a PDF (Qt's own dialog, so it is the same on every desktop and
    translatable); None when cancelled. Overwriting is not offered: :func:`pdf_target`
    refuses an existing file with a message."""
    from PySide6.QtWidgets import QFileDialog

    options = QFileDialog.Option.DontUseNativeDialog | QFileDialog.Option.DontConfirmOverwrite
    name, _filter = QFileDialog.getSaveFileName(parent, title, str(suggested), "PDF (*.pdf)",
                                                options=options)
    return Path(name) if name else None


def open_file(path: Path | None) -> bool:
    """Open ``path`` with the desktop's viewer (PDF reader); False when there is none."""
    if path is None:
        return False
    from PySide6.QtCore import QUrl
    from PySide6.QtGui import QDesktopServices

    return bool(QDesktopServices.openUrl(QUrl.fromLocalFile(str(path))))
