"""Patients: search by code, register, the patient's card (dosing data, the limits in force in
clinical terms with who set them and when, the ankle setup in force, the sessions with their
outcome), prescribe new limits, enter where the ankle centre sits on the platform (audited by
the record, its refusal shown as it words it), edit the clinical data (body mass, height, side, diagnosis, notes: audited by the record,
refused if someone else saved in between), write the progress report (PDF, to a path the user
chooses, never over a file), and — only for roles allowed to, only on request, every read
audited by the record — the identifying data. "Use for the session" hands the pseudonymous
patient to Prescribe/Run.

The role decides what is enabled (``patients.roles.allowed``); the record enforces it anyway.
Every record call runs on a worker (:class:`app.background.Background`).
"""
from __future__ import annotations

from typing import Any

from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import (
    QFormLayout,
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QListWidget,
    QListWidgetItem,
    QPushButton,
    QScrollArea,
    QVBoxLayout,
    QWidget,
)

from app.background import Background
from app.form_rows import FormRows
from app.i18n import tr
from app.patient_context import PatientContext
from app.report_action import ReportAction
from app.report_export import write_progress_report
from app.settings import GuiSettings
from app.style import TARGET_PX
from app.words import local_time

#: Ankle-setup lengths entered here, in mm (``AnkleSetup`` stores m).
_ANKLE_MM = ("height_above_sole_m", "offset_x_m", "offset_y_m", "sole_above_sensor_m")

#: Clinical limit fields edited here: (key, label) — degrees from neutral, N, deg/s.
_ROM = ("dorsiflexion_deg", "plantarflexion_deg", "inversion_deg", "eversion_deg")


def _number(text: str) -> float | None:
    """The number typed (a decimal comma is fine); None when empty.

    Raises:
        ValueError: not a number.
    """
    text = text.strip().replace(",", ".")
    return float(text) if text else None


def read_numbers(rows: FormRows, keys: tuple[str, ...],
                 message: QLabel) -> dict[str, float | None] | None:
    """The numbers typed in ``rows``' fields ``keys`` (None: empty); None when one is not a
    number: "a number is needed" under each such field and on the message line with the
    fields' names, and nothing else happens."""
    values: dict[str, float | None] = {}
    problems: dict[str, str] = {}
    for key in keys:
        try:
            values[key] = _number(rows.lines()[key].text())
        except ValueError:
            problems[key] = tr("a number is needed")
    rows.set_errors(problems)
    if problems:
        message.setText(tr("%1: a number is needed").replace(
            "%1", ", ".join(rows.labels[k] for k in problems)))
        return None
    return values


