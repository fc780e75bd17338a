"""Prescribe: the protocol library as cards, the parameter form generated from the schema,
a preview of the reference, and the pre-flight verdict from the RT process (predicted peaks,
or the refusal and its reason). Start is enabled only when the pre-flight of exactly this
document for exactly this patient passed. Where the protocol asks more than the robot can give
(the pre-flight's ``at_robot_limit``, e.g. a heel strike's few ms beyond the drives), a warning
says so in the patient's terms; it does not block Start."""
from __future__ import annotations

import json
import math
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import pyqtgraph as pg
from PySide6.QtCore import QLocale, Qt, Signal
from PySide6.QtWidgets import (
    QButtonGroup,
    QHBoxLayout,
    QLabel,
    QPushButton,
    QScrollArea,
    QVBoxLayout,
    QWidget,
)

from app.i18n import tr
from app.patient_context import PatientContext
from app.preview import Preview, compute_preview
from app.protocol_form import ProtocolForm
from app.rt_link import RtLink
from app.style import LARGE_PX, TARGET_PX
from app.words import STATE_COLOURS
from protocols.library import LIBRARY_DIR
from protocols.rt_session import protocol_document
from rt.errors import TalusError


def library_documents(directory: Path = LIBRARY_DIR) -> list[tuple[str, dict[str, Any]]]:
    """The shipped protocols as (file stem, document), in name order; unreadable files are
    left out (the CLI's ``talus session`` reports them)."""
    out = []
    for path in sorted(directory.glob("*.yaml")):
        try:
            out.append((path.stem, protocol_document(path)))
        except TalusError:
            continue
    return out


def _key(document: dict[str, Any], patient: PatientContext | None) -> str:
    return json.dumps([document, None if patient is None else patient.rt_patient()],
                      sort_keys=True)


