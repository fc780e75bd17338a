"""The twin's ATI server after a long idle: how late is the first record?

Run:  .venv/bin/python bench/ati_idle.py [--idle 30] [--env plate:0.74] [--rate 1000]

The server runs the full twin (``talus twin serve-ati --env``). A client streams 200 records,
stops, waits ``--idle`` seconds, starts again and measures the wall time from its start request
to the first record, then the median interval of the next 200. Before the fix the twin replayed
the idle time on the first request (2.6 s late after 30 s); now at most
``rt.twin.serve.MAX_CATCH_UP_S`` of twin time is simulated, so the first record should arrive
within about one sample period. Wall-clock figures (±30 % on these VMs); not a pass/fail test.
"""
from __future__ import annotations

import argparse
import itertools
import json
import statistics
import time

from rt.ati.rdt_client import RdtForceTorqueSensor
from rt.ati.rdt_server import RdtServer
from rt.twin.serve import MAX_CATCH_UP_S, twin_wrench_source


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--idle", type=float, default=30.0, help="idle time, s")
    parser.add_argument("--env", default="plate:0.74")
    parser.add_argument("--rate", type=float, default=1000.0, help="record rate, Hz")
    args = parser.parse_args()
    source = twin_wrench_source(args.env, None, seed=0)
    with RdtServer(source, port=0, rate_hz=args.rate) as server, \
            RdtForceTorqueSensor("127.0.0.1", server.port) as client:
        client.read_samples(200, 1.0, start=True)
        client.stop()
        time.sleep(args.idle)
        t0 = time.monotonic()
        records = client.read_samples(201, 10.0, start=True)
        t_first = records[0].t          # host monotonic receipt time of the first record
    times = [w.t for w in records]
    gaps = [b - a for a, b in itertools.pairwise(times)]
    print(json.dumps({
        "idle_s": args.idle, "env": args.env, "rate_hz": args.rate,
        "sample_period_ms": 1e3 / args.rate, "max_catch_up_s": MAX_CATCH_UP_S,
        "first_record_after_start_ms": (t_first - t0) * 1e3,
        "next_200_median_interval_ms": statistics.median(gaps) * 1e3,
        "next_200_max_interval_ms": max(gaps) * 1e3}))


if __name__ == "__main__":
    main()
