"""Run: take control, start the prescribed session, live plots (reference dashed, measured
solid: force in N; the ankle angles in clinical terms with the patient's ROM drawn as a shaded
band), progress with phase and time left; with the patient's ankle setup, the ankle torques
in clinical words. Nothing on this page needs typing.

The ankle view: while the telemetry carries the ankle's state (an exercise about the patient's
ankle centre: ``app.telemetry.ankle_state``), the angle plot shows the foot's dorsi/plantar
flexion and inversion/eversion *from the neutral pose* (their references derived from the
platform's, which differ from them by the neutral pose only), a line reads the angles, the
torques about the ankle and how far the ankle centre moved in clinical words, and the
platform's own roll and pitch go to an engineer view (a toggle: dotted curves and their
values). Without those fields the ankle view is hidden and the plot shows the platform's
angles in clinical signs, as before.

The plots are redrawn by a timer at :data:`FRAME_HZ` from the samples the link collected
(the GUI thread never waits for telemetry); each redraw costs one ``setData`` per curve.
"""
from __future__ import annotations

import collections
import time
from typing import Any

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import Qt, QTimer, Signal
from PySide6.QtGui import QBrush, QColor, QPen
from PySide6.QtWidgets import (
    QGraphicsRectItem,
    QGridLayout,
    QHBoxLayout,
    QLabel,
    QProgressBar,
    QPushButton,
    QVBoxLayout,
    QWidget,
)

from app.background import Background
from app.i18n import tr
from app.journal import SessionJournal
from app.patient_context import PatientContext
from app.rt_link import RtLink
from app.style import LARGE_PX, TARGET_PX
from app.telemetry import RepetitionCounter, ankle_state
from app.words import event_words
from rt.ipc.client import RtClient

#: Redraw rate of the live plots, Hz: the issue asks ≥ 30 fps; a 33 ms timer gives at most
#: 30.3 and any late tick drops below, so the timer runs a little faster (frames with no new
#: telemetry, 60 Hz, are skipped).
FRAME_HZ = 32
#: Seconds of history on the live plots.
WINDOW_S = 20.0
#: The angle curves of the ankle view (from neutral) and of the platform (absolute).
ANKLE_CURVES = ("ankle_dfpf_ref", "ankle_dfpf", "ankle_inev_ref", "ankle_inev")
PLATFORM_CURVES = ("pitch_ref", "pitch", "roll_ref", "roll")


class RomBand(QGraphicsRectItem):
    """A patient's range of motion on the angle plot: a shaded band across the fixed time
    axis. A plain rectangle, painted by Qt in C++: pyqtgraph's LinearRegionItem rebuilt its
    pens and bounds in Python at every frame and was the Run page's longest GUI stalls
    (bench/gui.py --synthetic, the stall tracer)."""

    def __init__(self, colour: QColor) -> None:
        super().__init__(-WINDOW_S, 0.0, WINDOW_S, 0.0)
        self.setBrush(QBrush(colour))
        self.setPen(QPen(Qt.PenStyle.NoPen))
        self.setZValue(-10)               # behind the curves

    def setRegion(self, region: tuple[float, float]) -> None:
        lo, hi = sorted(float(v) for v in region)
        self.setRect(-WINDOW_S, lo, WINDOW_S, hi - lo)

    def getRegion(self) -> tuple[float, float]:
        r = self.rect()
        return r.top(), r.bottom()


def _direction_words() -> dict[str, str]:
    """Clinical directions as a torque hold names them (``protocols.torque_hold``), in the
    installed language."""
    return {"plantarflexion": tr("plantarflexion"), "dorsiflexion": tr("dorsiflexion"),
            "inversion": tr("inversion"), "eversion": tr("eversion")}


def _last_finite(x: np.ndarray) -> float:
    """The newest finite value of ``x``; NaN when there is none."""
    finite = np.flatnonzero(np.isfinite(x))
    return float(x[finite[-1]]) if finite.size else float("nan")


