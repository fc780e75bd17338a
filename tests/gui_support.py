"""Shared by the GUI tests: the offscreen platform (set before Qt is imported) and a real RT
process on the twin with a heartbeat timeout widened for a loaded machine."""
from __future__ import annotations

import os

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from test_rt_process import start_rt, stop_rt, tolerant_config

#: The RT tests' owner heartbeat timeout on a loaded 2-core machine, s.
LOADED_HEARTBEAT_TIMEOUT_S = 1.0


def start_rt_for_gui(recordings_dir: str):
    """(process, endpoint, pub endpoint) of an RT process recording into ``recordings_dir``,
    its supervisor tolerant of a late loop (``tolerant_config``: the GUI tests are about the
    GUI; a loaded machine's late cycles would stop the robot before the step under test)."""
    return start_rt("--config", tolerant_config(Path(recordings_dir).parent),
                    "--heartbeat-timeout", str(LOADED_HEARTBEAT_TIMEOUT_S),
                    "--recordings-dir", recordings_dir)


@contextmanager
def window_on_rt(qtbot, proc, endpoint: str, recordings_dir: str,
                 name: str = "GUI test") -> Iterator:
    """The main window linked to the RT process ``proc`` at ``endpoint``, shown, once the link
    is connected (30 s bound); on exit the window and the link close and ``proc`` stops."""
    from app.main_window import MainWindow
    from app.rt_link import RtLink
    from app.settings import GuiSettings

    link = RtLink(endpoint, name=name)
    window = MainWindow(link, GuiSettings(recordings_dir=recordings_dir))
    qtbot.addWidget(window)
    link.start()
    window.show()
    try:
        qtbot.waitUntil(lambda: link.connected, timeout=30_000)
        yield window
    finally:
        window.close()
        link.close()
        stop_rt(proc)


__all__ = ["LOADED_HEARTBEAT_TIMEOUT_S", "start_rt_for_gui", "stop_rt", "window_on_rt"]