class PatientsPage(QWidget):
    """Emits ``patient_chosen(PatientContext)``."""

    patient_chosen = Signal(object)

    def __init__(self, record: Any, parent: QWidget | None = None,
                 settings: GuiSettings | None = None) -> None:
        super().__init__(parent)
        self.record = record
        self.settings = settings or GuiSettings()
        #: the progress report (messages on the page's message line)
        self.report = ReportAction(self, "gui-progress-report", self.settings)
        self.report.message.connect(self._report_said)
        self.report.busy_changed.connect(lambda _busy: self._enable())
        self.actor: Any = None
        self.current: dict[str, Any] | None = None
        self.worker = Background("gui-patients", self)
        self.worker.done.connect(self._done)
        self._all: list[dict[str, Any]] = []

        # left: search, list, registration
        self.search = QLineEdit()
        self.search.setPlaceholderText(tr("Search by code"))
        self.search.textChanged.connect(self._filter)
        self.list = QListWidget()
        self.list.setStyleSheet("QListWidget::item { min-height: 40px; }")
        self.list.currentItemChanged.connect(self._selected)
        sides = [(tr("right"), "right"), (tr("left"), "left"), (tr("both"), "both")]
        new_box = QGroupBox(tr("New patient"))
        self.new_rows = FormRows(QFormLayout(new_box), "new:")
        self.new_code = self.new_rows.line("code", tr("Code"), tr("automatic when empty"))
        self.new_mass = self.new_rows.line("body_mass_kg", tr("Body mass (kg)"))
        self.new_side = self.new_rows.combo("affected_side", tr("Affected side"), sides)
        self.new_diagnosis = self.new_rows.line("diagnosis", tr("Diagnosis (no names)"))
        self.create_button = self.new_rows.button(tr("Register patient"))
        self.create_button.clicked.connect(self.create_patient)
        left = QVBoxLayout()
        left.addWidget(self.search)
        left.addWidget(self.list, 1)
        left.addWidget(new_box)

        # right: the card
        self.card = QLabel(tr("Choose a patient."))
        self.card.setWordWrap(True)
        self.card.setTextFormat(Qt.TextFormat.PlainText)
        self.limits_label = QLabel()
        self.limits_label.setWordWrap(True)
        limits_box = QGroupBox(tr("Prescribe limits"))
        self.limit_rows = FormRows(QFormLayout(limits_box), "limit:")
        for key, label in (("dorsiflexion_deg", tr("Dorsiflexion (°)")),
                           ("plantarflexion_deg", tr("Plantarflexion (°)")),
                           ("inversion_deg", tr("Inversion (°)")),
                           ("eversion_deg", tr("Eversion (°)")),
                           ("max_force_n", tr("Maximum force (N)")),
                           ("max_angular_speed_deg_s", tr("Maximum angular speed (°/s)")),
                           ("reason", tr("Reason"))):
            self.limit_rows.line(key, label)
        self.limit_edits = self.limit_rows.lines()
        self.limits_button = self.limit_rows.button(tr("Save the new limits"))
        self.limits_button.clicked.connect(self.save_limits)

        # where the ankle centre sits on the platform (the exercises turn the foot about it)
        self.ankle_label = QLabel()
        self.ankle_label.setObjectName("ankleInForce")
        self.ankle_label.setWordWrap(True)
        self.ankle_label.setTextFormat(Qt.TextFormat.PlainText)
        ankle_box = QGroupBox(tr("Ankle centre on the platform"))
        self.ankle_rows = FormRows(QFormLayout(ankle_box), "ankle:")
        self.ankle_side = self.ankle_rows.combo("side", tr("Foot on the platform"), sides[:2])
        for key, label in (
                ("height_above_sole_m", tr("Ankle centre above the sole (mm, malleoli)")),
                ("offset_x_m", tr("Offset along the foot (mm, toes +)")),
                ("offset_y_m", tr("Offset across the foot (mm)")),
                ("sole_above_sensor_m", tr("Foot plate thickness (mm)")),
                ("reason", tr("Reason"))):
            self.ankle_rows.line(key, label)
        self.ankle_edits = self.ankle_rows.lines()
        self.ankle_button = self.ankle_rows.button(tr("Save the ankle setup"), "saveAnkle")
        self.ankle_button.clicked.connect(self.save_ankle)
        self.sessions = QListWidget()
        self.sessions.setStyleSheet("QListWidget::item { min-height: 32px; }")
        self.report_button = QPushButton(tr("Progress report (PDF)"))
        self.report_button.setObjectName("progressReport")
        self.report_button.clicked.connect(self.make_report)
        self.open_report_button = self.report.open_button

        # the clinical data, editable by the roles allowed to (patient.update)
        clinical_box = QGroupBox(tr("Clinical data"))
        self.clinical_rows = FormRows(QFormLayout(clinical_box), "clinical:")
        self.edit_mass = self.clinical_rows.line("body_mass_kg", tr("Body mass (kg)"))
        self.edit_height = self.clinical_rows.line("height_cm", tr("Height (cm)"))
        self.edit_side = self.clinical_rows.combo("affected_side", tr("Affected side"), sides)
        self.edit_diagnosis = self.clinical_rows.line("diagnosis", tr("Diagnosis (no names)"))
        self.edit_notes = self.clinical_rows.line("notes", tr("Notes (no names)"))
        self.clinical_button = self.clinical_rows.button(tr("Save clinical data"),
                                                         "saveClinical")
        self.clinical_button.clicked.connect(self.save_clinical)
        self.clinical_edits: tuple[QWidget, ...] = (
            self.edit_mass, self.edit_height, self.edit_side, self.edit_diagnosis,
            self.edit_notes)
        self.identity_button = QPushButton(tr("Show identifying data (audited)"))
        self.identity_button.clicked.connect(self.show_identity)
        self.identity = QLabel()
        self.identity.setWordWrap(True)
        self.identity.setTextFormat(Qt.TextFormat.PlainText)
        self.use_button = QPushButton(tr("Use for the session"))
        self.use_button.setObjectName("usePatient")
        self.use_button.clicked.connect(self.use)
        self.message = QLabel()
        self.message.setWordWrap(True)
        # (the form rows' fields and buttons have the touch height already: FormRows)
        for w in (self.search, self.identity_button, self.use_button, self.report_button,
                  self.open_report_button):
            w.setMinimumHeight(TARGET_PX)
        card_widget = QWidget()
        right = QVBoxLayout(card_widget)
        right.addWidget(self.card)
        right.addWidget(self.limits_label)
        right.addWidget(self.ankle_label)
        right.addWidget(self.use_button)
        right.addWidget(limits_box)
        right.addWidget(ankle_box)
        right.addWidget(clinical_box)
        right.addWidget(QLabel(tr("Sessions")))
        right.addWidget(self.sessions)
        reports_row = QHBoxLayout()
        reports_row.addWidget(self.report_button)
        reports_row.addWidget(self.open_report_button)
        right.addLayout(reports_row)
        right.addWidget(self.identity_button)
        right.addWidget(self.identity)
        right.addStretch(1)
        scroll = QScrollArea()
        scroll.setWidgetResizable(True)
        scroll.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        scroll.setWidget(card_widget)
        layout = QHBoxLayout(self)
        col = QVBoxLayout()
        col.addLayout(left)
        col.addWidget(self.message)
        layout.addLayout(col, 2)
        layout.addWidget(scroll, 3)
        self._enable()

    # ------------------------------------------------------------------ role

    def set_actor(self, actor: Any) -> None:
        """Who is logged in (None: nobody); reloads the list."""
        self.actor = actor
        self.current = None
        self.list.clear()
        self.card.setText(tr("Choose a patient."))
        self.limits_label.setText("")
        self.ankle_label.setText("")
        self.identity.setText("")
        self.sessions.clear()
        self._enable()
        if actor is not None:
            self.reload()

    def _may(self, action: str) -> bool:
        if self.actor is None:
            return False
        from patients.roles import Action, allowed
        return allowed(self.actor.role, Action(action))

    def _enable(self) -> None:
        chosen = self.current is not None
        self.create_button.setEnabled(self._may("patient.create"))
        self.limits_button.setEnabled(chosen and self._may("limits.set"))
        for edit in self.limit_edits.values():
            edit.setEnabled(self._may("limits.set"))
        # The record guards the ankle setup with the limits' permission (a prescription).
        self.ankle_button.setEnabled(chosen and self._may("limits.set"))
        for w in (self.ankle_side, *self.ankle_edits.values()):
            w.setEnabled(chosen and self._may("limits.set"))
        self.identity_button.setVisible(self._may("identity.read"))
        self.identity_button.setEnabled(chosen)
        has_limits = bool(self.current and self.current.get("limits"))
        self.use_button.setEnabled(chosen and has_limits)
        may_edit = self._may("patient.update")
        for w in self.clinical_edits:
            w.setEnabled(chosen and may_edit)
        self.clinical_button.setEnabled(chosen and may_edit)
        # The progress report compares with the prescribed range: it needs limits.
        self.report_button.setEnabled(chosen and has_limits and self._may("session.read")
                                      and not self.report.busy)

    # ------------------------------------------------------------------ record calls

    def reload(self, select: str | None = None) -> None:
        actor = self.actor
        self.worker.call(f"list:{select or ''}", lambda: self.record.list_patients(actor))

    def _selected(self, item: QListWidgetItem | None, _previous: object = None) -> None:
        if item is None:
            return
        self.message.setText("")
        self.open(str(item.data(Qt.ItemDataRole.UserRole)))

    def open(self, code: str) -> None:
        """Load patient ``code``'s card and sessions."""
        actor, record = self.actor, self.record
        self.identity.setText("")

        def load() -> dict[str, Any]:
            return {"patient": record.get_patient(actor, code),
                    "sessions": record.list_sessions(actor, code),
                    "ankle": record.ankle_in_force(actor, code)}
        self.worker.call("open", load)

    def create_patient(self) -> None:
        numbers = read_numbers(self.new_rows, ("body_mass_kg",), self.message)
        if numbers is None:
            return
        mass = numbers["body_mass_kg"]
        actor, record = self.actor, self.record
        code = self.new_code.text().strip().upper() or None
        values = {"body_mass_kg": mass, "affected_side": self.new_side.currentData(),
                  "diagnosis": self.new_diagnosis.text().strip() or None}
        self.worker.call("create", lambda: record.add_patient(actor, code, **values))

    def save_limits(self) -> None:
        if self.current is None:
            return
        from patients.anatomy import ClinicalRom, to_robot

        extra_keys = ("max_force_n", "max_angular_speed_deg_s")
        numbers = read_numbers(self.limit_rows, (*_ROM, *extra_keys), self.message)
        if numbers is None:
            return
        rom = {k: numbers[k] for k in _ROM}
        extra = {k: numbers[k] for k in extra_keys}
        missing = [k for k, v in rom.items() if v is None]
        if missing:
            self.message.setText(tr("Give the four ranges of motion."))
            return
        side = self.current.get("affected_side")
        actor, record, code = self.actor, self.record, self.current["code"]
        reason = self.limit_edits["reason"].text().strip() or None

        def save() -> dict[str, Any]:
            limits = to_robot(ClinicalRom(**{k: float(v) for k, v in rom.items()
                                             if v is not None}), side)
            limits.update({k: v for k, v in extra.items() if v is not None})
            return record.set_limits(actor, code, reason=reason, **limits)
        self.worker.call("limits", save)

    def save_ankle(self) -> None:
        """Enter a new ankle setup (``ClinicalRecord.set_ankle``: audited, history kept). Empty
        fields keep the values in force; the record's refusal is shown as it words it and
        nothing is saved."""
        if self.current is None:
            return
        mm = read_numbers(self.ankle_rows, _ANKLE_MM, self.message)
        if mm is None:
            return
        fields: dict[str, Any] = {k: v / 1000.0 for k, v in mm.items() if v is not None}
        fields["side"] = self.ankle_side.currentData()
        fields["source"] = "entered"        # typed here; the camera path is not wired yet
        actor, record, code = self.actor, self.record, self.current["code"]
        reason = self.ankle_edits["reason"].text().strip() or None
        self.worker.call("ankle", lambda: record.set_ankle(actor, code, reason=reason,
                                                           **fields))

    def save_clinical(self) -> None:
        """Save the edited clinical data (audited; refused when the patient changed since it
        was shown: ``expected_version``). Empty mass or height leaves them as they were."""
        if self.current is None:
            return
        numbers = read_numbers(self.clinical_rows, ("body_mass_kg", "height_cm"), self.message)
        if numbers is None:
            return
        mass, height_cm = numbers["body_mass_kg"], numbers["height_cm"]
        changes = {"body_mass_kg": mass,
                   "height_m": None if height_cm is None else height_cm / 100.0,
                   "affected_side": self.edit_side.currentData(),
                   "diagnosis": self.edit_diagnosis.text().strip(),
                   "notes": self.edit_notes.text().strip()}
        actor, record = self.actor, self.record
        code, version = self.current["code"], self.current.get("version")
        self.worker.call("clinical", lambda: record.update_patient(
            actor, code, expected_version=version, **changes))

    def _report_said(self, text: str) -> None:
        self.message.setText(text)

    def make_report(self) -> None:
        """Ask where, then write the chosen patient's progress report on a worker."""
        if self.current is None:
            return
        code = str(self.current["code"])
        actor, record = self.actor, self.record
        self.report.write(tr("Save the progress report"), f"progress-{code}.pdf",
                          lambda out, settings: write_progress_report(
                              record, actor, code, out, settings))

    def show_identity(self) -> None:
        if self.current is None:
            return
        actor, record, code = self.actor, self.record, self.current["code"]
        self.worker.call("identity",
                         lambda: record.get_patient(actor, code, include_identity=True))

    def use(self) -> None:
        p = self.current
        if p is None or not p.get("limits"):
            return
        lim = p["limits"]
        from rt.safety.limits import PatientLimits
        fields = {k: float(lim[k]) for k in PatientLimits.model_fields if k in lim}
        side = str(p["affected_side"]) if p.get("affected_side") in ("left", "right") \
            else "right"
        ankle = p.get("ankle")
        self.patient_chosen.emit(PatientContext(
            p["code"], p.get("body_mass_kg"), fields,
            f"{lim.get('set_by')} {local_time(lim.get('set_at'))}", side,
            None if ankle is None else dict(ankle)))

    # ------------------------------------------------------------------ results

    def _done(self, tag: str, result: Any, error: str) -> None:
        if error:
            self.message.setText(error)
            return
        if tag not in ("open", "identity") and not tag.startswith("list:"):
            # A refresh that follows a save ("Clinical data saved.") must not erase what the
            # user's action said; choosing another patient clears the message (_selected).
            self.message.setText("")
        if tag.startswith("list:"):
            self._all = list(result)
            self._filter()
            select = tag[len("list:"):]
            if select:
                for i in range(self.list.count()):
                    if self.list.item(i).data(Qt.ItemDataRole.UserRole) == select:
                        self.list.setCurrentRow(i)
        elif tag == "open":
            self.current = {**result["patient"], "ankle": result["ankle"]}
            self._show_card(result["patient"], result["sessions"])
            self._show_ankle(result["ankle"])
        elif tag == "ankle":
            assert self.current is not None
            self.message.setText(tr("Ankle setup saved."))
            self.open(self.current["code"])
        elif tag == "create":
            self.new_code.clear()
            self.new_mass.clear()
            self.new_diagnosis.clear()
            self.message.setText(tr("Patient %1 registered.").replace("%1", result["code"]))
            self.reload(select=result["code"])
        elif tag == "limits":
            assert self.current is not None
            self.message.setText(tr("Limits saved."))
            self.open(self.current["code"])
        elif tag == "clinical":
            self.message.setText(tr("Clinical data saved."))
            self.open(result["code"])
        elif tag == "identity":
            ident = result.get("identity")
            self.identity.setText(tr("No identifying data recorded.") if not ident else "\n".join(
                f"{k}: {v}" for k, v in ident.items() if v))
        self._enable()

    def _filter(self) -> None:
        needle = self.search.text().strip().upper()
        self.list.blockSignals(True)
        self.list.clear()
        for p in self._all:
            if needle in p["code"].upper():
                item = QListWidgetItem(p["code"])
                item.setData(Qt.ItemDataRole.UserRole, p["code"])
                self.list.addItem(item)
        self.list.blockSignals(False)

    def _show_ankle(self, ankle: dict[str, Any] | None) -> None:
        if ankle is None:
            self.ankle_label.setText(tr(
                "No ankle setup entered: exercises turn about the platform's centre."))
            side = self.current.get("affected_side") if self.current else None
            self.ankle_side.setCurrentIndex(max(0, self.ankle_side.findData(side)))
            for key in _ANKLE_MM:
                self.ankle_edits[key].setText("")
            return
        source = tr("measured with the camera") if ankle.get("source") == "camera" \
            else tr("entered by hand")
        self.ankle_label.setText(
            tr("Ankle centre in force (%1 foot): %2 mm above the sole; %3 mm along the foot "
               "(toes +), %4 mm across; foot plate %5 mm; %6")
            .replace("%1", tr(str(ankle["side"])))
            .replace("%2", f"{ankle['height_above_sole_m'] * 1e3:.0f}")
            .replace("%3", f"{ankle['offset_x_m'] * 1e3:+.0f}")
            .replace("%4", f"{ankle['offset_y_m'] * 1e3:+.0f}")
            .replace("%5", f"{ankle['sole_above_sensor_m'] * 1e3:.0f}")
            .replace("%6", source))
        self.ankle_side.setCurrentIndex(max(0, self.ankle_side.findData(ankle["side"])))
        for key in _ANKLE_MM:
            self.ankle_edits[key].setText(f"{ankle[key] * 1e3:g}")

    def _show_card(self, p: dict[str, Any], sessions: list[dict[str, Any]]) -> None:
        mass = p.get("body_mass_kg")
        self.card.setText("\n".join([
            tr("Patient %1").replace("%1", p["code"]),
            tr("Body mass: %1 kg").replace("%1", "—" if mass is None else f"{mass:g}"),
            tr("Height: %1 cm").replace("%1", "—" if p.get("height_m") is None
                                         else f"{100 * float(p['height_m']):.0f}"),
            # The side in the installed language (the record stores right/left/both).
            tr("Affected side: %1").replace("%1", tr(str(p["affected_side"]))
                                            if p.get("affected_side") else "—"),
            tr("Diagnosis: %1").replace("%1", str(p.get("diagnosis") or "—")),
            tr("Notes: %1").replace("%1", str(p.get("notes") or "—"))]))
        self.edit_mass.setText("" if mass is None else f"{mass:g}")
        self.edit_height.setText("" if p.get("height_m") is None
                                 else f"{100 * float(p['height_m']):g}")
        side_index = self.edit_side.findData(p.get("affected_side"))
        self.edit_side.setCurrentIndex(max(0, side_index))
        self.edit_diagnosis.setText(str(p.get("diagnosis") or ""))
        self.edit_notes.setText(str(p.get("notes") or ""))
        lim = p.get("limits")
        if not lim:
            self.limits_label.setText(tr("No limits prescribed yet: a session needs them."))
        else:
            c = lim.get("clinical") or {}
            rom = ", ".join(f"{name} {c[key]:g}°" for key, name in (
                ("dorsiflexion_deg", tr("dorsiflexion")), ("plantarflexion_deg",
                                                           tr("plantarflexion")),
                ("inversion_deg", tr("inversion")), ("eversion_deg", tr("eversion")))
                if key in c)
            self.limits_label.setText(
                tr("Limits in force: %1; force ≤ %2 N; speed ≤ %3 °/s — set by %4 on %5")
                .replace("%1", rom or "—").replace("%2", f"{lim['max_force_n']:g}")
                .replace("%3", f"{lim['max_angular_speed_deg_s']:g}")
                .replace("%4", str(lim.get("set_by"))).replace("%5", local_time(lim.get("set_at"))))
            for key in _ROM:
                if key in c:
                    self.limit_edits[key].setText(f"{c[key]:g}")
            self.limit_edits["max_force_n"].setText(f"{lim['max_force_n']:g}")
            self.limit_edits["max_angular_speed_deg_s"].setText(
                f"{lim['max_angular_speed_deg_s']:g}")
        self.sessions.clear()
        for s in sessions:
            self.sessions.addItem(f"{local_time(s.get('started_at'))}  {s.get('protocol_name')}"
                                  f" — {s.get('outcome')}")
        if not sessions:
            self.sessions.addItem(tr("No sessions yet."))
