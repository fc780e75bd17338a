"""The GUI thread's stalls (issue 14): the tracer names what ran and tells work from waiting;
the status band re-polishes nothing when the status did not change; the ROM bands are plain
rectangles with the region API the Run page uses."""
from __future__ import annotations

import time

import gui_support  # noqa: F401  (offscreen platform before Qt)
from PySide6.QtCore import QEvent, QObject, QTimer
from PySide6.QtGui import QColor

from app.pages.run import WINDOW_S, RomBand
from app.screenshots import settle
from app.stall_tracer import StallTracer
from app.status_band import StatusBand


def _busy_for_cpu(seconds: float) -> None:
    """Spend ``seconds`` of this thread's CPU (not wall time: a loaded machine)."""
    end = time.thread_time() + seconds
    while time.thread_time() < end:
        pass


def test_tracer_names_the_slot_that_stalled_and_its_cpu(qtbot):
    tracer = StallTracer(threshold_s=0.025)
    tracer.start()
    try:
        settle(0.1)
        QTimer.singleShot(0, lambda: _busy_for_cpu(0.08))
        settle(0.3)
        QTimer.singleShot(0, lambda: time.sleep(0.08))
        settle(0.3)
    finally:
        tracer.stop()
    busy = [s for s in tracer.stalls if s.cpu_s >= 0.075]
    assert busy, [s.as_dict() for s in tracer.stalls]
    assert busy[0].gap_s >= busy[0].cpu_s
    assert any("_busy_for_cpu" in k for k in busy[0].stacks), busy[0].stacks
    slept = [s for s in tracer.stalls if any("sleep" in k or "<lambda>" in k
                                              for k in s.stacks) and s.cpu_s < 0.04]
    assert slept, [s.as_dict() for s in tracer.stalls]          # waiting, not working
    report = tracer.report()
    assert report["max_gui_cpu_in_a_stall_ms"] >= 75.0
    assert report["stalls_over_threshold"] == len(tracer.stalls)


class _Count(QObject):
    def __init__(self) -> None:
        super().__init__()
        self.kinds: list[QEvent.Type] = []

    def eventFilter(self, watched: QObject, event: QEvent) -> bool:
        self.kinds.append(event.type())
        return False


def test_status_band_touches_nothing_when_the_status_did_not_change(qtbot):
    band = StatusBand()
    qtbot.addWidget(band)
    band.show()
    status = {"state": "run", "causes": [], "latched": [], "owner": {"name": "GUI (a)"}}
    band.update_status(status, True)
    settle(0.1)
    sheet = band.styleSheet()
    counter = _Count()
    for w in (band, band.state_label, band.owner_label, band.connection_label):
        w.installEventFilter(counter)
    for _ in range(5):
        band.update_status(dict(status), True)
    settle(0.1)
    restyle = {QEvent.Type.StyleChange, QEvent.Type.PaletteChange, QEvent.Type.FontChange,
               QEvent.Type.LayoutRequest}
    assert not [k for k in counter.kinds if k in restyle]
    assert band.styleSheet() == sheet
    stopped = dict(status, state="soft_stop", latched=[{"id": 3, "cause": "stop_client"}])
    band.update_status(stopped, True)
    assert band.styleSheet() != sheet and band.state == "soft_stop"
    assert band.reset_button.isVisibleTo(band) and band.detail_label.isVisibleTo(band)
    band.update_status(status, False, "gone")
    assert "gone" in band.connection_label.text()
    assert not band.reset_button.isVisibleTo(band)


def test_rom_band_spans_the_time_axis_with_the_region_given():
    band = RomBand(QColor(1, 2, 3, 40))
    band.setRegion((12.0, -15.0))
    assert band.getRegion() == (-15.0, 12.0)
    r = band.rect()
    assert (r.left(), r.right()) == (-WINDOW_S, 0.0)
    assert band.zValue() < 0