class PrescribePage(QWidget):
    """Emits ``start_requested(document)`` when Start is pressed (after a passed pre-flight)."""

    start_requested = Signal(dict)
    preview_ready = Signal(object, str)

    def __init__(self, link: RtLink | None, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.link = link
        self.patient: PatientContext | None = None
        self.preflight_ok_for: str | None = None
        self.last_preflight: dict[str, Any] | None = None
        self.last_refusal: str | None = None
        self.preview: Preview | None = None
        self._preview_pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="gui-preview")
        self._preview_generation = 0
        self.documents = library_documents()

        cards = QVBoxLayout()
        cards.addWidget(QLabel(tr("Protocols")))
        self.card_group = QButtonGroup(self)
        self.card_group.setExclusive(True)
        for i, (stem, doc) in enumerate(self.documents):
            card = QPushButton()
            card.setObjectName(f"card:{stem}")
            card.setAccessibleName(doc["name"])
            card.setCheckable(True)
            card.setMinimumHeight(LARGE_PX)
            card.setToolTip(doc.get("description", ""))
            card.setMinimumWidth(0)
            # The name wraps inside the card (a button's own text does not): no name is cut
            # at the card column's fixed width.
            name = QLabel(doc["name"], card)
            name.setWordWrap(True)
            name.setAttribute(Qt.WidgetAttribute.WA_TransparentForMouseEvents)
            inside = QHBoxLayout(card)
            inside.setContentsMargins(8, 4, 8, 4)
            inside.addWidget(name)
            card.setMinimumHeight(max(LARGE_PX, name.heightForWidth(220) + 12))
            self.card_group.addButton(card, i)
            cards.addWidget(card)
        cards.addStretch(1)
        self.card_group.idClicked.connect(self.select)

        self.form = ProtocolForm()
        self.form.changed.connect(self._form_changed)
        scroll = QScrollArea()
        scroll.setWidgetResizable(True)
        scroll.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        scroll.setWidget(self.form)

        self.plot = pg.PlotWidget()
        self.plot.setBackground("w")
        self.plot.showGrid(x=True, y=True, alpha=0.3)
        self.plot.setLabel("bottom", tr("time (s)"))
        self.plot.addLegend()
        self.preview_label = QLabel()
        self.preview_label.setWordWrap(True)
        self.verdict = QLabel(tr("Pre-flight not run yet."))
        self.verdict.setObjectName("verdict")
        self.verdict.setWordWrap(True)
        self.verdict.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        #: Where the protocol asks more than the robot gives (a warning: Start stays enabled).
        self.beyond = QLabel()
        self.beyond.setObjectName("beyond_robot")
        self.beyond.setWordWrap(True)
        self.beyond.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.beyond.setStyleSheet(f"color: {STATE_COLOURS['soft_stop']}; font-weight: bold;")
        self.beyond.hide()
        self.check_button = QPushButton(tr("Check on the robot model (pre-flight)"))
        self.start_button = QPushButton(tr("Start on the Run page"))
        for b in (self.check_button, self.start_button):
            b.setMinimumHeight(TARGET_PX)
        self.check_button.clicked.connect(self.run_preflight)
        self.start_button.clicked.connect(self._start)
        right = QVBoxLayout()
        right.addWidget(self.plot, 3)
        right.addWidget(self.preview_label)
        right.addWidget(self.verdict, 1)
        right.addWidget(self.beyond)
        right.addWidget(self.check_button)
        right.addWidget(self.start_button)

        card_column = QWidget()
        card_column.setLayout(cards)
        card_column.setFixedWidth(240)
        layout = QHBoxLayout(self)
        layout.addWidget(card_column)
        layout.addWidget(scroll, 5)
        layout.addLayout(right, 4)
        self.preview_ready.connect(self._show_preview)
        if link is not None:
            link.replied.connect(self._replied)
            link.connection_changed.connect(lambda *_: self._update_buttons())
        if self.documents:
            self.card_group.button(0).setChecked(True)
            self.select(0)

    # ------------------------------------------------------------------ selection

    def select(self, index: int) -> None:
        """Show protocol ``index`` of the library in the form."""
        self.card_group.button(index).setChecked(True)
        self.form.load(self.documents[index][1])

    def select_stem(self, stem: str) -> None:
        """Select the library protocol whose file is ``stem``.yaml."""
        for i, (s, _) in enumerate(self.documents):
            if s == stem:
                self.select(i)
                return
        raise KeyError(stem)

    def set_patient(self, patient: PatientContext | None) -> None:
        self.patient = patient
        self._form_changed(self.form.valid)

    # ------------------------------------------------------------------ preview

    def _form_changed(self, valid: bool) -> None:
        self.preflight_ok_for = None
        self.last_preflight = None
        self.last_refusal = None
        self._show_beyond([])
        self.verdict.setText(tr("Pre-flight not run yet.") if valid
                             else tr("Correct the fields marked in red first."))
        self.verdict.setStyleSheet("")
        self._update_buttons()
        if valid:
            self._preview_generation += 1
            generation = self._preview_generation
            doc = self.form.document
            weight = None if self.patient is None else self.patient.weight_kg
            side = "right" if self.patient is None else self.patient.side
            self.preview_label.setText(tr("Computing the preview…"))
            self._preview_pool.submit(self._compute, generation, doc, weight, side)

    def _compute(self, generation: int, doc: dict[str, Any], weight: float | None,
                 side: str) -> None:
        try:
            preview: Preview | None = compute_preview(doc, weight, side)
            error = ""
        except TalusError as exc:
            preview, error = None, str(exc)
        if generation == self._preview_generation:
            self.preview_ready.emit(preview, error)

    def _show_preview(self, preview: Preview | None, error: str) -> None:
        self.preview = preview
        self.plot.clear()
        if preview is None:
            self.preview_label.setText(tr("No preview: %1").replace("%1", error))
            return
        if preview.violations:
            self.preview_label.setText(tr("This protocol cannot be played: %1").replace(
                "%1", "; ".join(preview.violations)))
            return
        if preview.force_protocol:
            self.plot.setLabel("left", tr("force (N)"))
            self.plot.plot(preview.t, preview.fz_n, pen=pg.mkPen("#1f5fbf", width=2),
                           name=tr("force reference"))
        else:
            self.plot.setLabel("left", tr("angle (°)"))
            self.plot.plot(preview.t, preview.pitch_deg, pen=pg.mkPen("#1f5fbf", width=2),
                           name=tr("plantar(+)/dorsi(−) flexion"))
            self.plot.plot(preview.t, preview.roll_deg, pen=pg.mkPen("#bf5f1f", width=2),
                           name=tr("roll (+ is inversion of a right foot)"))
        self.preview_label.setText(tr("Duration: %1 s").replace("%1",
                                                                 f"{preview.duration_s:.1f}"))

    # ------------------------------------------------------------------ pre-flight

    def run_preflight(self) -> None:
        """Ask the RT process to pre-flight the form's document for the patient."""
        if self.link is None or self.patient is None or not self.form.valid:
            return
        doc, patient = self.form.document, self.patient
        key = _key(doc, patient)
        self.verdict.setText(tr("Pre-flight running on the robot model…"))
        self.verdict.setStyleSheet("")
        self._show_beyond([])
        self.link.call(f"preflight:{key}",
                       lambda c: c.session_preflight(doc, patient.rt_patient()))

    def _replied(self, tag: str, result: object, error: str) -> None:
        if not tag.startswith("preflight:"):
            return
        key = tag[len("preflight:"):]
        if key != _key(self.form.document, self.patient):
            return  # the form changed meanwhile: that verdict is not for this document
        if error:
            self.last_refusal = error
            self.verdict.setText(tr("REFUSED: %1").replace("%1", error))
            self.verdict.setStyleSheet("color: #c0262d; font-weight: bold;")
            self._show_beyond([])
        else:
            assert isinstance(result, dict)
            self.last_preflight = result
            self.preflight_ok_for = key
            self.verdict.setText(tr("Pre-flight passed. Predicted peaks: %1").replace(
                "%1", _peaks(result.get("predicted") or {})))
            self.verdict.setStyleSheet("color: #1e8a3c; font-weight: bold;")
            predicted = result.get("predicted") or {}
            self._show_beyond(predicted.get("at_robot_limit") or [],
                              predicted.get("drive_saturation"))
        self._update_buttons()

    def _show_beyond(self, limits: list[Any], saturation: Any = None) -> None:
        """The pre-flight's ``at_robot_limit`` in the patient's terms, and how close the
        drives came to the sustained-saturation stop (``drive_saturation``), or nothing."""
        lines = [line for line in (beyond_words(lim) for lim in clinical_limits(limits))
                 if line]
        if not lines:
            self.beyond.clear()
            self.beyond.hide()
            return
        margin = saturation_words(saturation)
        self.beyond.setText("\n".join(
            [tr("Warning: this protocol asks more than the robot can give (the session may "
                "still start):"), *("• " + line for line in lines), *([margin] if margin
                                                                      else [])]))
        self.beyond.show()

    def _update_buttons(self) -> None:
        connected = self.link is not None and self.link.connected
        self.check_button.setEnabled(connected and self.form.valid and self.patient is not None)
        self.start_button.setEnabled(
            connected and self.preflight_ok_for == _key(self.form.document, self.patient))
        if self.patient is None:
            self.check_button.setToolTip(tr("Choose a patient first"))

    def _start(self) -> None:
        if self.preflight_ok_for == _key(self.form.document, self.patient):
            self.start_requested.emit(dict(self.form.document))


