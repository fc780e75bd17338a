"""Calibrate (calibration engineer): a wizard over the calibration workflow — plate file and
work folder → plan (the sites drawn on the plate) → register the plate with the camera (the
camera's image with the detected ArUco markers and the registered plate outline drawn) → run
the trials on the twin, or through the RT process the GUI is connected to (live plot: the
running trial's commanded force and ATI load sample by sample, then each trial's vertical force
as the ATI reference and the plate recorded it, with the progress) → fit (PASS/FAIL, the COP
error map before/after drawn on the plate) → verify at check sites → certificate (PDF where the
engineer chooses, never over a file; stored in the clinical record when there is one). Each
step is enabled once the one before it is done; every step runs on a worker
(:mod:`app.calibration_flow`); the right side's tabs (plate, camera, trials) follow the step."""
from __future__ import annotations

import datetime as dt
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QObject, Qt, Signal
from PySide6.QtGui import QImage, QPixmap, QStandardItemModel
from PySide6.QtWidgets import (
    QComboBox,
    QFormLayout,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QProgressBar,
    QPushButton,
    QSizePolicy,
    QTabWidget,
    QVBoxLayout,
    QWidget,
)

from app.background import Background
from app.calibration_flow import (
    BACKENDS,
    CalibrationFlow,
    CameraView,
    TrialSeries,
    cop_error_points,
)
from app.i18n import tr
from app.report_export import ask_pdf_path, choose_report_target
from app.rt_link import RtLink
from app.settings import GuiSettings
from app.style import TARGET_PX
from rt.errors import InputError, TalusError

STEPS = ("plan", "register", "run", "fit", "verify", "certificate")
#: The right side's tabs, and the one each step's result shows.
TABS = ("plate", "camera", "trials")
TAB_OF_STEP = {"plan": "plate", "register": "camera", "run": "trials", "fit": "plate",
               "verify": "plate"}


class _Progress(QObject):
    """Trial progress and each finished trial's forces, from the worker to the GUI thread
    (queued signals)."""

    changed = Signal(int, int, str)
    trial = Signal(object)
    samples = Signal(object)


def qimage_from_bgr(image: np.ndarray) -> QImage:
    """A QImage owning a copy of a BGR uint8 (h, w, 3) array (OpenCV's layout)."""
    if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
        raise ValueError(f"a BGR uint8 image is (h, w, 3) uint8, got {image.shape} "
                         f"{image.dtype}")
    data = np.ascontiguousarray(image)
    h, w, _ = data.shape
    return QImage(data.data, w, h, data.strides[0], QImage.Format.Format_BGR888).copy()


class CameraLabel(QLabel):
    """The camera frame, scaled to the label keeping its aspect (the frame itself is kept)."""

    def __init__(self) -> None:
        super().__init__()
        self.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.setMinimumSize(200, 200)
        self.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Ignored)
        self.frame: QImage | None = None

    def set_frame(self, image: QImage | None) -> None:
        self.frame = image
        self._rescale()

    def resizeEvent(self, event: Any) -> None:
        super().resizeEvent(event)
        self._rescale()

    def _rescale(self) -> None:
        if self.frame is None:
            self.setPixmap(QPixmap())
            return
        self.setPixmap(QPixmap.fromImage(self.frame).scaled(
            self.size(), Qt.AspectRatioMode.KeepAspectRatio,
            Qt.TransformationMode.SmoothTransformation))


def default_work_folder() -> Path:
    """``~/talus-calibrations/<UTC time>``: a new folder per calibration."""
    stamp = dt.datetime.now(dt.UTC).strftime("%Y%m%dT%H%M%SZ")
    return Path.home() / "talus-calibrations" / stamp


