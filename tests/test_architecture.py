"""Layering contracts (CONVENTIONS 10, issue 9): Qt only in app/; each layer imports only the
layers below it — rt < protocols < patients, calibration < reports < app < talus (the entry
point, where the parts are composed). Checked on the source: every import statement, including
those inside functions, and every ``importlib.import_module("...")`` / ``__import__("...")``
with a literal name, so lazy imports are covered too."""
from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("rt", "protocols", "patients", "calibration", "reports", "app", "talus")
QT = ("PySide6", "shiboken6", "pyqtgraph", "PyQt5", "PyQt6")
#: package -> the packages it must not import (anything above it).
FORBIDDEN: dict[str, tuple[str, ...]] = {
    "rt": ("protocols", "patients", "calibration", "reports", "app", "talus"),
    "protocols": ("patients", "calibration", "reports", "app", "talus"),
    "patients": ("reports", "app", "talus"),
    "calibration": ("reports", "app", "talus"),
    "reports": ("app", "talus"),
    "app": ("talus",),
}


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
        elif isinstance(node, ast.Call) and node.args \
                and isinstance(node.args[0], ast.Constant) \
                and isinstance(node.args[0].value, str):
            f = node.func
            fname = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
            if fname in ("import_module", "__import__"):
                names.add(node.args[0].value)
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


def test_each_layer_imports_only_the_layers_below():
    offenders = []
    for package, forbidden in FORBIDDEN.items():
        for path in _modules(package):
            for name in _imports(path):
                if name.split(".")[0] in forbidden:
                    offenders.append(f"{path.relative_to(ROOT)}: {name}")
    assert offenders == []


def test_the_contract_can_fail(tmp_path):
    bad = tmp_path / "bad.py"
    bad.write_text("def f():\n    from PySide6 import QtWidgets\n"
                   "def g():\n    import importlib\n    importlib.import_module('protocols.x')\n")
    assert "PySide6" in _imports(bad) and "protocols.x" in _imports(bad)