def _number(value: float, decimals: int) -> str:
    """``value`` with ``decimals`` decimals in the language's number format (GUI.md)."""
    return QLocale().toString(float(value), "f", decimals)


def clinical_limits(limits: list[Any]) -> list[Any]:
    """The entries worth a clinician's line: a drive command at its limit while the drive's
    force is at its own is the same moment said twice (the command clips because the force
    asked is beyond the drive), so only the force is kept then; a command at its limit alone
    (a fast motion the drives cannot follow) stays."""
    forces = [e for e in limits if isinstance(e, dict) and e.get("what") == "actuator force"]

    def same_moment(e: dict[str, Any]) -> bool:
        try:
            a0, a1 = float(e["from_s"]), float(e["from_s"]) + float(e["longest_s"])
            return any(a0 <= float(f["from_s"]) + float(f["longest_s"])
                       and float(f["from_s"]) <= a1 for f in forces)
        except (KeyError, TypeError, ValueError):
            return False

    return [e for e in limits if not (isinstance(e, dict) and e.get("what") == "drive command"
                                      and same_moment(e))]


def beyond_words(limit: Any) -> str:
    """One entry of the pre-flight's ``at_robot_limit`` (``SessionFigures.at_limit``: what,
    limit, unit, peak asked, its longest stretch ``longest_s`` from ``from_s``) in a clinician's
    words: what the robot will deliver where the protocol asks more, for how long, and when on
    the protocol's time axis (``from_play_s``). "" for an entry it does not understand (a newer
    RT process's): the verdict above stays right."""
    if not isinstance(limit, dict):
        return ""
    what, lim, peak = limit.get("what"), limit.get("limit"), limit.get("peak")
    # The protocol's own time (its preview's axis) when the RT process gives it; else the
    # session's (an older RT process: the approach and the tare included).
    longest = limit.get("longest_s")
    start = limit.get("from_play_s")
    if not isinstance(start, (int, float)):
        start = limit.get("from_s")
    if not all(isinstance(v, (int, float)) and math.isfinite(v)
               for v in (lim, peak, longest, start)):
        return ""
    assert isinstance(lim, (int, float)) and isinstance(peak, (int, float))
    assert isinstance(longest, (int, float)) and isinstance(start, (int, float))
    ms, at = _number(longest * 1e3, 0), _number(start, 2)
    if what == "actuator force":
        # The drives' force is cut at their limit: the platform cannot push as hard or as
        # fast as prescribed there (a heel strike's peak arrives blunted).
        return (tr("the robot will deliver at most %1 N per drive where the protocol asks "
                   "up to %2 N, for %3 ms from t = %4 s: there the force on the foot falls "
                   "short of the prescribed one")
                .replace("%1", _number(lim, 0)).replace("%2", _number(peak, 0))
                .replace("%3", ms).replace("%4", at))
    if what == "drive command":
        # The amplifiers' command is clipped at its limit: the motion lags the protocol there.
        return (tr("the drives run at full power (their %1 V command limit) for %2 ms from "
                   "t = %3 s: there the platform follows the protocol less closely")
                .replace("%1", _number(lim, 1)).replace("%2", ms).replace("%3", at))
    return ""


