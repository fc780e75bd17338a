"""The owner's heartbeat, sent from a small child process rather than a thread of the GUI.

Why a process: a heartbeat thread shares the GIL with the GUI thread, and a long paint (a
screenshot grab, a big plot) held it past the RT process's 0.25 s timeout and soft-stopped a
session that was fine (seen on this machine). The child has its own interpreter, so GUI stalls
do not delay it. It still reflects the GUI's health:

* the GUI thread ticks it (:meth:`HeartbeatProcess.tick`, from a Qt timer); when ticks stop
  for :data:`GUI_STALL_LIMIT_S` (the GUI is hung, not merely busy) it stops heartbeating, and
  the RT process soft-stops a running motion after its own timeout;
* when the GUI process dies (SIGKILL included) the pipe reaches end-of-file at once: the child
  sends ``stop`` (a soft stop, anyone may) and exits, so the robot stops without waiting for
  the heartbeat timeout — if it was ever ticked (its GUI owned the robot: a GUI that only
  watched must not stop another's session by dying).

It beats only while ticked, so the GUI starts it early (:class:`app.rt_link.RtLink` does when
it starts) and ticks it once it owns the robot: the child's start-up (numpy and zmq imported,
1.3 s of CPU, 4.5 s at load ≈ 9 on this VM) is then paid before control is taken, not in the
first seconds of a motion, when a silent owner would be soft-stopped.

Qt-free. The child is ``python -m app.heartbeat`` reading ticks on its stdin (a plain
subprocess: ``multiprocessing``'s spawn would re-import the GUI's main script in the child).
"""
from __future__ import annotations

import math
import os
import select
import subprocess
import sys
import time

#: Longest the GUI thread may go without ticking before the heartbeat stops, s.
GUI_STALL_LIMIT_S = 1.0
_QUIT = b"q"
_TICK = b"t"


def serve(endpoint: str, client_id: str, period_s: float, stall_limit_s: float,
          fd: int = 0) -> None:
    """The child's loop: heartbeat every ``period_s`` while ticks arrive on ``fd``."""
    from rt.errors import TalusError
    from rt.ipc.client import RtClient

    client = RtClient(endpoint, client_id=client_id, timeout_s=max(0.2, 4 * period_s))
    last_tick = -math.inf           # silent until the GUI's first tick (module docstring)
    next_beat = time.monotonic()
    try:
        while True:
            wait = max(0.0, next_beat - time.monotonic())
            readable, _, _ = select.select([fd], [], [], wait)
            if readable:
                data = os.read(fd, 4096)
                if not data:
                    if math.isinf(last_tick):
                        return      # never ticked: its GUI did not own the robot
                    # The GUI process is gone without saying goodbye: stop the robot now.
                    try:
                        client.stop()
                    except TalusError:
                        pass  # the RT process soft-stops on the missing heartbeat anyway
                    return
                if _QUIT in data:
                    return
                last_tick = time.monotonic()
                continue
            next_beat = max(next_beat + period_s, time.monotonic())
            if time.monotonic() - last_tick <= stall_limit_s:
                try:
                    client.heartbeat()
                except TalusError:
                    pass  # the GUI's own watcher shows the lost connection
    finally:
        client.close()


class HeartbeatProcess:
    """Heartbeat for ``client_id`` at ``endpoint`` every ``period_s`` from a child process."""

    def __init__(self, endpoint: str, client_id: str, period_s: float = 0.05,
                 stall_limit_s: float = GUI_STALL_LIMIT_S) -> None:
        self._args = [sys.executable, "-m", "app.heartbeat", endpoint, client_id,
                      repr(float(period_s)), repr(float(stall_limit_s))]
        self._proc: subprocess.Popen[bytes] | None = None

    @property
    def pid(self) -> int | None:
        return None if self._proc is None else self._proc.pid

    def start(self) -> None:
        self._proc = subprocess.Popen(self._args, stdin=subprocess.PIPE)

    def alive(self) -> bool:
        return self._proc is not None and self._proc.poll() is None

    def tick(self) -> None:
        """The GUI thread is alive (call a few times a second from a Qt timer)."""
        self._send(_TICK)

    def _send(self, data: bytes) -> None:
        if self._proc is None or self._proc.stdin is None:
            return
        try:
            self._proc.stdin.write(data)
            self._proc.stdin.flush()
        except (OSError, ValueError):
            pass   # the child is gone; alive() says so

    def close(self, timeout_s: float = 2.0) -> None:
        """Stop heartbeating (a clean exit: no stop is sent). Safe to call twice."""
        proc = self._proc
        if proc is None:
            return
        self._proc = None
        if proc.poll() is None:
            try:
                assert proc.stdin is not None
                proc.stdin.write(_QUIT)
                proc.stdin.flush()
            except (OSError, ValueError):
                pass
            try:
                proc.wait(timeout_s)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        if proc.stdin is not None:
            proc.stdin.close()


if __name__ == "__main__":
    serve(sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4]))
