"""Spanish: every visible string of app/ is translated, the committed .qm is the compiled .ts,
and the window shows Spanish when asked (Qt's own lupdate/lrelease do the checking)."""
from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import gui_support  # noqa: F401  (offscreen platform before Qt)
import pytest

from app.i18n import I18N_DIR, install_language

APP = Path(__file__).resolve().parents[1] / "app"
BIN = Path(sys.executable).parent


def _sources() -> list[str]:
    return [str(p) for p in sorted(APP.glob("*.py")) + sorted(APP.glob("pages/*.py"))]


def test_every_string_has_a_spanish_translation(tmp_path):
    ts = tmp_path / "talus_es.ts"
    shutil.copy(I18N_DIR / "talus_es.ts", ts)
    out = subprocess.run([str(BIN / "pyside6-lupdate"), *_sources(), "-ts", str(ts),
                          "-no-obsolete"], capture_output=True, text=True, check=True)
    text = ts.read_text(encoding="utf-8")
    assert text.count("<message") > 150, out.stdout
    assert 'type="unfinished"' not in text, "untranslated strings: run `make translations` " \
        "and translate them in app/i18n/talus_es.ts"


def test_committed_qm_is_the_compiled_ts(tmp_path):
    qm = tmp_path / "talus_es.qm"
    subprocess.run([str(BIN / "pyside6-lrelease"), str(I18N_DIR / "talus_es.ts"), "-qm",
                    str(qm)], capture_output=True, check=True)
    assert qm.read_bytes() == (I18N_DIR / "talus_es.qm").read_bytes(), \
        "app/i18n/talus_es.qm is stale: run `make translations`"


def test_window_in_spanish(qtbot, tmp_path):
    from app.main_window import MainWindow
    from app.settings import GuiSettings

    install_language("es")
    try:
        w = MainWindow(None, GuiSettings(language="es", recordings_dir=str(tmp_path)))
        qtbot.addWidget(w)
        assert w.rail_buttons["prescribe"].text() == "Prescribir"
        assert w.stops.stop_button.text().startswith("PARAR")
        assert "Conexión con el robot perdida" in w.band.state_label.text()
    finally:
        install_language("en")
    with pytest.raises(ValueError, match="unknown language"):
        install_language("fr")
