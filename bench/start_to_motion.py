"""Start to motion with and without a kept pre-flight (issue 14; ``rt.preflight_reuse``), twin
figures.

A real RT process (``talus rt serve``, backend sim, real time) and one client, the GUI's flow:

* ``fresh``: ``session_start`` alone (the RT process pre-flights, then starts);
* ``reused``: ``session_preflight`` first (the Prescribe page, timed on its own), then
  ``session_start`` with the same protocol and patient (the Run page's Start), which runs on
  the kept pre-flight.

Per start: the time to the reply and to the first telemetry sample of the session (motion, as
``bench/gui.py`` defines it); each session is aborted once it moves, and the next starts from
rest. The two kinds alternate (``--reps`` pairs) so that they share the machine's load.

    .venv/bin/python bench/start_to_motion.py [--reps 3] [--cycles 18] [--json]

The RT config tolerates a late loop (``deadline_overruns: 1000``): on a machine shared by
several engineers the real-time loop soft-stops on overruns otherwise, and the figure is the
pre-flight's cost, not the loop's.
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

_HERE = str(Path(__file__).resolve().parent)
sys.path[:] = [p for p in sys.path if str(Path(p or ".").resolve()) != _HERE]

PATIENT = {"id": "BENCH", "weight_kg": 70.0}
CONFIG = ("schema_version: 1\nheartbeat_timeout_s: 1.0\nrobot_limits:\n"
          "  deadline_overruns: 1000\n  max_tracking_error_m: 0.05\n")


def _first_motion(sub: Any, sid: str, timeout_s: float = 30.0) -> float:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        msg = sub.recv(0.05)
        if msg is not None and msg.get("topic") == "telemetry" and msg.get("session") == sid:
            return time.monotonic()
    raise RuntimeError(f"no telemetry of session {sid} in {timeout_s} s")


def _one(client: Any, sub: Any, doc: dict[str, Any], reuse: bool, rec: str) -> dict[str, Any]:
    from rt.errors import InputError

    out: dict[str, Any] = {"kind": "reused" if reuse else "fresh"}
    latched = client.status()["latched"]
    if latched:          # e.g. a loop late at start-up on a loaded machine: said, cleared
        out["cleared"] = [e["cause"] for e in latched]
        client.reset()
    if reuse:
        t0 = time.monotonic()
        try:
            client.session_preflight(doc, PATIENT, timeout_s=600.0)
        except InputError as exc:   # e.g. past the RT process's 120 s on a loaded machine
            out["refused"] = f"pre-flight: {exc}"
            return out
        out["preflight_s"] = round(time.monotonic() - t0, 3)
    while sub.recv(0.0) is not None:
        pass
    t0 = time.monotonic()
    try:
        started = client.session_start(doc, PATIENT, {"dir": rec}, timeout_s=600.0)
    except InputError as exc:       # stopped during pre-flight (a loaded machine): a figure
        out["refused"] = str(exc)
        if client.status()["latched"]:
            client.reset()
        return out
    out["reply_s"] = round(time.monotonic() - t0, 3)
    out["motion_s"] = round(_first_motion(sub, started["session_id"]) - t0, 3)
    out["preflight_reused"] = started["preflight_reused"]
    out["not_reused"] = started["preflight_not_reused"]
    client.session_abort()
    while client.session_status()["session"] == started["session_id"]:
        time.sleep(0.1)
    if client.status()["latched"]:
        client.reset()
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--cycles", type=int, default=18, help="sine Fz cycles (1 Hz)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    from protocols.library import LIBRARY_DIR
    from protocols.rt_session import protocol_document
    from rt.ipc.client import RtClient, Subscriber

    doc = protocol_document(LIBRARY_DIR / "sine_fz.yaml")
    doc.update(cycles=args.cycles, ramp_in_s=1.0, ramp_out_s=1.0)
    tmp = Path(tempfile.mkdtemp(prefix="talus-start-"))
    (tmp / "rt.yaml").write_text(CONFIG)
    proc = subprocess.Popen([sys.executable, "-m", "talus", "rt", "serve", "--config",
                             str(tmp / "rt.yaml"), "--endpoint", "tcp://127.0.0.1:*",
                             "--pub-endpoint", "tcp://127.0.0.1:*", "--recordings-dir",
                             str(tmp)], stdout=subprocess.PIPE, text=True)
    runs: list[dict[str, Any]] = []
    try:
        serving = json.loads(proc.stdout.readline())["serving"]  # type: ignore[union-attr]
        sub = Subscriber(serving["pub_endpoint"], ["telemetry"])
        with RtClient(serving["endpoint"], timeout_s=5.0) as client:
            client.control_acquire("start-to-motion bench")
            client.start_heartbeat(0.05)
            time.sleep(2.0)
            for _ in range(args.reps):
                for reuse in (False, True):
                    runs.append(_one(client, sub, doc, reuse, str(tmp)))
                    if not args.json:
                        print(json.dumps(runs[-1]), flush=True)
            client.stop_heartbeat()
        sub.close()
    finally:
        proc.terminate()
        proc.wait(timeout=60)
    summary: dict[str, Any] = {"protocol_s": float(args.cycles) + 2.0, "runs": runs}
    for kind in ("fresh", "reused"):
        mine = [r for r in runs if r["kind"] == kind and "refused" not in r]
        if not mine:
            continue
        summary[kind] = {k: round(statistics.median(r[k] for r in mine), 3)
                         for k in ("reply_s", "motion_s") + (("preflight_s",)
                                                              if kind == "reused" else ())}
    print(json.dumps(summary if args.json else {k: summary.get(k) for k in ("fresh", "reused")}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
