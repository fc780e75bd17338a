"""A session's round trip through the RT process (twin figures, this machine):

* ``session_start`` latency (validation + reference generation + pre-flight in the worker
  process + start at a cycle boundary), first (worker cold) and second (warm) session;
* the telemetry rate a subscribing client sees during a session (config ``telemetry_hz``);
* deadline misses of the real-time loop while a session runs, per 1000 cycles;
* owner killed (SIGKILL) → the supervisor's soft stop, wall-clock latency.

    .venv/bin/python bench/rt_session.py [--json]
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

from protocols.bench_force import SINE
from protocols.rt_session import protocol_document
from rt.errors import InputError
from rt.ipc.client import RtClient, Subscriber

SERVE = [sys.executable, "-m", "talus", "rt", "serve", "--endpoint", "tcp://127.0.0.1:*",
         "--pub-endpoint", "tcp://127.0.0.1:*"]


#: Attempts at starting a session: a loaded machine's loop can miss deadlines in a row and
#: soft-stop (deadline_overruns) during pre-flight; the bench then acknowledges the stop and
#: tries again, and reports the stops it cleared.
START_ATTEMPTS = 3


def _clear_stops(client: RtClient) -> list[str]:
    """Acknowledge and reset whatever is latched; returns the causes that were."""
    latched = client.status()["latched"]
    if latched:
        client.reset([e["id"] for e in latched])
    return [e["cause"] for e in latched]


def _session(client: RtClient, sub: Subscriber, doc: dict) -> dict:
    cleared: list[str] = []
    for attempt in range(START_ATTEMPTS):
        cleared += _clear_stops(client)
        before = client.status()
        t0 = time.monotonic()
        try:
            started = client.session_start(doc, {"id": "BENCH"})
            break
        except InputError as exc:
            if attempt == START_ATTEMPTS - 1 or "stopped" not in str(exc):
                raise
            cleared.append(f"refused: {exc}")
    latency = time.monotonic() - t0
    sid = started["session_id"]
    n, t_first, t_last = 0, None, None
    while client.session_status()["session"] == sid:
        end = time.monotonic() + 0.2
        while time.monotonic() < end:
            msg = sub.recv(0.05)
            if msg and msg["topic"] == "telemetry" and msg.get("session") == sid:
                # Rate from the samples' own loop times (a receive backlog would inflate a
                # rate taken from arrival times).
                n += 1
                t_first = msg["t"] if t_first is None else t_first
                t_last = msg["t"]
    after = client.status()
    cycles = after["cycles"] - before["cycles"]
    return {"start_latency_s": latency, "stops_cleared_before_start": cleared,
            "telemetry_hz": (n - 1) / (t_last - t_first) if n > 1 else None,
            "misses_per_1000": 1000.0 * (after["deadline_misses"] - before["deadline_misses"])
            / max(cycles, 1)}


def _owner_kill(endpoint: str, pub: str, doc: dict) -> float | None:
    script = textwrap.dedent(f"""
        import json, sys, time
        from rt.ipc.client import RtClient
        c = RtClient({endpoint!r}, timeout_s=120.0)
        c.control_acquire("bench owner")
        c.start_heartbeat(0.05)
        c.session_start(json.loads(sys.stdin.readline()), {{"id": "BENCH"}})
        print("started", flush=True)
        time.sleep(300)
    """)
    child = subprocess.Popen([sys.executable, "-c", script], stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE, text=True)
    sub = Subscriber(pub, ["event"])
    try:
        child.stdin.write(json.dumps(doc) + "\n")
        child.stdin.flush()
        child.stdout.readline()
        time.sleep(2.0)
        killed = time.time()
        os.kill(child.pid, signal.SIGKILL)
        end = time.monotonic() + 5.0
        while time.monotonic() < end:
            msg = sub.recv(0.2)
            if msg and msg.get("cause") == "heartbeat_lost":
                return msg["wall"] - killed
        return None
    finally:
        child.kill()
        child.wait()
        sub.close()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "sine.yaml"
        path.write_text(SINE.format(f=1.0, cycles=6))
        doc = protocol_document(path)
        proc = subprocess.Popen([*SERVE, "--recordings-dir", tmp], stdout=subprocess.PIPE,
                                text=True)
        try:
            serving = json.loads(proc.stdout.readline())["serving"]
            endpoint, pub = serving["endpoint"], serving["pub_endpoint"]
            sub = Subscriber(pub, ["telemetry"])
            with RtClient(endpoint, timeout_s=2.0) as client:
                client.control_acquire("bench")
                client.start_heartbeat(0.05)
                first = _session(client, sub, doc)
                second = _session(client, sub, doc)
                idle0 = client.status()
                time.sleep(5.0)
                idle1 = client.status()
                client.stop_heartbeat()
                client.control_release()
            sub.close()
            kill = _owner_kill(endpoint, pub, doc)
        finally:
            proc.send_signal(signal.SIGTERM)
            proc.wait(timeout=20)
    idle_misses = 1000.0 * (idle1["deadline_misses"] - idle0["deadline_misses"]) / max(
        idle1["cycles"] - idle0["cycles"], 1)
    result = {"twin": True, "first_session": first, "second_session": second,
              "idle_misses_per_1000": idle_misses, "owner_kill_to_soft_stop_s": kill}
    if args.json:
        print(json.dumps(result))
        return 0
    print("session round trip through the RT process (twin, this machine)")
    for name, r in (("first (worker cold)", first), ("second (worker warm)", second)):
        print(f"  {name:22s} start latency {r['start_latency_s']:.2f} s, telemetry "
              f"{r['telemetry_hz'] or 0:.1f} Hz at the client, deadline misses "
              f"{r['misses_per_1000']:.2f} per 1000 cycles")
        if r["stops_cleared_before_start"]:
            print(f"  {'':22s} stops cleared before the start (loaded machine): "
                  f"{', '.join(r['stops_cleared_before_start'])}")
    print(f"  idle loop              deadline misses {idle_misses:.2f} per 1000 cycles")
    print(f"  owner SIGKILL → soft stop: "
          f"{'not seen' if kill is None else f'{kill * 1e3:.0f} ms'} (timeout 250 ms)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
