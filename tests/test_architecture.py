"""Layering contracts (CONVENTIONS 10): Qt only in app/, and the real-time side never imports
the GUI. Checked on the source (every import statement), so it holds for lazy imports too."""
from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("rt", "protocols", "patients", "calibration", "reports", "app")
QT = ("PySide6", "shiboken6", "pyqtgraph", "PyQt5", "PyQt6")


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
    return names


def _modules(package: str):
    yield from (ROOT / package).rglob("*.py")


def test_qt_only_in_app():
    offenders = []
    for package in PACKAGES:
        if package == "app":
            continue
        for path in _modules(package):
            if any(name.split(".")[0] in QT for name in _imports(path)):
                offenders.append(str(path.relative_to(ROOT)))
    assert offenders == []


def test_rt_does_not_import_app_or_higher_layers():
    offenders = []
    for path in _modules("rt"):
        for name in _imports(path):
            if name.split(".")[0] in ("app", "patients", "reports", "calibration"):
                offenders.append(f"{path.relative_to(ROOT)}: {name}")
    assert offenders == []


def test_the_contract_can_fail(tmp_path):
    bad = tmp_path / "bad.py"
    bad.write_text("def f():\n    from PySide6 import QtWidgets\n")
    assert "PySide6" in _imports(bad)
