"""A protocol's parameter form, generated from the protocol schema (``protocols.schema``).

Each scalar field of the kind's JSON Schema becomes an editor (numbers and text: a line edit;
a choice: a combo box; a flag: a check box; a list of choices: a comma-separated line),
nested blocks (``pose``, ``amplitude_deg``, ``limits``) become titled groups. Validation is the
schema's own (``validate_protocol_data``): each problem is shown next to the field its path
names. Fields the form cannot edit as one line (lists of holds, a stance block) keep their
value from the protocol file and are shown read-only.
"""
from __future__ import annotations

import copy
import json
from dataclasses import dataclass
from typing import Any

from PySide6.QtCore import Signal
from PySide6.QtWidgets import (
    QCheckBox,
    QComboBox,
    QFormLayout,
    QGroupBox,
    QLabel,
    QLineEdit,
    QVBoxLayout,
    QWidget,
)

from app.field_labels import field_label
from app.form_rows import ERROR_STYLE, error_label, field_cell
from app.i18n import tr
from app.style import TARGET_PX
from protocols.schema import KINDS, validate_protocol_data
from rt.errors import ProtocolValidationError

#: Keys never edited in the form (they say what the document is).
FIXED_KEYS = ("schema_version", "kind")
#: Source name in validation messages (stripped before display).
FORM_SOURCE = "form"


@dataclass
class FieldEditor:
    """One editable leaf: its dotted path, the JSON type, its widget and its error label."""

    path: str
    json_type: str                 # number, integer, string, boolean, choice, choices
    widget: QWidget
    error: QLabel
    optional: bool
    #: the nearest optional block holding this field ("" when none): a block left wholly
    #: empty is omitted, so its required fields are only required once one of them is set
    block: str = ""


def _resolve(schema: dict[str, Any], defs: dict[str, Any]) -> tuple[dict[str, Any], bool]:
    """The schema of a property with $ref and ``X | None`` resolved; and whether None is ok."""
    optional = False
    if "anyOf" in schema:
        members = [m for m in schema["anyOf"] if m.get("type") != "null"]
        optional = len(members) < len(schema["anyOf"])
        if len(members) == 1:
            schema = {**members[0], **{k: v for k, v in schema.items() if k != "anyOf"}}
    if "$ref" in schema:
        target = defs[schema["$ref"].rsplit("/", 1)[-1]]
        schema = {**target, **{k: v for k, v in schema.items() if k != "$ref"}}
    return schema, optional


def _kind_of(schema: dict[str, Any]) -> str | None:
    if "enum" in schema or "const" in schema:
        return "choice"
    t = schema.get("type")
    if t in ("number", "integer", "string", "boolean"):
        return str(t)
    if t == "array":
        items = schema.get("items", {})
        if "enum" in items or "$ref" not in items and items.get("type") == "string":
            return "choices"
    if t == "object" and "properties" in schema:
        return "object"
    return None


def _get(doc: dict[str, Any], path: str) -> Any:
    node: Any = doc
    for p in path.split("."):
        if not isinstance(node, dict) or p not in node:
            return None
        node = node[p]
    return node


def _set(doc: dict[str, Any], path: str, value: Any) -> None:
    parts = path.split(".")
    node = doc
    for p in parts[:-1]:
        if not isinstance(node.get(p), dict):
            node[p] = {}
        node = node[p]
    if value is None:
        node.pop(parts[-1], None)
    else:
        node[parts[-1]] = value


def _prune_empty(doc: dict[str, Any]) -> None:
    """Drop optional blocks the form left empty (``limits: {}`` means no limits)."""
    for key in [k for k, v in doc.items() if isinstance(v, dict)]:
        _prune_empty(doc[key])
        if not doc[key]:
            del doc[key]


def _form_layout(parent: QWidget) -> QFormLayout:
    form = QFormLayout(parent)
    form.setFieldGrowthPolicy(QFormLayout.FieldGrowthPolicy.AllNonFixedFieldsGrow)
    form.setRowWrapPolicy(QFormLayout.RowWrapPolicy.WrapLongRows)
    return form


