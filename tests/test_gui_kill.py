"""A GUI process killed with SIGKILL during a session leaves the robot soft-stopped within
250 ms (+ the loaded-machine slack the RT tests use): its heartbeat child sees the GUI's pipe
close and sends STOP at once, without waiting for the heartbeat timeout."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import gui_support
from test_rt_process import LOADED_MACHINE_SLACK_S

from rt.ipc.client import RtClient, Subscriber

DRIVER = Path(__file__).with_name("gui_kill_driver.py")


def _soft_stop_after(sub: Subscriber, t_wall: float, timeout_s: float):
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        msg = sub.recv(0.2)
        if msg and msg.get("reaction") in ("soft_stop", "hard_stop") \
                and msg.get("wall", 0.0) >= t_wall - 0.01:
            return msg
    return None


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def test_gui_killed_mid_session_soft_stops_the_robot(tmp_path):
    rec = tmp_path / "rec"
    rec.mkdir()
    proc, endpoint, pub = gui_support.start_rt_for_gui(str(rec))
    sub = Subscriber(pub, ["event"])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(Path(__file__).resolve().parents[1]), os.environ.get("PYTHONPATH", "")])}
    gui = subprocess.Popen([sys.executable, str(DRIVER), endpoint, str(rec)],
                           stdout=subprocess.PIPE, text=True, env=env)
    try:
        line = gui.stdout.readline().split()
        assert line and line[0] == "running", line
        heartbeat_pid = int(line[1])
        time.sleep(0.5)                                  # the session runs
        with RtClient(endpoint, timeout_s=2.0) as c:
            st = c.status()
            assert st["session"] is not None and st["state"] == "run", st
        killed_at = time.time()
        os.kill(gui.pid, signal.SIGKILL)
        gui.wait()
        event = _soft_stop_after(sub, killed_at, 5.0)
    finally:
        if gui.poll() is None:
            gui.kill()
        sub.close()
    try:
        assert event is not None and event["reaction"] == "soft_stop", event
        latency = event["wall"] - killed_at
        print(f"\nGUI killed → soft stop ({event['cause']}): {latency * 1e3:.0f} ms")
        assert event["cause"] == "stop_client"          # the heartbeat child's STOP
        assert latency <= 0.25 + LOADED_MACHINE_SLACK_S
        with RtClient(endpoint, timeout_s=2.0) as c:
            deadline = time.monotonic() + 5.0
            while c.status()["state"] != "soft_stop" and time.monotonic() < deadline:
                time.sleep(0.05)
            assert c.status()["state"] == "soft_stop"
        deadline = time.monotonic() + 5.0
        while _alive(heartbeat_pid) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not _alive(heartbeat_pid)                # the child did not outlive the GUI
    finally:
        gui_support.stop_rt(proc)
