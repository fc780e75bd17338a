"""A GUI process for the SIGKILL test: the real window (offscreen) drives a session on the RT
process at argv[1] as a clinician would, prints ``running`` once it runs, then keeps the GUI
alive until it is killed."""
from __future__ import annotations

import os
import sys

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")


def main() -> None:
    from app.launch import application
    from app.main_window import MainWindow
    from app.rt_link import RtLink
    from app.screenshots import settle, start_demo_session
    from app.settings import GuiSettings

    application()
    link = RtLink(sys.argv[1], name="GUI about to be killed")
    window = MainWindow(link, GuiSettings(recordings_dir=sys.argv[2]))
    link.start()
    window.show()
    start_demo_session(window)
    print("running", link.heartbeat.pid if link.heartbeat else -1, flush=True)
    while True:
        settle(1.0)


if __name__ == "__main__":
    main()
