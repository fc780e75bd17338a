"""What wire safety costs and what it protects: the RT server's round trip in plain ZeroMQ vs
CurveZMQ on loopback, and an oversized frame against the server's memory.

Run:  .venv/bin/python bench/ipc_wire.py [--requests 2000]

1. ``status`` round trips through ``RtClient`` to an ``RtServer`` whose handler answers at
   once (so the figure is the wire and the server thread, not the robot): median/p99/max µs,
   plain and with CurveZMQ (handshake excluded: one warm-up request first), and the time of
   the first request of a fresh CurveZMQ client (handshake included).
2. A 200 MB frame sent to a server running in a child process: how long the server's other
   client waits meanwhile (median/max µs of its round trips) and how much the child's peak
   resident memory (VmHWM) grew.

Figures vary ±30 % run to run on these VMs (PLATFORM.md); compare within one run.
Not a pass/fail test.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path
from typing import Any

import numpy as np
import zmq

from rt.ipc.client import RtClient
from rt.ipc.security import ClientCurveConfig, ServerCurveConfig, make_keys
from rt.ipc.server import RtServer

ANY = "tcp://127.0.0.1:*"


class AnswerAll:
    def __getattr__(self, cmd: str) -> Any:
        if cmd.startswith("_"):
            raise AttributeError(cmd)
        return lambda **kwargs: {}


def _us(samples: list[float]) -> dict[str, float]:
    a = np.asarray(samples) * 1e6
    return {"median": round(float(np.median(a)), 1), "p99": round(float(np.percentile(a, 99)), 1),
            "max": round(float(a.max()), 1)}


def round_trips(client: RtClient, n: int) -> list[float]:
    client.status()                                  # connect (and handshake) first
    out = []
    for _ in range(n):
        t0 = time.perf_counter()
        client.status()
        out.append(time.perf_counter() - t0)
    return out


def plain_vs_curve(n: int) -> dict[str, Any]:
    with tempfile.TemporaryDirectory() as tmp:
        server_pub, server_secret = make_keys(Path(tmp) / "server", "server")
        client_pub, client_secret = make_keys(Path(tmp) / "allowed", "ws")
        server_cfg = ServerCurveConfig(secret_key_file=server_secret,
                                       allowed_clients_dir=client_pub.parent)
        client_cfg = ClientCurveConfig(secret_key_file=client_secret,
                                       server_public_key_file=server_pub)
        result: dict[str, Any] = {}
        with RtServer(AnswerAll(), ANY, ANY) as server, \
                RtClient(server.endpoint, timeout_s=5.0) as client:
            result["plain_round_trip_us"] = _us(round_trips(client, n))
        with RtServer(AnswerAll(), ANY, ANY, curve=server_cfg) as server:
            with RtClient(server.endpoint, timeout_s=5.0, curve=client_cfg) as client:
                result["curve_round_trip_us"] = _us(round_trips(client, n))
            firsts = []
            for _ in range(20):
                with RtClient(server.endpoint, timeout_s=5.0, curve=client_cfg) as fresh:
                    t0 = time.perf_counter()
                    fresh.status()
                    firsts.append(time.perf_counter() - t0)
            result["curve_first_request_us"] = _us(firsts)
    return result


_CHILD = textwrap.dedent("""
    import sys
    from rt.ipc.server import RtServer

    class AnswerAll:
        def __getattr__(self, cmd):
            if cmd.startswith("_"):
                raise AttributeError(cmd)
            return lambda **kwargs: {}

    with RtServer(AnswerAll(), "tcp://127.0.0.1:*", "tcp://127.0.0.1:*") as server:
        print(server.endpoint, flush=True)
        sys.stdin.read()
""")


def _hwm_kib(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1])
    raise RuntimeError("no VmHWM")


def oversized_frame() -> dict[str, Any]:
    child = subprocess.Popen([sys.executable, "-c", _CHILD], stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout is not None
        endpoint = child.stdout.readline().strip()
        with RtClient(endpoint, timeout_s=10.0) as client:
            client.status()
            before = _hwm_kib(child.pid)
            ctx = zmq.Context()
            rogue = ctx.socket(zmq.DEALER)
            rogue.setsockopt(zmq.LINGER, 0)
            rogue.connect(endpoint)
            rogue.send_multipart([b"", bytearray(200 * 1024 * 1024)], copy=False)
            during = []
            t_end = time.monotonic() + 1.0
            while time.monotonic() < t_end:
                t0 = time.perf_counter()
                client.status()
                during.append(time.perf_counter() - t0)
            rogue.close()
            ctx.term()
            grown = (_hwm_kib(child.pid) - before) / 1024
        return {"frame_mib": 200, "server_peak_rss_growth_mib": round(grown, 1),
                "other_client_round_trip_us_during": _us(during)}
    finally:
        if child.stdin is not None:
            child.stdin.close()
        child.wait(timeout=10)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--requests", type=int, default=2000)
    args = parser.parse_args()
    print(json.dumps({**plain_vs_curve(args.requests), "oversized": oversized_frame()}))


if __name__ == "__main__":
    main()