class CalibratePage(QWidget):
    """The calibration wizard."""

    def __init__(self, parent: QWidget | None = None, settings: GuiSettings | None = None,
                 record: Any = None, actor: Callable[[], Any] = lambda: None,
                 link: RtLink | None = None) -> None:
        super().__init__(parent)
        #: The RT process the GUI is connected to: offered as the ``rt`` backend while the
        #: connection holds (its loop plays the trials; the GUI's control is borrowed).
        self.link = link
        from calibration.plate import TWIN_PLATE_FILE

        self.settings = settings or GuiSettings()
        self.record = record
        self.actor = actor
        self.flow: CalibrationFlow | None = None
        self.done: set[str] = set()
        self.busy = False
        self.last_error = ""
        self.last_certificate: Path | None = None
        self.ask_path: Callable[[str, Path], Path | None] = \
            lambda title, suggested: ask_pdf_path(self, title, suggested)
        self.worker = Background("gui-calibration", self)
        self.worker.done.connect(self._done)
        self.progress_signal = _Progress(self)
        self.progress_signal.changed.connect(self._progress)
        self.progress_signal.trial.connect(self._trial)
        self.progress_signal.samples.connect(self._samples)

        self.plate_file = QLineEdit(str(TWIN_PLATE_FILE))
        self.work_folder = QLineEdit(str(default_work_folder()))
        self.plan_file = QLineEdit()
        self.plan_file.setPlaceholderText(tr("empty: the default plan"))
        self.backend = QComboBox()
        for key, label in (("twin", tr("robot twin (realistic)")),
                           ("direct", tr("plate only (quick dry run)")),
                           ("rt", tr("the robot (the RT process this GUI is connected to)"))):
            if key == "rt" and link is None:
                continue        # no RT process to offer
            self.backend.addItem(label, key)
        assert {self.backend.itemData(i) for i in range(self.backend.count())} <= set(BACKENDS)
        self.buttons = {
            "plan": QPushButton(tr("1. Plan the loads")),
            "register": QPushButton(tr("2. Register the plate (camera)")),
            "run": QPushButton(tr("3. Run the trials")),
            "fit": QPushButton(tr("4. Fit the calibration")),
            "verify": QPushButton(tr("5. Verify at check sites")),
            "certificate": QPushButton(tr("6. Certificate (PDF)")),
        }
        for key, b in self.buttons.items():
            b.setObjectName(f"calibrate:{key}")
            b.clicked.connect(lambda _c=False, k=key: self.step(k))
        self.progress = QProgressBar()
        self.progress.setRange(0, 1)
        self.progress.setValue(0)
        self.status = QLabel(tr("Choose the plate description and a new work folder, then "
                                "plan."))
        self.status.setWordWrap(True)
        self.verdict = QLabel()
        font = self.verdict.font()
        font.setPointSize(18)
        font.setBold(True)
        self.verdict.setFont(font)
        for w in (self.plate_file, self.work_folder, self.plan_file, self.backend, self.progress,
                  *self.buttons.values()):
            w.setMinimumHeight(TARGET_PX)

        self.plot = pg.PlotWidget(title=tr("Plate (top view, m)"))
        self.plot.setBackground("w")
        self.plot.setAspectLocked(True)
        self.plot.showGrid(x=True, y=True, alpha=0.3)
        self.plot.addLegend(offset=(10, 10))

        # Camera: the frame with the detected markers and the registered outline drawn.
        self.camera = CameraLabel()
        self.camera.setObjectName("calibrate:camera")
        self.camera_caption = QLabel(tr("The camera's view of the plate appears when the "
                                        "plate is registered."))
        self.camera_caption.setWordWrap(True)
        self.camera_view: CameraView | None = None
        camera_tab = QWidget()
        camera_box = QVBoxLayout(camera_tab)
        camera_box.addWidget(self.camera, 1)
        camera_box.addWidget(self.camera_caption)

        # Trials: the vertical force as the reference (ATI) and the plate measured it.
        self.live = pg.PlotWidget(title=tr("Vertical force on the plate"))
        self.live.setBackground("w")
        self.live.setLabel("left", tr("force (N)"))
        self.live.setLabel("bottom", tr("robot time (s)"))
        self.live.setMouseEnabled(x=False, y=False)
        self.live.addLegend(offset=(10, 10))
        self.live_curves = {
            "ati": self.live.plot(pen=pg.mkPen("#1f5fbf", width=2),
                                  name=tr("reference (ATI)")),
            "plate": self.live.plot(pen=pg.mkPen("#c0262d", width=1,
                                                 style=Qt.PenStyle.DashLine),
                                    name=tr("plate (nominal matrix)"))}
        #: the running trial, sample by sample while it runs (calibration's LiveSamples
        #: blocks): the commanded force and the load the ATI measures along the tool
        self.running_curves = {
            "commanded": self.live.plot(pen=pg.mkPen("#555555", width=1,
                                                     style=Qt.PenStyle.DashLine),
                                        name=tr("commanded")),
            "ati": self.live.plot(pen=pg.mkPen("#7fa8e0", width=2),
                                  name=tr("reference (ATI), trial running"))}
        #: the running trial's blocks (cleared when its file's forces arrive)
        self.running_blocks: list[Any] = []
        #: the live plot's data: per curve, the trials' segments (x, y) in arrival order
        self.live_series: list[TrialSeries] = []
        for p in (self.live,):
            # Only what is visible, about a point per pixel (a campaign is minutes long).
            p.setClipToView(True)
            p.setDownsampling(auto=True, mode="peak")

        self.tabs = QTabWidget()
        self.tabs.setObjectName("calibrate:views")
        self.tabs.tabBar().setStyleSheet(f"QTabBar::tab {{ min-height: {TARGET_PX}px; "
                                         "padding: 0 16px; }")
        for key, widget, label in (("plate", self.plot, tr("Plate")),
                                   ("camera", camera_tab, tr("Camera")),
                                   ("trials", self.live, tr("Trials"))):
            self.tabs.addTab(widget, label)
            widget.setObjectName(f"calibrate:tab:{key}")

        form = QFormLayout()
        form.addRow(tr("Plate description"), self.plate_file)
        form.addRow(tr("Work folder (new)"), self.work_folder)
        form.addRow(tr("Loading plan (YAML)"), self.plan_file)
        form.addRow(tr("Run on"), self.backend)
        left = QVBoxLayout()
        left.addLayout(form)
        for b in self.buttons.values():
            left.addWidget(b)
        left.addWidget(self.progress)
        left.addWidget(self.verdict)
        left.addWidget(self.status)
        left.addStretch(1)
        layout = QHBoxLayout(self)
        layout.addLayout(left, 2)
        layout.addWidget(self.tabs, 3)
        if link is not None:
            link.connection_changed.connect(lambda *_: self._enable())
        self._enable()

    # ------------------------------------------------------------------ steps

    def _enable(self) -> None:
        for i, key in enumerate(STEPS):
            ready = all(k in self.done for k in STEPS[:i])
            self.buttons[key].setEnabled(not self.busy and ready)
        for w in (self.plate_file, self.work_folder, self.plan_file, self.backend):
            w.setEnabled(not self.busy and "run" not in self.done)
        rt = self.backend.findData("rt")
        if rt >= 0:
            # Offered while the GUI is connected to its RT process (a lost connection greys
            # it out; a campaign already running there reports its own failure).
            connected = self.link is not None and self.link.connected
            model = self.backend.model()
            assert isinstance(model, QStandardItemModel)
            item = model.item(rt)
            item.setEnabled(connected)
            item.setToolTip("" if connected else tr("Not connected to the RT process"))

    def step(self, key: str) -> None:
        """Run step ``key`` on the worker (its button's slot)."""
        if self.busy:
            return
        if key == "plan":
            folder = Path(self.work_folder.text().strip()).expanduser()
            if folder.exists() and any(folder.iterdir()):
                self.status.setText(tr("%1 is not empty: choose a new work folder.")
                                    .replace("%1", str(folder)))
                return
            backend = str(self.backend.currentData())
            link = self.link
            if backend == "rt" and (link is None or not link.connected):
                self.status.setText(tr("Not connected to the RT process: choose another "
                                       "backend or connect first."))
                return
            self.flow = CalibrationFlow(
                folder, Path(self.plate_file.text().strip()), backend,
                endpoint=None if link is None or backend != "rt" else link.endpoint,
                client_id=None if link is None or backend != "rt" else link.client_id)
            self.done.clear()
            self.verdict.setText("")
            self._clear_views()
        flow = self.flow
        if flow is None:
            return
        job: Callable[[], Any]
        if key == "plan":
            plan_path = self.plan_file.text().strip()

            def job() -> Any:
                text = None
                if plan_path:
                    try:
                        text = Path(plan_path).expanduser().read_text(encoding="utf-8")
                    except (OSError, UnicodeDecodeError) as exc:
                        raise InputError(f"plan {plan_path}: cannot read: {exc}") from None
                return flow.make_plan(text)
        elif key == "register":
            job = flow.register
        elif key == "run":
            self._clear_live()
            self.tabs.setCurrentIndex(TABS.index("trials"))
            job = lambda: flow.run(self.progress_signal.changed.emit,
                                   self.progress_signal.trial.emit,
                                   self.progress_signal.samples.emit)
        elif key == "fit":
            job = flow.fit
        elif key == "verify":
            job = lambda: flow.verify(progress=self.progress_signal.changed.emit)
        else:
            try:
                target = choose_report_target(self.ask_path,
                                              tr("Save the calibration certificate"),
                                              flow.folder / "certificate.pdf", self.settings)
            except TalusError as exc:
                self.status.setText(str(exc))
                return
            if target is None:
                return
            out, settings = target
            record, actor = self.record, self.actor()
            job = lambda: flow.certificate(out, settings, record, actor)
        self.busy = True
        self.last_error = ""
        self.status.setText(tr("Working…"))
        self._enable()
        self.worker.call(key, job)

    def _progress(self, k: int, n: int, trial: str) -> None:
        self.progress.setRange(0, n)
        self.progress.setValue(k + 1)
        self.status.setText(tr("Trial %1 of %2: %3").replace("%1", str(k + 1))
                            .replace("%2", str(n)).replace("%3", trial))

    def _done(self, key: str, result: Any, error: str) -> None:
        self.busy = False
        if error:
            self.last_error = error
            self.status.setText(tr("Step failed: %1").replace("%1", error))
            self._enable()
            return
        self.done.add(key)
        if key in TAB_OF_STEP:
            self.tabs.setCurrentIndex(TABS.index(TAB_OF_STEP[key]))
        if key == "plan":
            self._draw_plan(result)
            self.status.setText(tr("%1 trials at %2 sites (%3 held out for validation), "
                                   "loads %4 N.").replace("%1", str(result["trials"]))
                                .replace("%2", str(len(result["sites"])))
                                .replace("%3", str(result["held_out"]))
                                .replace("%4", ", ".join(f"{x:g}" for x in result["loads_n"])))
        elif key == "register":
            self._show_camera(result)
        elif key == "run":
            self.status.setText(tr("%1 trials run (%2 s of robot time).")
                                .replace("%1", str(result["trials"]))
                                .replace("%2", f"{result['robot_time_s']:.0f}"))
        elif key == "fit":
            self._draw_cop(result)
            ok = bool(result["verdict"]["pass"])
            self.verdict.setText(tr("PASS") if ok else tr("FAIL"))
            self.verdict.setStyleSheet(f"color: {'#1a7f37' if ok else '#c0262d'};")
            m = result["metrics"]
            text = tr("COP error RMS: %1 mm before, %2 mm after.") \
                .replace("%1", f"{m['before']['cop_rms_mm']:.1f}") \
                .replace("%2", f"{m['nonlinear']['cop_rms_mm']:.1f}")
            failed = result["verdict"].get("failed") or []
            if failed:
                text += " " + tr("Not within the thresholds: %1.").replace(
                    "%1", ", ".join(str(f) for f in failed))
            self.status.setText(text)
        elif key == "verify":
            ok = bool(result["verdict"]["pass"])
            self.status.setText((tr("Verification passed: COP error RMS %1 mm.") if ok else
                                 tr("Verification failed: COP error RMS %1 mm.")).replace(
                "%1", f"{result['metrics']['nonlinear']['cop_rms_mm']:.1f}"))
        else:
            self.last_certificate = Path(result["out"])
            self.status.setText(tr("Certificate written: %1 (%2 pages)")
                                .replace("%1", result["out"])
                                .replace("%2", str(result["pages"])))
        self._enable()

    # ------------------------------------------------------------------ drawing

    def _clear_views(self) -> None:
        self.plot.clear()
        self.camera_view = None
        self.camera.set_frame(None)
        self.camera_caption.setText(tr("The camera's view of the plate appears when the "
                                       "plate is registered."))
        self._clear_live()

    def _clear_live(self) -> None:
        self.live_series = []
        self.running_blocks = []
        for curve in (*self.live_curves.values(), *self.running_curves.values()):
            curve.setData([], [])

    def _samples(self, block: Any) -> None:
        """A block of the running trial's samples (``calibration.trial.LiveSamples``, already
        decimated): appended to the running trial's curves."""
        if self.running_blocks and self.running_blocks[-1].trial_id != block.trial_id:
            self.running_blocks = []
        self.running_blocks.append(block)
        t = np.concatenate([b.t_robot for b in self.running_blocks])
        self.running_curves["commanded"].setData(
            t, np.concatenate([b.force_ref for b in self.running_blocks]))
        self.running_curves["ati"].setData(
            t, np.concatenate([b.ati_load for b in self.running_blocks]))
        if len(self.running_blocks) == 1:
            self.live.setTitle(tr("Vertical force on the plate — trial running: %1")
                               .replace("%1", block.trial_id))

    def _show_camera(self, view: CameraView | None) -> None:
        """The registration step's frame and what it found, in words."""
        self.camera_view = view
        if view is None:
            self.camera.set_frame(None)
            text = tr("This plan places the plate by hand to its marks (nominal "
                      "registration): no camera.")
        else:
            self.camera.set_frame(qimage_from_bgr(view.image_bgr))
            text = tr("%1 of %2 markers detected (green). The plate outline (red) is where "
                      "the camera puts it: %3 mm, %4 mm from the planned place, turned %5°; "
                      "uncertainty %6 mm, %7° (1 σ).") \
                .replace("%1", str(view.markers)).replace("%2", str(len(view.expected_ids))) \
                .replace("%3", f"{view.offset_mm[0]:+.1f}") \
                .replace("%4", f"{view.offset_mm[1]:+.1f}") \
                .replace("%5", f"{view.yaw_deg:+.2f}") \
                .replace("%6", f"{view.sigma_translation_mm:.2f}") \
                .replace("%7", f"{view.sigma_rotation_deg:.3f}")
        self.camera_caption.setText(text)
        self.status.setText(text)

    def _trial(self, series: TrialSeries) -> None:
        """A finished trial's forces appended to the live plot (one gap between trials); its
        running curves give way to them (what the campaign recorded, zeroed and aligned)."""
        self.live_series.append(series)
        if self.running_blocks and self.running_blocks[-1].trial_id == series.trial_id:
            self.running_blocks = []
            for curve in self.running_curves.values():
                curve.setData([], [])
        gap = np.array([np.nan])
        for key, curve in self.live_curves.items():
            xs: list[np.ndarray] = []
            ys: list[np.ndarray] = []
            for s in self.live_series:
                x, y = (s.t_ati_s, s.ati_fz_n) if key == "ati" else (s.t_plate_s, s.plate_fz_n)
                xs += [x, gap]
                ys += [y, gap]
            curve.setData(np.concatenate(xs), np.concatenate(ys), connect="finite")
        self.live.setTitle(tr("Vertical force on the plate — trial %1 of %2: %3")
                           .replace("%1", str(series.index + 1))
                           .replace("%2", str(series.count)).replace("%3", series.trial_id))

    def _outline(self, size_m: tuple[float, float]) -> None:
        w, h = size_m
        x = np.array([-w / 2, w / 2, w / 2, -w / 2, -w / 2])
        y = np.array([-h / 2, -h / 2, h / 2, h / 2, -h / 2])
        self.plot.plot(x, y, pen=pg.mkPen("#333333", width=2), name=tr("plate"))

    def _draw_plan(self, plan: dict[str, Any]) -> None:
        self.plot.clear()
        self._outline(tuple(plan["size_m"]))
        for held, colour, name in ((False, "#1f5fbf", tr("training sites")),
                                   (True, "#bf5f1f", tr("validation sites"))):
            pts = [(x, y) for _n, x, y, h in plan["sites"] if h == held]
            if pts:
                xs, ys = zip(*pts, strict=True)
                self.plot.plot(list(xs), list(ys), pen=None, symbol="o", symbolSize=12,
                               symbolBrush=colour, name=name)

    def _draw_cop(self, record: dict[str, Any]) -> None:
        """The COP error per site before (hollow) and after (filled) the calibration: the
        marker's size is the error (mm)."""
        self.plot.clear()
        self._outline(tuple(record["plate"]["size_m"]))
        for stage, name, filled in (("before", tr("COP error before (mm)"), False),
                                    ("after", tr("COP error after (mm)"), True)):
            pts = cop_error_points(record, stage)
            if not pts:
                continue
            xs, ys, err = (np.array(v) for v in zip(*pts, strict=True))
            sizes = 8 + 4 * np.sqrt(err)
            colour = "#c0262d" if stage == "before" else "#1a7f37"
            scatter = pg.ScatterPlotItem(xs, ys, size=sizes, name=name,
                                         pen=pg.mkPen(colour, width=2),
                                         brush=pg.mkBrush(colour) if filled else None)
            self.plot.addItem(scatter)
            for x, y, e in pts if stage == "after" else ():
                label = pg.TextItem(f"{e:.1f}", color=colour, anchor=(0, 1))
                label.setPos(x, y)
                self.plot.addItem(label)