def phase_words(phase: str) -> str:
    return {"approach": tr("moving to the start position"), "play": tr("exercise"),
            "return": tr("returning to rest"), "stopped": tr("stopped"),
            "rest": tr("at rest")}.get(phase, phase)


class RunPage(QWidget):
    """Emits ``session_ended(summary)`` when the RT process publishes ``session_end``."""

    session_ended = Signal(dict)

    def __init__(self, link: RtLink | None, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.link = link
        self.patient: PatientContext | None = None
        self.document: dict[str, Any] | None = None
        self.session_id: str | None = None
        self.duration_s: float | None = None
        self.last_summary: dict[str, Any] | None = None
        self.last_error = ""
        self.recording: str | None = None
        self.start_clicked_at: float | None = None
        #: False for roles that may not move the robot (viewer, engineer, admin)
        self.may_run = True
        #: the last "Take control" failed and the status has not shown this GUI as the owner
        self._control_error = False
        #: the clinical record's journal of sessions (None: no record)
        self.journal: SessionJournal | None = None
        self._journal_pool = Background("gui-journal", self)
        self._journal_pool.done.connect(self._journaled)
        #: frames drawn, and the samples on the plots at the last one
        self.frames = 0
        self.samples_shown = 0
        self._drawn = -1
        #: (monotonic time, seconds spent, CPU seconds of this thread) of the recent frames
        #: drawn (bench/gui.py's figures)
        self.frame_log: collections.deque[tuple[float, float, float]] = \
            collections.deque(maxlen=20000)
        self._latest: dict[str, Any] | None = None

        self.protocol_label = QLabel(tr("No protocol prescribed: choose one in Prescribe."))
        self.protocol_label.setWordWrap(True)
        self.control_button = QPushButton(tr("Take control of the robot"))
        self.start_button = QPushButton(tr("Start session"))
        self.start_button.setObjectName("startSession")
        for b in (self.control_button, self.start_button):
            b.setMinimumHeight(LARGE_PX)
        self.control_button.clicked.connect(self.take_control)
        self.start_button.clicked.connect(self.start_session)
        self.message = QLabel()
        self.message.setWordWrap(True)

        pg.setConfigOptions(antialias=False)
        self.force_plot = pg.PlotWidget(title=tr("Force (N)"))
        self.angle_plot = pg.PlotWidget(title=tr("Ankle angles (°)"))
        for p in (self.force_plot, self.angle_plot):
            # Draw only what is visible, at most about a point per pixel (CPU: the RT loop
            # shares the machine).
            p.setClipToView(True)
            p.setDownsampling(auto=True, mode="peak")
            # Ranges are set by redraw(), not by an autorange pass every frame; nothing on
            # this page is dragged (a finger on the plot must not pan it away from "now").
            p.disableAutoRange()
            p.setMouseEnabled(x=False, y=False)
            p.hideButtons()
            p.setBackground("w")
            # No grid: pyqtgraph replays the axes' grid lines with every frame, and they were
            # most of the frame's cost (bench/gui.py --frame-cost: 46 → 19 → 9 ms a frame with
            # the fixed time axis, no grid and thin dashed references on this VM).
            p.addLegend(offset=(10, 10))
            p.setLabel("bottom", tr("seconds before now"))
            # A fixed time axis, "now" at 0: the axes and their ticks are drawn once, not
            # regenerated every frame as a scrolling range would (the largest cost per frame).
            p.setXRange(-WINDOW_S, 0.0, padding=0.0)
        dash = Qt.PenStyle.DashLine
        self.curves = {
            # References dashed and 1 px (a wide dashed stroke costs the most to draw);
            # measured 2 px solid, read from a metre away.
            "force_ref": self.force_plot.plot(pen=pg.mkPen("#555555", width=1, style=dash),
                                              name=tr("reference")),
            "force": self.force_plot.plot(pen=pg.mkPen("#1f5fbf", width=2),
                                          name=tr("measured")),
            "pitch_ref": self.angle_plot.plot(pen=pg.mkPen("#1f5fbf", width=1, style=dash)),
            "pitch": self.angle_plot.plot(pen=pg.mkPen("#1f5fbf", width=2),
                                          name=tr("plantar(+)/dorsi(−) flexion")),
            "roll_ref": self.angle_plot.plot(pen=pg.mkPen("#bf5f1f", width=1, style=dash)),
            "roll": self.angle_plot.plot(pen=pg.mkPen("#bf5f1f", width=2),
                                         name=tr("inversion(+)/eversion(−)")),
            # The ankle view (only while the telemetry carries the ankle's state).
            "ankle_dfpf_ref": self.angle_plot.plot(
                pen=pg.mkPen("#1f5fbf", width=1, style=dash)),
            "ankle_dfpf": self.angle_plot.plot(
                pen=pg.mkPen("#1f5fbf", width=2),
                name=tr("ankle: plantar(+)/dorsi(−) flexion from neutral")),
            "ankle_inev_ref": self.angle_plot.plot(
                pen=pg.mkPen("#bf5f1f", width=1, style=dash)),
            "ankle_inev": self.angle_plot.plot(
                pen=pg.mkPen("#bf5f1f", width=2),
                name=tr("ankle: inversion(+)/eversion(−) from neutral")),
        }
        self._legend_names = {key: curve.name() for key, curve in self.curves.items()}
        #: True while the angle plot shows the ankle view (the telemetry's ankle fields)
        self.ankle_mode = False
        self.angle_plot.getViewBox().setLimits(minYRange=10.0)
        self.rom_bands = {
            axis: RomBand(QColor(*colour))
            for axis, colour in (("pitch", (31, 95, 191, 35)), ("roll", (191, 95, 31, 35)))}
        for band in self.rom_bands.values():
            self.angle_plot.addItem(band)
            band.hide()

        self.progress = QProgressBar()
        self.progress.setMinimumHeight(TARGET_PX)
        self.progress.setRange(0, 1000)
        self.progress.setTextVisible(True)
        self.phase_label = QLabel()
        font = self.phase_label.font()
        font.setPointSize(14)
        self.phase_label.setFont(font)
        self.events_label = QLabel()
        self.events_label.setWordWrap(True)
        self.reps_label = QLabel()
        self.reps_label.setObjectName("repetitions")
        self.reps_label.setFont(font)
        self.reps_label.hide()
        # The patient's ankle torques live, in clinical words (only with an ankle setup).
        self.ankle_label = QLabel()
        self.ankle_label.setObjectName("ankleTorque")
        self.ankle_label.hide()
        self._ankle_setup: Any = None
        # The ankle view's readout (angles from neutral, centre displacement), and the
        # engineers' platform angles behind a toggle.
        self.ankle_angles_label = QLabel()
        self.ankle_angles_label.setObjectName("ankleAngles")
        self.ankle_angles_label.setFont(font)
        self.ankle_angles_label.setWordWrap(True)
        self.ankle_angles_label.hide()
        self.engineer_button = QPushButton(tr("Platform angles (engineers)"))
        self.engineer_button.setObjectName("engineerView")
        self.engineer_button.setCheckable(True)
        self.engineer_button.setMinimumHeight(TARGET_PX)
        self.engineer_button.toggled.connect(self._toggle_engineer)
        self.engineer_button.hide()
        self.platform_label = QLabel()
        self.platform_label.setObjectName("platformAngles")
        self.platform_label.hide()

        top = QHBoxLayout()
        top.addWidget(self.protocol_label, 3)
        top.addWidget(self.control_button, 1)
        top.addWidget(self.start_button, 1)
        plots = QGridLayout()
        plots.addWidget(self.force_plot, 0, 0)
        plots.addWidget(self.angle_plot, 0, 1)
        layout = QVBoxLayout(self)
        layout.addLayout(top)
        layout.addWidget(self.message)
        layout.addLayout(plots, 1)
        phase_row = QHBoxLayout()
        phase_row.addWidget(self.phase_label, 1)
        phase_row.addWidget(self.reps_label)
        layout.addLayout(phase_row)
        layout.addWidget(self.progress)
        layout.addWidget(self.events_label)
        ankle_row = QHBoxLayout()
        ankle_column = QVBoxLayout()
        ankle_column.addWidget(self.ankle_angles_label)
        ankle_column.addWidget(self.ankle_label)
        ankle_column.addWidget(self.platform_label)
        ankle_row.addLayout(ankle_column, 1)
        ankle_row.addWidget(self.engineer_button, 0, Qt.AlignmentFlag.AlignTop)
        layout.addLayout(ankle_row)
        self._set_angle_mode(False, force=True)

        self.timer = QTimer(self)
        self.timer.setTimerType(Qt.TimerType.PreciseTimer)
        self.timer.setInterval(int(1000 / FRAME_HZ))
        self.timer.timeout.connect(self.redraw)
        if link is not None:
            link.replied.connect(self._replied)
            link.event_received.connect(self._event)
            link.status_changed.connect(lambda _s: self.update_buttons())
            link.connection_changed.connect(lambda *_: self.update_buttons())
            self.timer.start()
        self.update_buttons()

    # ------------------------------------------------------------------ inputs

    def _inversion_sign(self) -> float:
        """+1 when the platform's positive roll is the patient's inversion (right foot).
        The foot on the platform is the ankle setup's side when one is in force (what the RT
        process turns about, ``rt.model.ankle.ankle_angles``), else the affected side."""
        if self.patient is None:
            return 1.0
        side = (self.patient.ankle or {}).get("side") or self.patient.side
        return -1.0 if side == "left" else 1.0

    def set_patient(self, patient: PatientContext | None) -> None:
        """Draw this patient's ROM: plantar(+)/dorsi(−) flexion is the platform's pitch;
        inversion(+)/eversion(−) is its roll, mirrored for a left foot."""
        self.patient = patient
        from rt.model.ankle import AnkleSetup
        self._ankle_setup = None if patient is None or patient.ankle is None \
            else AnkleSetup(**patient.ankle)
        self.show_ankle(None)
        lim = None if patient is None else patient.patient_limits()
        inv = self._inversion_sign()
        for axis, band in self.rom_bands.items():
            if lim is None:
                band.hide()
                continue
            lo, hi = getattr(lim, f"{axis}_min_deg"), getattr(lim, f"{axis}_max_deg")
            if axis == "roll":
                lo, hi = sorted((inv * lo, inv * hi))
            band.setRegion((lo, hi))
            band.show()
        self.update_buttons()

    def prescribe(self, document: dict[str, Any]) -> None:
        """The protocol to run next (its pre-flight passed on Prescribe)."""
        self.document = document
        self.protocol_label.setText(tr("Protocol: %1").replace("%1", document["name"]))
        self.message.setText("")
        self.update_buttons()

    # ------------------------------------------------------------------ commands

    def take_control(self) -> None:
        if self.link is not None:
            self.link.take_control()

    def start_session(self) -> None:
        link, doc, patient = self.link, self.document, self.patient
        if link is None or doc is None or patient is None:
            return
        self.start_clicked_at = time.monotonic()
        self.message.setText(tr("Checking the protocol on the robot model, then starting…"))
        self.start_button.setEnabled(False)
        journal = self.journal

        def start(c: RtClient) -> dict[str, Any]:
            # With a clinical record the row is opened first: its snapshot of the limits is
            # what the RT process enforces.
            args = patient.rt_patient() if journal is None else journal.begin(patient.code, doc)
            return c.session_start(doc, args)
        link.call("session_start", start)

    def _replied(self, tag: str, result: object, error: str) -> None:
        if tag == "control":
            owned = self._owned()
            self.message.setText(tr("You control the robot.") if not error or owned
                                 else tr("Could not take control: %1").replace("%1", error))
            self._control_error = bool(error) and not owned
        elif tag == "session_start":
            if error:
                self.last_error = error
                self.message.setText(tr("The session did not start: %1").replace("%1", error))
                journal = self.journal
                if journal is not None:
                    self._journal_pool.call("refused", lambda: journal.refused(error))
            else:
                assert isinstance(result, dict)
                self.session_id = str(result["session_id"])
                duration = result.get("duration_s")
                self.duration_s = float(duration) if isinstance(duration, (int, float)) else None
                self.recording = result.get("recording")
                if self.link is not None:
                    self.link.telemetry.clear()
                    self.link.telemetry.count_repetitions(
                        self.session_id, None if self.document is None
                        else RepetitionCounter.for_protocol(self.document))
                self.message.setText(tr("Session running."))
        elif tag in ("stop", "estop", "reset") and error:
            self.message.setText(f"{tag}: {error}")
        self.update_buttons()

    def _event(self, event: dict[str, Any]) -> None:
        if event.get("kind") == "session_end":
            summary = event.get("summary") or {}
            self.last_summary = summary if isinstance(summary, dict) else {}
            ended_here = self.session_id is not None
            self.session_id = None
            journal, done = self.journal, self.last_summary
            if journal is not None and ended_here:
                self._journal_pool.call("end", lambda: journal.end(done))
            self.message.setText(tr("Session ended: %1").replace(
                "%1", str(self.last_summary.get("outcome", event.get("cause", "")))))
            self.session_ended.emit(self.last_summary)
        elif event.get("kind") == "fault":
            words = event_words(event)
            self.events_label.setText(tr("Stopped: %1").replace("%1", words))
            if self.session_id is not None:
                # Not "Session running." until the session's end arrives: it is stopping.
                self.message.setText(tr("Session stopping: %1").replace("%1", words))
        self.update_buttons()

    def _journaled(self, tag: str, _result: object, error: str) -> None:
        if error:
            self.message.setText(tr("The clinical record did not take the session: %1")
                                 .replace("%1", error))

    def _owned(self) -> bool:
        """The latest status says this GUI controls the robot."""
        link = self.link
        status = None if link is None else link.last_status
        return bool(status and isinstance(status.get("owner"), dict)
                    and link is not None and status["owner"].get("client") == link.client_id)

    def update_buttons(self) -> None:
        link = self.link
        connected = link is not None and link.connected
        status = None if link is None else link.last_status
        owned = self._owned()
        if owned and self._control_error:
            # The control reply was lost but the RT process took the request (a loaded
            # machine): the status is the truth.
            self._control_error = False
            self.message.setText(tr("You control the robot."))
        stopped = bool(status and status.get("state") != "run")
        running = bool(status and status.get("session"))
        self.control_button.setEnabled(self.may_run and connected and not owned)
        self.start_button.setEnabled(self.may_run and connected and owned and not stopped
                                     and not running
                                     and self.document is not None and self.patient is not None)

    # ------------------------------------------------------------------ drawing

    def redraw(self) -> None:
        """Redraw from the link's telemetry ring (the frame timer's slot).

        Cheap by construction: nothing when the page is hidden or no sample arrived; else one
        copy of the ring (≈ 2000 × 8 floats), one ``setData`` per curve with the finite check
        skipped where the values cannot be NaN, on a fixed time axis ("now" at 0: no autorange
        pass and no axis redrawn per frame) with the y ranges revised twice a second.
        """
        assert self.link is not None
        ring = self.link.telemetry
        if ring.written == self._drawn or not self.isVisible():
            return
        began, began_cpu = time.perf_counter(), time.thread_time()
        n, col = ring.snapshot()
        self._drawn = n
        if n == 0:
            return
        t = col["t"]
        keep = t >= t[-1] - WINDOW_S
        t = t[keep] - t[-1]
        inv = self._inversion_sign()
        series = {"force_ref": col["force_ref"][keep], "force": col["force"][keep],
                  "pitch": np.degrees(col["pitch"][keep]),
                  "pitch_ref": np.degrees(col["pitch_ref"][keep]),
                  "roll": inv * np.degrees(col["roll"][keep]),
                  "roll_ref": inv * np.degrees(col["roll_ref"][keep])}
        dfpf = np.degrees(col["ankle_dfpf"][keep])
        switched = self._set_angle_mode(bool(np.isfinite(dfpf).any()))
        if self.ankle_mode:
            inev = np.degrees(col["ankle_inev"][keep])
            series["ankle_dfpf"], series["ankle_inev"] = dfpf, inev
            # The ankle's angle is the platform's rotation from the neutral pose
            # (rt.model.ankle): the references from neutral are the platform's, less the
            # neutral pose the newest sample shows.
            series["ankle_dfpf_ref"] = series["pitch_ref"] - _last_finite(series["pitch"] - dfpf)
            series["ankle_inev_ref"] = series["roll_ref"] - _last_finite(series["roll"] - inev)
        for key, curve in self.curves.items():
            if not curve.isVisible():
                continue
            y = series[key]
            finite = bool(np.isfinite(y).all())
            curve.setData(t, y, connect="all" if finite else "finite", skipFiniteCheck=finite)
        self.samples_shown = int(t.size)
        self.frames += 1
        if switched or self.frames % (FRAME_HZ // 2) == 1:      # y ranges twice a second
            self._revise_y(series)
        latest = ring.latest or {}
        self._latest = latest
        progress = float(latest.get("progress") or 0.0)
        self.progress.setValue(round(1000 * min(max(progress, 0.0), 1.0)))
        left = ""
        if self.duration_s and latest.get("session"):
            left = " — " + tr("%1 s left").replace(
                "%1", f"{max(0.0, (1.0 - progress) * float(self.duration_s)):.0f}")
        text = phase_words(str(latest.get("phase", ""))) + left
        if text != self.phase_label.text():
            self.phase_label.setText(text)
        self._show_repetitions()
        self.show_ankle(latest)
        self.frame_log.append((time.monotonic(), time.perf_counter() - began,
                               time.thread_time() - began_cpu))

    def _revise_y(self, series: dict[str, np.ndarray]) -> None:
        """Y ranges from the data shown (and the ROM bands), changed only when the data leave
        them or use less than half of them: a steady plot does not jitter."""
        angles = tuple(k for k in (*ANKLE_CURVES, *PLATFORM_CURVES)
                       if k in series and self.curves[k].isVisible())
        for plot, keys, floor in ((self.force_plot, ("force_ref", "force"), 50.0),
                                  (self.angle_plot, angles, 10.0)):
            values = [v[np.isfinite(v)] for v in (series[k] for k in keys)]
            values = [v for v in values if v.size]
            lo = min((float(v.min()) for v in values), default=0.0)
            hi = max((float(v.max()) for v in values), default=0.0)
            if plot is self.angle_plot:
                for band in self.rom_bands.values():
                    if band.isVisible():
                        b0, b1 = band.getRegion()
                        lo, hi = min(lo, float(b0)), max(hi, float(b1))
            if hi - lo < floor:
                mid = 0.5 * (hi + lo)
                lo, hi = mid - floor / 2, mid + floor / 2
            (c0, c1), = plot.getViewBox().viewRange()[1:]
            span = hi - lo
            if lo < c0 or hi > c1 or (c1 - c0) > 2.0 * 1.1 * span:
                margin = 0.05 * span
                plot.setYRange(lo - margin, hi + margin, padding=0.0)

    def _toggle_engineer(self, _on: bool) -> None:
        self._set_angle_mode(self.ankle_mode, force=True)
        self._drawn = -1            # the next frame draws the curves now shown

    def _set_angle_mode(self, ankle: bool, force: bool = False) -> bool:
        """Show the ankle view (``ankle``: the telemetry carries the ankle's state) or the
        platform's angles; in the ankle view the platform's curves are the engineers' (dotted,
        behind the toggle). Legend, title and curves change only when the mode does (or
        ``force``); returns whether they changed."""
        if ankle == self.ankle_mode and not force:
            return False
        self.ankle_mode = ankle
        engineer = ankle and self.engineer_button.isChecked()
        self.engineer_button.setVisible(ankle)
        self.ankle_angles_label.setVisible(ankle)
        self.platform_label.setVisible(engineer)
        self.angle_plot.setTitle(tr("Ankle angles from neutral (°)") if ankle
                                 else tr("Ankle angles (°)"))
        dot, dash = Qt.PenStyle.DotLine, Qt.PenStyle.DashLine
        platform_pens = {"pitch": ("#1f5fbf", 2, Qt.PenStyle.SolidLine),
                         "pitch_ref": ("#1f5fbf", 1, dash),
                         "roll": ("#bf5f1f", 2, Qt.PenStyle.SolidLine),
                         "roll_ref": ("#bf5f1f", 1, dash)}
        for key, (colour, width, style) in platform_pens.items():
            self.curves[key].setPen(pg.mkPen(colour, width=1 if ankle else width,
                                             style=dot if ankle else style))
        legend = self.angle_plot.getPlotItem().legend
        if legend is not None:
            legend.clear()
        names = dict(self._legend_names)
        if ankle:
            names["pitch"] = tr("platform pitch (engineers)")
            names["roll"] = tr("platform roll (engineers)")
        for key in (*PLATFORM_CURVES, *ANKLE_CURVES):
            curve = self.curves[key]
            shown = key in ANKLE_CURVES if ankle else key in PLATFORM_CURVES
            if ankle and engineer and key in PLATFORM_CURVES:
                shown = key in ("pitch", "roll")      # the platform's measured angles only
            curve.setVisible(shown)
            if not shown:
                curve.setData([], [])
            elif legend is not None and names.get(key):
                legend.addItem(curve, names[key])
        if not ankle:
            self.ankle_angles_label.setText("")
        return True

    def show_ankle(self, latest: dict[str, Any] | None) -> None:
        """The ankle in clinical words from the latest telemetry sample.

        With the ankle's state in the telemetry (the ankle view): its angles from neutral,
        its torques and how far its centre moved, as the RT process computed them about the
        patient's ankle centre; the platform's angles for the engineer view. Else, with the
        patient's ankle setup, the torques from the sensor's wrench moved to the ankle centre
        (``rt.model.ankle.ankle_torques``); hidden without either, a dash while the sensor has
        no finite sample."""
        latest = latest or {}
        if self.ankle_mode:
            self._show_ankle_state(latest)
            return
        if self._ankle_setup is None:
            self.ankle_label.hide()
            return
        from rt.model.ankle import ankle_torques
        wrench = latest.get("wrench") or []
        values = [float(x) for x in wrench[:6] if x is not None]
        if len(values) < 6 or not all(np.isfinite(values)):
            text = tr("Ankle torque: —")
        else:
            tp, ti, _ = ankle_torques(values, self._ankle_setup)
            text = self._torque_words(tp, ti)
        if text != self.ankle_label.text():
            self.ankle_label.setText(text)
        self.ankle_label.show()

    @staticmethod
    def _torque_words(plantar_nm: float, inversion_nm: float) -> str:
        return tr("Ankle torque: %1 %2 N·m, %3 %4 N·m").replace(
            "%1", tr("plantarflexion") if plantar_nm >= 0 else tr("dorsiflexion")) \
            .replace("%2", f"{abs(plantar_nm):.1f}") \
            .replace("%3", tr("inversion") if inversion_nm >= 0 else tr("eversion")) \
            .replace("%4", f"{abs(inversion_nm):.1f}")

    def _displacement_limit_mm(self) -> float:
        """The ankle centre's comfort limit of the prescribed protocol (mm; the product's
        default when the protocol does not set one)."""
        from rt.model.ankle import DEFAULT_COMFORT_LIMIT_M
        value = (self.document or {}).get("ankle_displacement_limit_mm")
        return float(value) if isinstance(value, (int, float)) \
            else DEFAULT_COMFORT_LIMIT_M * 1e3

    def _show_ankle_state(self, latest: dict[str, Any]) -> None:
        """The ankle view's words (:meth:`show_ankle`)."""
        state = ankle_state(latest)
        pf, ie = state["ankle_dfpf"], state["ankle_inev"]
        if np.isfinite(pf) and np.isfinite(ie):
            angles = tr("Ankle from neutral: %1 %2°, %3 %4°").replace(
                "%1", tr("plantarflexion") if pf >= 0 else tr("dorsiflexion")) \
                .replace("%2", f"{abs(pf):.1f}") \
                .replace("%3", tr("inversion") if ie >= 0 else tr("eversion")) \
                .replace("%4", f"{abs(ie):.1f}")
        else:
            angles = tr("Ankle from neutral: —")
        moved = state["ankle_displacement"]
        if np.isfinite(moved):
            angles += " — " + tr("the ankle centre moved %1 mm (comfort limit %2 mm)") \
                .replace("%1", f"{moved:.0f}") \
                .replace("%2", f"{self._displacement_limit_mm():.0f}")
        target = latest.get("ankle_target")
        if isinstance(target, dict) and isinstance(target.get("target_nm"), (int, float)) \
                and isinstance(target.get("now_nm"), (int, float)):
            # An isometric hold regulated on the ankle torque: its target, ramps included.
            angles += "\n" + tr("Hold %1: %2 %3 N·m (target now %4 N·m)") \
                .replace("%1", str(target.get("hold", ""))) \
                .replace("%2", _direction_words().get(str(target.get("direction")),
                                                     str(target.get("direction", "")))) \
                .replace("%3", f"{abs(float(target['target_nm'])):.1f}") \
                .replace("%4", f"{abs(float(target['now_nm'])):.1f}")
        tp, ti = state["ankle_torque_dfpf"], state["ankle_torque_inev"]
        torque = self._torque_words(tp, ti) if np.isfinite(tp) and np.isfinite(ti) \
            else tr("Ankle torque: —")
        for label, text in ((self.ankle_angles_label, angles), (self.ankle_label, torque)):
            if text != label.text():
                label.setText(text)
        self.ankle_label.show()
        if self.engineer_button.isChecked():
            pose = latest.get("pose") or []
            if len(pose) > 2 and all(isinstance(x, (int, float)) for x in pose[1:3]):
                text = tr("Platform (engineers): roll %1°, pitch %2°") \
                    .replace("%1", f"{np.degrees(pose[1]):+.1f}") \
                    .replace("%2", f"{np.degrees(pose[2]):+.1f}")
            else:
                text = tr("Platform (engineers): —")
            if text != self.platform_label.text():
                self.platform_label.setText(text)

    def _show_repetitions(self) -> None:
        assert self.link is not None
        reps = self.link.telemetry.repetitions()
        if reps is None:
            text = ""
        elif reps[1] is None:
            text = tr("Repetitions: %1").replace("%1", str(reps[0]))
        else:
            text = tr("Repetitions: %1 of %2").replace("%1", str(reps[0])) \
                .replace("%2", str(reps[1]))
        if text != self.reps_label.text():
            self.reps_label.setText(text)
        self.reps_label.setVisible(bool(text))
