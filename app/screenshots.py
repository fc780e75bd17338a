"""``talus gui --screenshot DIR``: every page rendered to a PNG, with a demo patient and a demo
session run on the twin (a short sine Fz), as the docs and the smoke tests show them.

The driving is the user's: the same buttons and form fields, in the order a clinician uses
them; waits process Qt events (the GUI stays live) with a deadline that names what did not
happen.
"""
from __future__ import annotations

import json
import os
import shutil
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from app.patient_context import PatientContext
from app.settings import GuiSettings
from rt.errors import HardwareError, InputError

#: The demo patient (pseudonymous; limits as a clinician would set for a first session).
DEMO_PATIENT = PatientContext(
    "DEMO-0001", 72.0,
    {"roll_min_deg": -12.0, "roll_max_deg": 12.0, "pitch_min_deg": -15.0,
     "pitch_max_deg": 15.0, "max_force_n": 600.0, "max_angular_speed_deg_s": 30.0},
    limits_set_by="demo")
#: Shots besides one per page: the Run page live, stopped with Reset asking, and Calibrate
#: after its plan and camera registration (the markers detected in the twin camera's frame).
EXTRA_SHOTS = ("run_live", "stopped", "calibrate_camera")
#: Heartbeat timeout of the demo's embedded RT process, s.
DEMO_HEARTBEAT_TIMEOUT_S = 1.0
#: The demo session: sine Fz shortened to a few cycles.
DEMO_PROTOCOL = ("sine_fz", {"cycles": "4", "ramp_in_s": "1", "ramp_out_s": "1"})


def wait_until(predicate: Callable[[], bool], timeout_s: float, what: str) -> None:
    """Run the Qt event loop until ``predicate()`` or ``timeout_s``.

    A real event loop (``QEventLoop``) as ``app.exec()`` runs it, the predicate checked by a
    10 ms timer: the GUI thread sleeps in the loop's poll and wakes for every event, as in the
    product. (Polling ``processEvents`` with a 10 ms sleep in between left every event waiting
    up to the sleep and made the stalls bench/gui.py measured partly the harness's.)

    Raises:
        HardwareError: it did not happen in time (``what`` says what was awaited).
    """
    from PySide6.QtCore import QEventLoop, QTimer

    if predicate():
        return
    end = time.monotonic() + timeout_s
    loop = QEventLoop()
    timer = QTimer()
    timer.setInterval(10)

    def check() -> None:
        if time.monotonic() > end or predicate():
            loop.quit()
    timer.timeout.connect(check)
    timer.start()
    try:
        loop.exec()
    finally:
        timer.stop()
    if not predicate():
        raise HardwareError(f"GUI: {what} did not happen within {timeout_s:g} s")


def settle(seconds: float) -> None:
    """Let the GUI run for ``seconds`` (plots redraw, workers report)."""
    end = time.monotonic() + seconds
    wait_until(lambda: time.monotonic() > end, seconds + 1.0, "settling")


def demo_record(directory: Path) -> tuple[Any, str, str]:
    """A demo clinical record in ``directory`` (``patients.demo``): (record, clinician user
    name, password), or (None, "", "") when the patients package is not installed."""
    try:
        from patients import demo
        from patients.service import ClinicalRecord
    except ImportError:
        return None, "", ""
    record = ClinicalRecord.open(str(directory / "talus-demo.db"), create=True)
    demo.ensure_demo(record)
    password = os.environ.get("TALUS_PASSWORD") or json.loads(
        demo.credentials_file(record).read_text())["password"]
    return record, demo.CLINICIAN, password


def log_in(window: Any, user: str, password: str, timeout_s: float = 30.0) -> None:
    """Log in on the login page."""
    window.show_page("login")
    wait_until(lambda: window.login.checked_users, timeout_s, "the record's users")
    window.login.user.setText(user)
    window.login.password.setText(password)
    window.login.button.click()
    wait_until(lambda: window.actor is not None or "…" not in window.login.message.text()
               and bool(window.login.message.text()), timeout_s, "logging in")
    if window.actor is None:
        raise InputError(f"demo login refused: {window.login.message.text()}")


def log_in_and_choose(window: Any, user: str, password: str, timeout_s: float = 30.0) -> None:
    """Log in on the login page and use the record's first patient for the session."""
    log_in(window, user, password, timeout_s)
    page = window.patients
    wait_until(lambda: page.list.count() > 0, timeout_s, "the patient list")
    page.list.setCurrentRow(0)
    wait_until(lambda: page.use_button.isEnabled(), timeout_s, "the patient's card")
    page.use_button.click()


#: Attempts at starting the demo session (a loaded machine's loop may stop itself).
DEMO_START_ATTEMPTS = 3