def saturation_words(saturation: Any) -> str:
    """The pre-flight's ``drive_saturation`` (``protocols.session.drive_saturation_margin``)
    in a clinician's words: the longest the drives stay at their limit within the
    supervisor's window beside what stops the robot, so a protocol close to that stop is seen
    as such (a heavier patient or a stiffer contact would be stopped). "" when nothing was
    saturated or the entry is not understood (a newer RT process's)."""
    if not isinstance(saturation, dict):
        return ""
    peak, window, stops = (saturation.get(k) for k in ("peak_s", "window_s", "stops_beyond_s"))
    if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in (peak, window, stops)):
        return ""
    assert isinstance(peak, (int, float)) and isinstance(window, (int, float))
    assert isinstance(stops, (int, float))
    if peak <= 0.0:
        return ""
    return (tr("The drives stay at their limit for at most %1 ms in any %2 s; the robot "
               "stops itself beyond %3 ms.")
            .replace("%1", _number(peak * 1e3, 0)).replace("%2", _number(window, 1))
            .replace("%3", _number(stops * 1e3, 0)))


def _peaks(predicted: dict[str, Any]) -> str:
    """The pre-flight's predicted peaks in clinical words and units (against the limits the
    verdict already applied)."""
    parts = []
    force = predicted.get("peak_platform_force_n")
    if isinstance(force, (int, float)):
        parts.append(tr("platform force %1 N").replace("%1", f"{force:.0f}"))
    angles = predicted.get("platform_angles_deg") or {}
    words = {"pitch": tr("dorsi/plantarflexion"), "roll": tr("inversion/eversion")}
    for axis, span in angles.items():
        if isinstance(span, list) and len(span) == 2 and axis in words:
            parts.append(f"{words[axis]} {span[0]:+.1f}° … {span[1]:+.1f}°")
    ankle = predicted.get("ankle_displacement_mm")
    if isinstance(ankle, dict) and all(isinstance(ankle.get(k), (int, float))
                                       for k in ("peak", "rms", "limit")):
        # How far the patient's ankle centre is pushed off its place (the shank dragged):
        # what the comfort limit of pre-flight is about.
        parts.append(tr("the ankle centre moves at most %1 mm (RMS %2 mm; comfort limit %3 mm)")
                     .replace("%1", f"{ankle['peak']:.1f}").replace("%2", f"{ankle['rms']:.1f}")
                     .replace("%3", f"{ankle['limit']:.0f}"))
    err = predicted.get("rms_error_pct")
    if isinstance(err, (int, float)):
        parts.append(tr("force tracking error %1 %").replace("%1", f"{err:.1f}"))
    duration = predicted.get("duration_s")
    if isinstance(duration, (int, float)):
        parts.append(tr("duration %1 s").replace("%1", f"{duration:.0f}"))
    return "; ".join(parts) or "—"
