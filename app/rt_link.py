"""The GUI's connection to the RT process: commands, heartbeat, telemetry, connection state.

The GUI thread never waits on the network (GUI.md). Everything that talks to the RT process
runs on Python threads here and comes back to the GUI thread as Qt signals (queued across
threads):

* commands run on a small thread pool (:meth:`RtLink.call`), each reply delivered as
  ``replied(tag, result, error)``;
* STOP and E-STOP have a client and a thread of their own, so a long request (a pre-flight
  takes seconds) never delays a stop;
* a watcher thread asks ``status`` every :attr:`status_period_s` on its own client; no reply
  within ``stale_after_s``, or telemetry older than that, is ``connection_changed(False,
  reason)`` at once, and the pages disable motion. A reply that is merely late (up to
  ``stale_after_s``) is not a lost connection: with a 0.5 s cut-off a machine at load ≈ 9
  flagged a live RT process "lost" about once a minute for half a second, which greyed out the
  clinician's buttons (a click on "Take control" in that instant did nothing) and flashed the
  band red;
* a subscriber thread decodes the telemetry into a preallocated ring of numpy columns
  (:class:`app.telemetry.TelemetryRing`, also counting repetitions); the Run page reads it at
  its own frame rate, so 60 Hz telemetry never floods the event loop nor costs the GUI thread
  per-sample work.

The owner's heartbeat comes from a child process (:mod:`app.heartbeat`) that the GUI thread
ticks: GUI stalls do not starve it, a hung GUI stops it, and when this process dies (SIGKILL
included) it sends a soft stop at once. It is started with the link and stays silent until
ticked (its start-up took 1-4.5 s on a loaded machine: paid before control, not after). It
beats whenever the RT process says this GUI owns the robot, whatever became of the
``control_acquire`` reply: a reply lost on a loaded machine (the RT process took the request,
the 5 s wait ran out) used to leave an owner without a heartbeat, whose first motion the RT
process would soft-stop.
"""
from __future__ import annotations

import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from PySide6.QtCore import QObject, QTimer, Signal

from app.heartbeat import HeartbeatProcess
from app.telemetry import TelemetryRing
from rt.errors import TalusError
from rt.ipc.client import RtClient, Subscriber, default_client_id

#: Telemetry samples kept for the plots (≈ 60 Hz × 33 s).
TELEMETRY_BUFFER = 2000