def start_demo_session(window: object, timeout_s: float = 180.0) -> None:
    """Prescribe, pre-flight, take control and start the demo session (returns once it runs)."""
    from app.main_window import MainWindow

    assert isinstance(window, MainWindow)
    link = window.link
    assert link is not None
    wait_until(lambda: link.connected, 30.0, "connecting to the RT process")
    if window.patient is None:
        window.set_patient(DEMO_PATIENT)
    stem, values = DEMO_PROTOCOL
    window.show_page("prescribe")
    window.prescribe.select_stem(stem)
    for path, text in values.items():
        window.prescribe.form.set_value(path, text)
    wait_until(lambda: window.prescribe.check_button.isEnabled(), 10.0, "a valid form")
    window.prescribe.check_button.click()
    wait_until(lambda: window.prescribe.start_button.isEnabled()
               or window.prescribe.last_refusal is not None, timeout_s, "the pre-flight")
    if window.prescribe.last_refusal is not None:
        raise InputError(f"demo session refused: {window.prescribe.last_refusal}")
    window.prescribe.start_button.click()
    window.run.control_button.click()
    wait_until(lambda: bool(link.last_status and link.last_status.get("you_own")), 30.0,
               "taking control")
    for attempt in range(DEMO_START_ATTEMPTS):
        # A loaded machine's RT loop may have stopped itself (deadline overruns): the demo
        # acknowledges what is latched, as the clinician would with Reset, and starts again.
        latched = (link.last_status or {}).get("latched") or []
        if latched:
            link.client.reset([int(f["id"]) for f in latched])
        try:
            wait_until(lambda: window.run.start_button.isEnabled(), 30.0, "the robot ready")
        except HardwareError as exc:
            raise HardwareError(f"{exc}: {window.run.message.text()}") from None
        window.run.last_error = ""
        window.run.start_button.click()
        wait_until(lambda: window.run.session_id is not None or bool(window.run.last_error),
                   timeout_s, "the session start")
        if window.run.session_id is not None:
            return
        settle(1.0)                       # the status that says what stopped it
    raise InputError(f"demo session did not start: {window.run.last_error}")


def register_demo_plate(window: Any, folder: Path, timeout_s: float = 120.0) -> None:
    """Calibrate: plan the default campaign in ``folder`` (new) and register the twin plate
    with the camera, as an engineer's first two clicks (the camera tab then shows the markers
    detected)."""
    page = window.calibrate
    window.show_page("calibrate")
    page.work_folder.setText(str(folder))
    for step in ("plan", "register"):
        page.buttons[step].click()
        wait_until(lambda: not page.busy, timeout_s, f"the calibration's {step} step")
        if step not in page.done:
            raise InputError(f"demo calibration {step} failed: {page.last_error}")


def render_all(directory: Path, settings: GuiSettings, force: bool = False) -> list[Path]:
    """Render every page to ``directory/<page>.png``; refuses existing PNGs unless ``force``.

    Returns the files written.
    """
    from app.i18n import install_language
    from app.launch import application, recordings_dir, robot
    from app.main_window import PAGE_KEYS, MainWindow
    from app.rt_link import RtLink

    targets = {k: directory / f"{k}.png" for k in [*PAGE_KEYS, *EXTRA_SHOTS]}
    existing = [str(p) for p in targets.values() if p.exists()]
    if existing and not force:
        raise InputError(f"{', '.join(existing)} exist; use --force to overwrite")
    app = application()
    install_language(settings.language)
    directory.mkdir(parents=True, exist_ok=True)
    settings = settings.model_copy(update={"recordings_dir": str(recordings_dir(settings))})
    written: list[Path] = []
    # A demo on whatever machine runs it (CI shares its cores): the embedded twin's heartbeat
    # timeout is widened as the RT tests do; `talus gui` itself keeps the robot's 0.25 s.
    work = Path(tempfile.mkdtemp(prefix="talus-screenshots-"))
    record, user, password = demo_record(work)
    with robot(settings, heartbeat_timeout_s=DEMO_HEARTBEAT_TIMEOUT_S) as endpoint:
        link = RtLink(endpoint, name="GUI (screenshots)")
        window = MainWindow(link, settings, record=record)
        try:
            link.start()
            window.show()
            pages = list(window.pages)
            assert set(pages) <= set(PAGE_KEYS), pages

            def shot(key: str) -> None:
                settle(0.3)
                tmp = targets[key].with_suffix(".tmp.png")
                if not window.grab().save(str(tmp)):
                    raise InputError(f"could not write {tmp}")
                tmp.replace(targets[key])
                written.append(targets[key])

            wait_until(lambda: link.connected, 60.0, "connecting to the RT process")
            if record is not None:
                shot("login")
                log_in_and_choose(window, user, password)
            # The Run page live, then stopped with the fault latched and Reset asking.
            start_demo_session(window)
            window.show_page("run")
            settle(3.0)
            shot("run_live")
            window.stops.stop_button.click()
            wait_until(lambda: window.band.state == "soft_stop" and bool(window.band.latched),
                       10.0, "the soft stop")
            window.band.reset_button.click()
            shot("stopped")
            window.band.ack_button.click()
            wait_until(lambda: not window.band.latched, 10.0, "the reset")
            wait_until(lambda: window.run.session_id is None, 60.0, "the end of the session")
            window.review.refresh()
            window.review.open_button.click()
            wait_until(lambda: window.review.data is not None, 60.0, "reading the recording")
            for key in pages:
                if key not in ("login", "users"):
                    window.show_page(key)
                    shot(key)
            if "calibrate" in pages:
                register_demo_plate(window, work / "calibration")
                shot("calibrate_camera")
            if "users" in pages:
                # The Users page is the administrator's: log in as the demo admin.
                from patients import demo
                window.lock("")
                log_in(window, demo.ADMIN, password)
                wait_until(lambda: window.users.list.count() > 0, 30.0, "the user list")
                window.show_page("users")
                shot("users")
        finally:
            window.close()
            link.close()
            if record is not None:
                record.close()
            shutil.rmtree(work, ignore_errors=True)
    del app
    return written
