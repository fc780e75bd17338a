"""The RT process end to end: a real `talus rt serve` subprocess, real ZeroMQ clients, a client
killed with SIGKILL while it drives the robot."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from rt.errors import InputError
from rt.ipc.client import RtClient, Subscriber

SERVE = [sys.executable, "-m", "rt.cli", "rt", "serve", "--endpoint", "tcp://127.0.0.1:*",
         "--pub-endpoint", "tcp://127.0.0.1:*"]


@pytest.fixture()
def rt_process():
    proc = subprocess.Popen(SERVE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        serving = json.loads(line)["serving"]
        yield proc, serving["endpoint"], serving["pub_endpoint"]
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def _wait_for(pred, timeout=3.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = pred()
        if value:
            return value
        time.sleep(0.01)
    return None


def test_commands_status_estop_reset(rt_process):
    _, endpoint, _ = rt_process
    with RtClient(endpoint, timeout_s=2.0) as client:
        st = client.status()
        assert st["state"] == "run" and st["drives_enabled"] and st["phase"] == 4
        assert client.run("move", {"z": 0.65, "roll": 0.05, "hold_s": 0.2})["program"] == "move"
        assert _wait_for(lambda: client.status()["phase"] in (0, 1, 2))
        client.estop("cli")
        st = _wait_for(lambda: (s := client.status())["state"] == "hard_stop" and s)
        assert st and not st["drives_enabled"] and "estop_cli" in st["causes"]
        # A program cannot start while stopped; bad input changes nothing.
        with pytest.raises(InputError, match="reset the faults first"):
            client.run("benchmark", {})
        with pytest.raises(InputError, match="unknown program 'dance'"):
            client.run("dance", {})
        assert client.reset()["cleared"] == ["estop_cli"]
        st = client.status()
        assert st["state"] == "run" and st["drives_enabled"]
        with pytest.raises(InputError, match="roll"):
            client.run("move", {"roll": 2.0})
        assert client.status()["phase"] == 4


def test_killed_client_soft_stops_within_the_heartbeat_timeout(rt_process):
    _, endpoint, pub = rt_process
    driver = textwrap.dedent(f"""
        import time
        from rt.ipc.client import RtClient
        c = RtClient({endpoint!r}, timeout_s=2.0)
        c.start_heartbeat(0.05)
        c.run("benchmark", {{"duration_s": 60.0}})
        print("driving", flush=True)
        time.sleep(60)
    """)
    sub = Subscriber(pub, ["event"])
    child = subprocess.Popen([sys.executable, "-c", driver], stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().strip() == "driving"
        time.sleep(0.5)                                  # the robot is moving
        killed_at = time.time()
        os.kill(child.pid, signal.SIGKILL)
        child.wait()
        event = None
        end = time.monotonic() + 3.0
        while time.monotonic() < end:
            msg = sub.recv(0.2)
            if msg and msg.get("cause") == "heartbeat_lost":
                event = msg
                break
    finally:
        if child.poll() is None:
            child.kill()
        sub.close()
    assert event is not None and event["reaction"] == "soft_stop"
    # Heartbeats every 50 ms, timeout 250 ms: the stop comes 250-300 ms after the last
    # heartbeat, i.e. within the timeout (+ one heartbeat period and scheduling slack) of the kill.
    assert event["wall"] - killed_at <= 0.25 + 0.1
    with RtClient(endpoint, timeout_s=2.0) as client:
        assert _wait_for(lambda: client.status()["state"] == "soft_stop")


def test_rt_process_killed_drives_drop_within_50_ms():
    """The RT process (rt serve --backend twin_shm) feeds the rig's amplifier watchdog every
    cycle; SIGKILL it and the rig — a separate process, like the real amplifiers — must zero
    the drive outputs within 50 ms (the fault matrix's rt_process_loss row, run for real)."""
    from rt.safety.fault_matrix import run_rt_process_loss

    r = run_rt_process_loss()
    assert r["detected"] and r["reaction"] == "hard_stop", r
    assert r["time_to_zero_output_ms"] <= 50.0, r
    assert r["final_state"] == "drives_off_watchdog_tripped"
