"""Review: a past session from its recording — force (measured solid, reference dashed) and
the ankle angles, stops marked on the time axis with their cause in words; the plots can be
zoomed and panned (scrubbed) with the mouse, finger or keyboard. Reading runs on a worker.
"Session report (PDF)" writes the opened session's report where the user chooses (never over
an existing file), from the clinical record's session when it holds this recording; the
report is drawn on a worker too."""
from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import pyqtgraph as pg
from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import (
    QHBoxLayout,
    QLabel,
    QListWidget,
    QListWidgetItem,
    QPushButton,
    QVBoxLayout,
    QWidget,
)

from app.i18n import tr
from app.report_action import ReportAction
from app.report_export import write_session_report
from app.review_data import ReviewData, load_review, recording_protocol_name
from app.settings import GuiSettings
from app.style import TARGET_PX
from app.words import cause_words, local_time
from rt.errors import TalusError


def recording_title(path: Path, protocol_name: str | None = None) -> str:
    """``<date time> — <patient>`` over ``<protocol>`` from the RT process's file name
    (``20261123T181621Z_<patient>_<protocol>.mcap``), in local time; the stem otherwise.
    ``protocol_name`` (read from the recording's metadata) replaces the file name's
    filesystem-safe form of it, which lost characters such as "±"."""
    import datetime as dt

    parts = path.stem.split("_", 2)
    try:
        when = dt.datetime.strptime(parts[0], "%Y%m%dT%H%M%SZ").replace(tzinfo=dt.UTC)
    except (ValueError, IndexError):
        return path.stem
    patient = parts[1] if len(parts) > 1 else "?"
    protocol = parts[2].replace("-", " ") if len(parts) > 2 else ""
    return f"{local_time(when.isoformat())} — {patient}\n{protocol_name or protocol}"