class ProtocolForm(QWidget):
    """Edits one protocol document. ``changed`` fires after every edit with the new validity.

    Attributes:
        document: the last document built from the form (valid or not).
        valid: whether ``document`` passed the schema.
    """

    changed = Signal(bool)

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.editors: dict[str, FieldEditor] = {}
        self.document: dict[str, Any] = {}
        self.valid = False
        self._base: dict[str, Any] = {}
        self._layout = QVBoxLayout(self)
        self.general_error = QLabel()
        self.general_error.setWordWrap(True)
        self.general_error.setStyleSheet(ERROR_STYLE)

    # ------------------------------------------------------------------ building

    def load(self, document: dict[str, Any]) -> None:
        """Show ``document`` (a validated protocol as JSON, ``protocol_document``)."""
        while self._layout.count():
            item = self._layout.takeAt(0)
            w = None if item is None else item.widget()
            if w is not None and w is not self.general_error:
                # Detach now: deferred deletion waits for the event loop, and the old form
                # must not show under the new one meanwhile.
                w.hide()
                w.setParent(None)
                w.deleteLater()
        self.editors.clear()
        self._base = copy.deepcopy(document)
        cls = KINDS[document["kind"]]
        schema = cls.model_json_schema()
        defs = schema.get("$defs", {})
        main = QGroupBox(tr("Parameters"))
        form = _form_layout(main)
        self._layout.addWidget(main)
        self._add_fields(form, schema, defs, "", document)
        self._layout.addWidget(self.general_error)
        self._layout.addStretch(1)
        self._revalidate()

    def _add_fields(self, form: QFormLayout, schema: dict[str, Any], defs: dict[str, Any],
                    prefix: str, document: dict[str, Any], block: str = "") -> None:
        required = set(schema.get("required", ()))
        for name, raw in schema.get("properties", {}).items():
            if not prefix and name in FIXED_KEYS:
                continue
            path = f"{prefix}{name}"
            prop, optional = _resolve(raw, defs)
            optional = optional or name not in required
            kind = _kind_of(prop)
            if kind == "object":
                box = QGroupBox(field_label(name))
                sub = _form_layout(box)
                self._add_fields(sub, prop, defs, f"{path}.", document,
                                 path if optional else block)
                form.addRow(box)
                continue
            value = _get(document, path)
            if kind is None:
                text = json.dumps(value, ensure_ascii=False) if value is not None else "—"
                shown = QLabel(text[:200] + ("…" if len(text) > 200 else ""))
                shown.setWordWrap(True)
                shown.setToolTip(tr("Edited in the protocol file"))
                form.addRow(field_label(name), shown)
                continue
            widget = self._editor(kind, prop, value)
            error = error_label(f"error:{path}")
            cell = field_cell(widget, error)
            widget.setObjectName(f"field:{path}")
            unit = prop.get("description", "")
            if unit:
                widget.setToolTip(unit)
            form.addRow(field_label(name), cell)
            self.editors[path] = FieldEditor(path, kind, widget, error, optional, block)

    def _editor(self, kind: str, prop: dict[str, Any], value: Any) -> QWidget:
        widget: QWidget
        if kind == "choice":
            combo = QComboBox()
            options = prop.get("enum") or [prop.get("const")]
            combo.addItems([str(o) for o in options])
            if value is not None:
                combo.setCurrentText(str(value))
            combo.currentIndexChanged.connect(self._revalidate)
            widget = combo
        elif kind == "boolean":
            box = QCheckBox()
            box.setChecked(bool(value))
            box.toggled.connect(self._revalidate)
            widget = box
        else:
            edit = QLineEdit()
            if kind == "choices":
                edit.setText(", ".join(str(v) for v in value or []))
                edit.setPlaceholderText(", ".join(
                    str(o) for o in prop.get("items", {}).get("enum", [])))
            elif value is not None:
                edit.setText(f"{value:g}" if isinstance(value, float) else str(value))
            edit.textChanged.connect(self._revalidate)
            widget = edit
        widget.setMinimumHeight(TARGET_PX)
        return widget

    # ------------------------------------------------------------------ reading

    def set_value(self, path: str, text: str) -> None:
        """Type ``text`` into the field at ``path`` (tests, and the keyboard-only user)."""
        widget = self.editors[path].widget
        if isinstance(widget, QComboBox):
            widget.setCurrentText(text)
        elif isinstance(widget, QCheckBox):
            widget.setChecked(text.lower() in ("1", "true", "yes"))
        elif isinstance(widget, QLineEdit):
            widget.setText(text)

    def _read(self) -> tuple[dict[str, Any], dict[str, str]]:
        doc = copy.deepcopy(self._base)
        problems: dict[str, str] = {}
        used_blocks = {ed.block for ed in self.editors.values() if ed.block and (
            not isinstance(ed.widget, QLineEdit) or ed.widget.text().strip())}
        for path, ed in self.editors.items():
            w = ed.widget
            value: Any
            if isinstance(w, QComboBox):
                value = w.currentText()
            elif isinstance(w, QCheckBox):
                value = w.isChecked()
            else:
                assert isinstance(w, QLineEdit)
                raw = w.text()
                text = raw.strip()
                if not text:
                    value = None
                    if not ed.optional and (not ed.block or ed.block in used_blocks):
                        problems[path] = tr("required")
                elif ed.json_type in ("number", "integer"):
                    try:
                        number = float(text.replace(",", ".")) if ed.json_type == "number" \
                            else int(text)
                        value = number
                    except ValueError:
                        problems[path] = (tr("a number is needed") if ed.json_type == "number"
                                          else tr("a whole number is needed"))
                        continue
                elif ed.json_type == "choices":
                    value = [p.strip() for p in text.split(",") if p.strip()]
                else:
                    value = raw            # free text is kept as typed
            _set(doc, path, value)
        _prune_empty(doc)
        return doc, problems

    def _revalidate(self) -> None:
        doc, problems = self._read()
        general: list[str] = []
        if not problems:
            try:
                validate_protocol_data(copy.deepcopy(doc), FORM_SOURCE)
            except ProtocolValidationError as exc:
                for line in str(exc).splitlines():
                    path, reason = self._split(line)
                    target = self._editor_for(path)
                    if target is None:
                        general.append(f"{path}: {reason}" if path else reason)
                    else:
                        problems.setdefault(target, reason)
        for path, ed in self.editors.items():
            ed.error.setText(problems.get(path, ""))
            ed.error.setVisible(path in problems)
        self.general_error.setText("\n".join(general))
        self.general_error.setVisible(bool(general))
        self.document = doc
        self.valid = not problems and not general
        self.changed.emit(self.valid)

    @staticmethod
    def _split(line: str) -> tuple[str, str]:
        prefix = f"{FORM_SOURCE}: "
        line = line.removeprefix(prefix)
        path, sep, reason = line.partition(": ")
        return (path, reason) if sep else ("", line)

    def _editor_for(self, path: str) -> str | None:
        """The editor a problem's path belongs to (itself, or its nearest parent field)."""
        while path:
            if path in self.editors:
                return path
            if "." not in path:
                break
            path = path.rsplit(".", 1)[0]
        return None

    def errors(self) -> dict[str, str]:
        """Field path → the message shown next to it (for tests)."""
        return {p: ed.error.text() for p, ed in self.editors.items() if ed.error.text()}
