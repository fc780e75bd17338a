"""One form row, written once: a label that wraps (a long Spanish label must not widen the form
past a 1366×768 screen), the field at the touch height, and its error message under the field
(red, hidden until there is one) — the way the protocol editor shows validation messages next
to the field. :class:`FormRows` builds such rows into a ``QFormLayout`` and keeps the fields
and their error labels by key."""
from __future__ import annotations

from PySide6.QtWidgets import (
    QComboBox,
    QFormLayout,
    QLabel,
    QLineEdit,
    QPushButton,
    QVBoxLayout,
    QWidget,
)

from app.style import TARGET_PX

#: Colour of an error message under its field.
ERROR_STYLE = "color: #c0262d;"


def error_label(object_name: str = "") -> QLabel:
    """A field's error message: red, wrapping, hidden while empty."""
    error = QLabel()
    if object_name:
        error.setObjectName(object_name)
    error.setWordWrap(True)
    error.setStyleSheet(ERROR_STYLE)
    error.hide()
    return error


def field_cell(widget: QWidget, error: QLabel) -> QWidget:
    """The field with its error label under it, as one cell of a form row."""
    cell = QWidget()
    col = QVBoxLayout(cell)
    col.setContentsMargins(0, 0, 0, 0)
    col.setSpacing(2)
    col.addWidget(widget)
    col.addWidget(error)
    return cell


def row_label(text: str) -> QLabel:
    """A form row's label, wrapping instead of widening the form."""
    label = QLabel(text)
    label.setWordWrap(True)
    return label


class FormRows:
    """Rows of ``form``: ``line``/``combo``/``button`` add one and return its widget; fields
    are kept by key (``fields``), their error labels too (``errors``, object name
    ``error:<prefix><key>``), ``set_errors`` shows the messages of a check and hides the
    others."""

    def __init__(self, form: QFormLayout, prefix: str = "") -> None:
        self.form = form
        self.prefix = prefix
        self.fields: dict[str, QWidget] = {}
        self.errors: dict[str, QLabel] = {}
        self.labels: dict[str, str] = {}
        form.setRowWrapPolicy(QFormLayout.RowWrapPolicy.WrapLongRows)

    def add(self, key: str, label: str, widget: QWidget) -> QWidget:
        """A row of ``widget`` labelled ``label`` with its error label."""
        widget.setMinimumHeight(TARGET_PX)
        if not widget.objectName():
            widget.setObjectName(f"{self.prefix}{key}")
        error = error_label(f"error:{self.prefix}{key}")
        self.form.addRow(row_label(label), field_cell(widget, error))
        self.fields[key] = widget
        self.errors[key] = error
        self.labels[key] = label
        return widget

    def line(self, key: str, label: str, placeholder: str = "") -> QLineEdit:
        edit = QLineEdit()
        if placeholder:
            edit.setPlaceholderText(placeholder)
        self.add(key, label, edit)
        return edit

    def combo(self, key: str, label: str, choices: list[tuple[str, str]]) -> QComboBox:
        """A choice of (shown text, value) pairs."""
        box = QComboBox()
        for text, value in choices:
            box.addItem(text, value)
        self.add(key, label, box)
        return box

    def button(self, text: str, object_name: str = "") -> QPushButton:
        """A button spanning the form's width (its action)."""
        button = QPushButton(text)
        button.setMinimumHeight(TARGET_PX)
        if object_name:
            button.setObjectName(object_name)
        self.form.addRow(button)
        return button

    def lines(self) -> dict[str, QLineEdit]:
        """The line edits by key."""
        return {k: w for k, w in self.fields.items() if isinstance(w, QLineEdit)}

    def set_errors(self, problems: dict[str, str]) -> None:
        """Show each key's message under its field; clear the others."""
        for key, error in self.errors.items():
            text = problems.get(key, "")
            error.setText(text)
            error.setVisible(bool(text))
