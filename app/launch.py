"""Starting the GUI: the Qt application, the language, the RT process (the configured one, or
an embedded one on the twin when none answers), the link and the main window."""
from __future__ import annotations

import contextlib
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from app.settings import GuiSettings


def recordings_dir(settings: GuiSettings) -> Path:
    """Where sessions are recorded: the setting, else the RT process's default."""
    if settings.recordings_dir:
        return Path(settings.recordings_dir)
    from rt.service import default_recordings_dir
    return default_recordings_dir()


#: How long the configured RT process may take to answer before an embedded one is started
#: (s): a loaded machine answered a live one's status after more than the 0.5 s default, and
#: the GUI then started a second RT process beside it.
PROBE_TIMEOUT_S = 3.0


@contextlib.contextmanager
def robot(settings: GuiSettings, fast: bool = False,
          heartbeat_timeout_s: float | None = None) -> Iterator[str]:
    """The endpoint of an RT process for ``settings`` (embedded on the twin if none answers;
    stopped on exit if it was started here; ``heartbeat_timeout_s`` as in ``rt_process``)."""
    from rt.ipc.embedded import rt_process

    rec = recordings_dir(settings)
    rec.mkdir(parents=True, exist_ok=True)
    with rt_process(settings.rt_endpoint, PROBE_TIMEOUT_S, fast=fast, recordings_dir=str(rec),
                    heartbeat_timeout_s=heartbeat_timeout_s) as endpoint:
        yield endpoint


def clinical_record(settings: GuiSettings) -> Any:
    """The clinical record at the settings' database URL (None when this installation has no
    ``patients`` package: the GUI then runs without log in, e.g. a calibration bench)."""
    try:
        from patients.service import ClinicalRecord
    except ImportError:
        return None
    return ClinicalRecord.open(settings.database_url or None)


def application() -> Any:
    """The QApplication (created once), with a base font a clinician reads from a metre."""
    from PySide6.QtGui import QFont
    from PySide6.QtWidgets import QApplication

    app = QApplication.instance() or QApplication(sys.argv[:1])
    assert isinstance(app, QApplication)
    font = QFont(app.font())
    font.setPointSize(max(11, font.pointSize()))
    app.setFont(font)
    return app


def run_gui(settings: GuiSettings, settings_path: Path | None) -> int:
    """Open the window and run until it is closed; the exit code."""
    from app.i18n import install_language
    from app.main_window import MainWindow
    from app.rt_link import RtLink

    app = application()
    install_language(settings.language)
    settings = settings.model_copy(update={"recordings_dir": str(recordings_dir(settings))})
    record = clinical_record(settings)
    with robot(settings) as endpoint:
        link = RtLink(endpoint, name="GUI")
        window = MainWindow(link, settings, settings_path, record=record)
        link.start()
        window.show()
        code = int(app.exec())
        link.close()
    if record is not None:
        record.close()
    return code