class RtLink(QObject):
    """Qt face of the RT process for one GUI (one client id: the one that owns the robot).

    Args:
        endpoint: the RT process's request address.
        name: shown to other clients as the owner ("GUI (username)").
        status_period_s: how often the connection is checked, s.
        stale_after_s: telemetry older than this while connected means the link is lost, s.
        heartbeat_period_s: owner heartbeat period, s (the RT process's timeout is 0.25 s).
    """

    #: tag, result (dict or None), error message ("" when ok)
    replied = Signal(str, object, str)
    #: connected, reason when not
    connection_changed = Signal(bool, str)
    #: the latest ``status`` reply
    status_changed = Signal(object)
    #: a published event (safety events, ``session_end`` with its summary)
    event_received = Signal(object)

    def __init__(self, endpoint: str, name: str = "GUI", *, status_period_s: float = 0.25,
                 stale_after_s: float = 1.0, heartbeat_period_s: float = 0.05) -> None:
        super().__init__()
        self.endpoint = endpoint
        self.name = name
        self.status_period_s = status_period_s
        self.stale_after_s = stale_after_s
        self.heartbeat_period_s = heartbeat_period_s
        self.client_id = default_client_id("gui")
        # Commands wait up to 5 s: a loaded machine answered control_acquire after 2 s.
        self.client = RtClient(endpoint, client_id=self.client_id, timeout_s=5.0)
        self._stop_client = RtClient(endpoint, client_id=default_client_id("gui-stop"),
                                     timeout_s=1.0)
        self._pool = ThreadPoolExecutor(max_workers=3, thread_name_prefix="gui-rt")
        self._stop_pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="gui-stop")
        #: the live samples (written by the subscriber thread, read at the frame rate)
        self.telemetry = TelemetryRing(TELEMETRY_BUFFER)
        self._tlock = threading.Lock()
        self._beat_lock = threading.Lock()   # the heartbeat child: started by a worker
        self._last_telemetry_mono = 0.0
        self._quit = threading.Event()
        self.connected = False
        self.last_status: dict[str, Any] | None = None
        self.heartbeat: HeartbeatProcess | None = None
        self._tick_timer = QTimer(self)
        self._tick_timer.setInterval(200)
        self._tick_timer.timeout.connect(self._tick)
        self.replied.connect(self._on_control)
        self.status_changed.connect(self._on_status)
        self._threads = [threading.Thread(target=self._watch, name="gui-rt-watch", daemon=True),
                         threading.Thread(target=self._listen, name="gui-rt-sub", daemon=True)]

    # ------------------------------------------------------------------ lifecycle

    def start(self) -> None:
        """Start watching the connection and receiving telemetry, and the heartbeat child
        (silent until ticked: started now so that its start-up is paid before control is
        taken; on a worker, forking a process the GUI's size takes tens of ms)."""
        for t in self._threads:
            t.start()
        self._pool.submit(self._ensure_heartbeat)

    def close(self) -> None:
        """Stop the threads and close the clients (the heartbeat stops: if this GUI owned a
        moving robot, the RT process soft-stops it). Safe to call twice."""
        if self._quit.is_set():
            return
        self._quit.set()
        for t in self._threads:
            if t.is_alive():
                t.join(timeout=2.0)
        self._tick_timer.stop()
        with self._beat_lock:
            if self.heartbeat is not None:
                self.heartbeat.close()
        self._pool.shutdown(wait=False, cancel_futures=True)
        self._stop_pool.shutdown(wait=False, cancel_futures=True)
        self.client.close()
        self._stop_client.close()

    # ------------------------------------------------------------------ commands

    def call(self, tag: str, fn: Callable[[RtClient], dict[str, Any]]) -> None:
        """Run ``fn(client)`` on a worker; its result or error comes back as ``replied``."""
        self._pool.submit(self._run, tag, fn, self.client)

    def _run(self, tag: str, fn: Callable[[RtClient], dict[str, Any]], client: RtClient) -> None:
        try:
            result = fn(client)
        except TalusError as exc:
            if not self._quit.is_set():
                self.replied.emit(tag, None, str(exc))
            return
        if not self._quit.is_set():
            self.replied.emit(tag, result, "")

    def take_control(self) -> None:
        """Become the owner (reply tag ``control``), then heartbeat from the child process
        (started on the worker too: forking a process the size of the GUI's takes tens of
        milliseconds the GUI thread must not spend)."""
        def acquire(c: RtClient) -> dict[str, Any]:
            reply = c.control_acquire(self.name)
            self._ensure_heartbeat()
            return reply
        self.call("control", acquire)

    def _ensure_heartbeat(self) -> None:
        """Start the heartbeat child unless it runs (any thread but the GUI's)."""
        with self._beat_lock:
            if (self.heartbeat is None or not self.heartbeat.alive()) \
                    and not self._quit.is_set():
                beat = HeartbeatProcess(self.endpoint, self.client_id, self.heartbeat_period_s)
                beat.start()
                self.heartbeat = beat

    def _on_control(self, tag: str, result: object, error: str) -> None:
        if tag != "control" or error or self._quit.is_set():
            return
        self._start_ticking()

    def _on_status(self, status: object) -> None:
        """This GUI owns the robot (however it came to): its heartbeat is ticked."""
        if isinstance(status, dict) and status.get("you_own") and not self._quit.is_set():
            self._start_ticking()

    def _start_ticking(self) -> None:
        """Tick the heartbeat child now and every 200 ms (GUI thread): it beats from the first
        tick on."""
        if not self._tick_timer.isActive():
            self._tick()
            self._tick_timer.start()

    def _tick(self) -> None:
        if self.heartbeat is not None:
            self.heartbeat.tick()

    def stop(self) -> None:
        """Soft stop, on the dedicated stop thread and client (reply tag ``stop``)."""
        self._stop_pool.submit(self._run, "stop", lambda c: c.stop(), self._stop_client)

    def estop(self, source: str = "gui") -> None:
        """Hard stop, on the dedicated stop thread and client (reply tag ``estop``)."""
        self._stop_pool.submit(self._run, "estop", lambda c: c.estop(source), self._stop_client)

    # ------------------------------------------------------------------ telemetry

    def _listen(self) -> None:
        sub: Subscriber | None = None
        probe = RtClient(self.endpoint, client_id=default_client_id("gui-sub"), timeout_s=1.0)
        try:
            while not self._quit.is_set():
                if sub is None:
                    try:
                        sub = Subscriber(probe.subscribe_info()["pub_endpoint"])
                    except TalusError:
                        self._quit.wait(0.5)
                        continue
                try:
                    msg = sub.recv(0.1)
                except TalusError:
                    continue  # one bad publication: skip it, keep listening
                if msg is None:
                    continue
                if msg["topic"] == "telemetry":
                    self.telemetry.push(msg)
                    with self._tlock:
                        self._last_telemetry_mono = time.monotonic()
                elif not self._quit.is_set():
                    self.event_received.emit(msg)
        finally:
            if sub is not None:
                sub.close()
            probe.close()

    # ------------------------------------------------------------------ connection

    def _watch(self) -> None:
        # A reply later than the period is late, not lost: lost is nothing for stale_after_s
        # (module docstring).
        watcher = RtClient(self.endpoint, client_id=default_client_id("gui-watch"),
                           timeout_s=max(self.stale_after_s, self.status_period_s * 2))
        try:
            while not self._quit.is_set():
                reason = ""
                try:
                    st = watcher.status()
                    # "you_own" in the reply is the watcher's; say whether this GUI owns.
                    owner = st.get("owner")
                    st["you_own"] = isinstance(owner, dict) and owner.get("client") == \
                        self.client_id
                    self.last_status = st
                    if st["you_own"]:
                        # The owner heartbeats even when the control reply was lost (module
                        # docstring); its ticks start on the GUI thread (_on_status).
                        self._ensure_heartbeat()
                    if not self._quit.is_set():
                        self.status_changed.emit(st)
                    with self._tlock:
                        age = time.monotonic() - self._last_telemetry_mono
                    if self._last_telemetry_mono and age > self.stale_after_s:
                        reason = f"no telemetry from the robot for {age:.1f} s"
                except TalusError as exc:
                    reason = str(exc)
                self._set_connected(not reason, reason)
                self._quit.wait(self.status_period_s)
        finally:
            watcher.close()

    def _set_connected(self, connected: bool, reason: str) -> None:
        if connected != self.connected and not self._quit.is_set():
            self.connected = connected
            self.connection_changed.emit(connected, reason)
