"""Translations: English in the code, Spanish in ``app/i18n/talus_es.ts`` (Qt Linguist
format, extracted by ``pyside6-lupdate``, compiled to ``.qm`` by ``pyside6-lrelease``; see
``make translations``). Every visible string goes through :func:`tr`.
"""
from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import QCoreApplication, QLocale, QTranslator

#: Where the compiled translations live (package data).
I18N_DIR = Path(__file__).resolve().parent / "i18n"
#: Language code → name shown in Settings (each in its own language).
LANGUAGES = {"en": "English", "es": "Español"}
#: The translation context: lupdate files free `tr("...")` calls under the empty context.
CONTEXT = ""

_installed: QTranslator | None = None


def tr(text: str) -> str:
    """``text`` in the installed language (English when none is installed)."""
    return QCoreApplication.translate(CONTEXT, text)


def install_language(code: str) -> None:
    """Use language ``code`` (a key of :data:`LANGUAGES`) for every later :func:`tr`.

    Raises:
        ValueError: unknown code, or its compiled translation is missing.
    """
    global _installed
    if code not in LANGUAGES:
        raise ValueError(f"unknown language {code!r}; known: {', '.join(LANGUAGES)}")
    app = QCoreApplication.instance()
    if app is None:
        raise ValueError("install_language needs a QApplication")
    if _installed is not None:
        app.removeTranslator(_installed)
        _installed = None
    QLocale.setDefault(QLocale(QLocale.Language.Spanish if code == "es"
                               else QLocale.Language.English))
    if code == "en":
        return
    translator = QTranslator(app)
    qm = I18N_DIR / f"talus_{code}.qm"
    if not translator.load(str(qm)):
        raise ValueError(f"translation {qm} is missing or unreadable; run `make translations`")
    app.installTranslator(translator)
    _installed = translator