class ReviewPage(QWidget):
    """Lists the recordings in a folder (newest first) and plots the one opened."""

    loaded = Signal(object, str)
    #: (recording path, protocol name from its metadata), read on the worker after a refresh
    title_read = Signal(str, str)

    def __init__(self, recordings_dir: Path | None, parent: QWidget | None = None,
                 settings: GuiSettings | None = None, record: Any = None,
                 actor: Callable[[], Any] = lambda: None) -> None:
        super().__init__(parent)
        self.recordings_dir = recordings_dir
        self.settings = settings or GuiSettings()
        self.record = record
        self.actor = actor
        self.data: ReviewData | None = None
        #: the session report (its ``last_result["session"]``: the clinical record's session
        #: it came from, None when from the file alone)
        self.report = ReportAction(self, "gui-report", self.settings)
        self.report.message.connect(self._report_said)
        self.report.busy_changed.connect(self._report_busy)
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="gui-review")
        #: its own worker, so that a folder of recordings being retitled never delays opening one
        self._titles_pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="gui-titles")
        self.sessions = QListWidget()
        self.sessions.setMinimumWidth(260)
        self.sessions.setStyleSheet("QListWidget::item { min-height: 48px; }")
        self.sessions.setWordWrap(True)
        self.sessions.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        self.sessions.itemActivated.connect(lambda item: self.open(Path(item.data(
            Qt.ItemDataRole.UserRole))))
        self.refresh_button = QPushButton(tr("Refresh"))
        self.open_button = QPushButton(tr("Open"))
        self.report_button = QPushButton(tr("Session report (PDF)"))
        self.report_button.setObjectName("sessionReport")
        self.report_button.setEnabled(False)
        self.report_button.clicked.connect(self.make_report)
        self.report_message = QLabel()
        self.report_message.setWordWrap(True)
        self.open_report_button = self.report.open_button
        for b in (self.refresh_button, self.open_button, self.report_button):
            b.setMinimumHeight(TARGET_PX)
        self.refresh_button.clicked.connect(self.refresh)
        self.open_button.clicked.connect(self._open_selected)
        self.info = QLabel(tr("Choose a session on the left."))
        self.info.setWordWrap(True)
        self.force_plot = pg.PlotWidget(title=tr("Force (N)"))
        self.angle_plot = pg.PlotWidget(title=tr("Ankle angles (°)"))
        for p in (self.force_plot, self.angle_plot):
            p.setBackground("w")
            p.showGrid(x=True, y=True, alpha=0.3)
            p.addLegend(offset=(10, 10))
            p.setLabel("bottom", tr("time (s)"))
        # Angles that stay at 0 (force protocols) must not magnify numerical noise.
        self.angle_plot.getViewBox().setLimits(minYRange=10.0)
        self.angle_plot.setXLink(self.force_plot)
        left = QVBoxLayout()
        left.addWidget(QLabel(tr("Recorded sessions")))
        left.addWidget(self.sessions, 1)
        buttons = QHBoxLayout()
        buttons.addWidget(self.refresh_button)
        buttons.addWidget(self.open_button)
        left.addLayout(buttons)
        left.addWidget(self.report_button)
        left.addWidget(self.open_report_button)
        left.addWidget(self.report_message)
        right = QVBoxLayout()
        right.addWidget(self.info)
        right.addWidget(self.force_plot, 1)
        right.addWidget(self.angle_plot, 1)
        layout = QHBoxLayout(self)
        layout.addLayout(left, 1)
        layout.addLayout(right, 3)
        self.loaded.connect(self._show)
        self.title_read.connect(self._retitle)
        self.refresh()

    def refresh(self) -> None:
        """List the folder's recordings, newest first."""
        self.sessions.clear()
        if self.recordings_dir is None or not self.recordings_dir.is_dir():
            return
        files = sorted(self.recordings_dir.glob("*.mcap"), key=lambda p: p.stat().st_mtime,
                       reverse=True)
        for path in files:
            item = QListWidgetItem(recording_title(path))
            item.setData(Qt.ItemDataRole.UserRole, str(path))
            self.sessions.addItem(item)
        if files:
            self.sessions.setCurrentRow(0)
            # The file names' titles show at once; the protocols' own names follow from the
            # files' metadata, read on the worker (a chunk per file: not on the GUI thread).
            self._titles_pool.submit(self._read_titles, files)

    def _read_titles(self, files: list[Path]) -> None:
        for path in files:
            try:
                name = recording_protocol_name(path)
            except TalusError:
                continue                  # the title from the file name stays; open says why
            if name is not None:
                self.title_read.emit(str(path), name)

    def _retitle(self, path: str, protocol_name: str) -> None:
        for row in range(self.sessions.count()):
            item = self.sessions.item(row)
            if item.data(Qt.ItemDataRole.UserRole) == path:
                item.setText(recording_title(Path(path), protocol_name))

    def _open_selected(self) -> None:
        item = self.sessions.currentItem()
        if item is not None:
            self.open(Path(item.data(Qt.ItemDataRole.UserRole)))

    def open(self, path: Path) -> None:
        """Read ``path`` on the worker; the plots follow when it is done."""
        self.info.setText(tr("Reading %1…").replace("%1", path.name))
        self._pool.submit(self._load, path)

    def _load(self, path: Path) -> None:
        try:
            self.loaded.emit(load_review(path), "")
        except TalusError as exc:
            self.loaded.emit(None, str(exc))

    def _report_said(self, text: str) -> None:
        self.report_message.setText(text)

    def _report_busy(self, busy: bool) -> None:
        self.report_button.setEnabled(self.data is not None and not busy)

    def make_report(self) -> None:
        """Ask where, then write the opened session's report on the worker."""
        data = self.data
        if data is None:
            return
        recording = Path(data.path)
        record, actor = self.record, self.actor()
        self.report.write(tr("Save the session report"), f"session-{recording.stem}.pdf",
                          lambda out, settings: write_session_report(
                              recording, out, settings, record, actor))

    def _show(self, data: ReviewData | None, error: str) -> None:
        self.data = data
        self.report_button.setEnabled(data is not None and not self.report.busy)
        self.report_message.setText("")
        self.force_plot.clear()
        self.angle_plot.clear()
        if data is None:
            self.info.setText(tr("Cannot open: %1").replace("%1", error))
            return
        dash = Qt.PenStyle.DashLine
        if len(data.t_ref):
            self.force_plot.plot(data.t_ref, data.force_ref_n, name=tr("reference"),
                                 pen=pg.mkPen("#555555", width=2, style=dash))
        self.force_plot.plot(data.t_force, data.force_n, name=tr("measured"),
                             pen=pg.mkPen("#1f5fbf", width=2), connect="finite")
        if data.has_ankle:
            # The foot's angles about the patient's ankle centre, in clinical terms; the
            # platform's pitch and roll stay, thin and dotted, for engineers.
            self.angle_plot.plot(data.t_ankle, data.plantarflexion_deg,
                                 name=tr("ankle: plantar(+)/dorsi(−) flexion"),
                                 pen=pg.mkPen("#1f5fbf", width=2))
            self.angle_plot.plot(data.t_ankle, data.inversion_deg,
                                 name=tr("ankle: inversion(+)/eversion(−)"),
                                 pen=pg.mkPen("#bf5f1f", width=2))
            dot = Qt.PenStyle.DotLine
            self.angle_plot.plot(data.t, data.pitch_deg, name=tr("platform pitch (engineers)"),
                                 pen=pg.mkPen("#7f9fcf", width=1, style=dot), connect="finite")
            self.angle_plot.plot(data.t, data.roll_deg, name=tr("platform roll (engineers)"),
                                 pen=pg.mkPen("#cf9f7f", width=1, style=dot), connect="finite")
        else:
            self.angle_plot.plot(data.t, data.pitch_deg,
                                 name=tr("plantar(+)/dorsi(−) flexion"),
                                 pen=pg.mkPen("#1f5fbf", width=2), connect="finite")
            self.angle_plot.plot(data.t, data.roll_deg,
                                 name=tr("roll (+ is inversion of a right foot)"),
                                 pen=pg.mkPen("#bf5f1f", width=2), connect="finite")
        for t, cause, _event in data.stops:
            for plot in (self.force_plot, self.angle_plot):
                line = pg.InfiniteLine(pos=t, angle=90, pen=pg.mkPen("#c0262d", width=2),
                                       label=cause_words(cause), labelOpts={"color": "#c0262d"})
                plot.addItem(line)
        meta = data.metadata
        duration = float(data.t[-1]) if len(data.t) else 0.0
        text = tr("%1 — patient %2 — %3 s").replace("%1", str(meta.get("protocol_name", "?"))) \
            .replace("%2", str(meta.get("patient_id", "?"))).replace("%3", f"{duration:.1f}")
        if data.has_ankle:
            text += " — " + _ankle_words(data)
        if data.stops:
            text += " — " + tr("stops: %1").replace("%1", "; ".join(
                f"{t:.1f} s {cause_words(c)}" for t, c, _ in data.stops))
        if not data.complete:
            text += " — " + tr("recording cut short (recovered up to its last whole block)")
        self.info.setText(text)


def _ankle_words(data: ReviewData) -> str:
    """The ankle's range reached and peak torques, in clinical words (from ``/ankle/state``):
    dorsiflexion and eversion are the negative sides of the recorded angles and torques."""
    pf, inv = data.plantarflexion_deg, data.inversion_deg
    tpf, tinv = data.plantarflexion_torque_nm, data.inversion_torque_nm
    return (tr("ankle reached dorsiflexion %1°, plantarflexion %2°, inversion %3°, eversion "
               "%4°; peak torques DF %5, PF %6, INV %7, EV %8 N·m")
            .replace("%1", f"{max(0.0, -float(pf.min())):.1f}")
            .replace("%2", f"{max(0.0, float(pf.max())):.1f}")
            .replace("%3", f"{max(0.0, float(inv.max())):.1f}")
            .replace("%4", f"{max(0.0, -float(inv.min())):.1f}")
            .replace("%5", f"{max(0.0, -float(tpf.min())):.1f}")
            .replace("%6", f"{max(0.0, float(tpf.max())):.1f}")
            .replace("%7", f"{max(0.0, float(tinv.max())):.1f}")
            .replace("%8", f"{max(0.0, -float(tinv.min())):.1f}"))
