"""Per-call costs of the real-time building blocks, and the recorder's crash loss.

Run:  .venv/bin/python bench/costs.py [--calls 5000] [--crash 5]

Prints one JSON object: the median and p99 cost (µs) of one call of the velocity estimator,
the references (approach, benchmark trajectory, playback), a recorder enqueue (wrench, event),
an RT-server publish; the recorder thread's CPU µs per written message; and with ``--crash N``
the data lost by N recordings SIGKILLed at 1 kHz (ms). These used to be assertions in the test
suite (tests must not depend on how fast or loaded the machine is: PLATFORM.md); they are
figures. Wall-clock, ±30 % run to run on these VMs.
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
from collections.abc import Callable
from pathlib import Path

import numpy as np

METADATA = {"protocol_name": "bench", "protocol_version": "1", "parameters": {},
            "patient_id": "bench", "robot_description": "talus_nominal"}


def _cost_us(fn: Callable[[], object], calls: int) -> dict[str, float]:
    times = np.empty(calls)
    for i in range(calls):
        t0 = time.perf_counter_ns()
        fn()
        times[i] = time.perf_counter_ns() - t0
    return {"median": float(np.median(times)) / 1e3,
            "p99": float(np.percentile(times, 99)) / 1e3}


def estimator_and_references(calls: int) -> dict[str, dict[str, float]]:
    from rt.estimation.velocity import KalmanVelocityEstimator
    from rt.references.approach import Approach
    from rt.references.benchmark_trajectory import BenchmarkTrajectory
    from rt.references.playback import TrajectoryPlayback

    est = KalmanVelocityEstimator()
    z = np.array([0.1, 0.2, 0.3])
    for _ in range(300):
        est.update(z, 1e-3)
    p, v, a = np.zeros(3), np.zeros(3), np.zeros(3)
    ap = Approach()
    ap.reset([0.0] * 3)
    ap.set_target([0.4] * 3, minimum_duration=20.0)
    bench = BenchmarkTrajectory()
    bench.validate()
    t = np.arange(0.0, 26.0 + 1e-9, 0.01)
    play = TrajectoryPlayback(t, bench.evaluate(t)[0])
    play.validate()
    return {"kalman_velocity_update": _cost_us(lambda: est.update(z, 1e-3), calls),
            "approach_update": _cost_us(lambda: ap.update(p, v, a), calls),
            "benchmark_trajectory_update": _cost_us(lambda: bench.update(p, v, a), calls),
            "playback_update": _cost_us(lambda: play.update(p, v, a), calls)}


def recorder(calls: int, tmp: Path) -> dict[str, object]:
    from rt.recording.writer import SessionRecorder

    event = {"t": 0.0, "kind": "warn", "cause": "x", "reaction": "warn", "message": "m",
             "values": {}}
    with SessionRecorder(tmp / "costs.mcap", METADATA, queue_capacity=4 * calls) as rec:
        k = [0]

        def wrench() -> None:
            k[0] += 1
            rec.wrench(k[0] * 1e-3, 1.0, 2.0, 3.0, 0.0, 0.0, 0.0)

        out: dict[str, object] = {"enqueue_wrench": _cost_us(wrench, calls),
                                  "enqueue_event": _cost_us(lambda: rec.event(event), calls)}
    summary = rec.close()
    out["writer_cpu_us_per_message"] = summary["writer_us_per_message"]
    return out


class _IdleHandler:
    """An RT-server handler nobody calls here (only publishing is measured)."""

    def __getattr__(self, name: str) -> Callable[..., dict[str, str]]:
        if name in ("status", "heartbeat", "stop", "estop", "reset", "set_gains", "run"):
            return lambda **_: {"did": name}
        raise AttributeError(name)


def publish(calls: int) -> dict[str, float]:
    from rt.ipc.server import RtServer

    with RtServer(_IdleHandler(), "tcp://127.0.0.1:*", "tcp://127.0.0.1:*") as server:
        i = [0]

        def one() -> None:
            i[0] += 1
            server.publish("telemetry", {"t": i[0] * 1e-3, "seq": i[0]})

        return _cost_us(one, calls)


_CRASH_CHILD = textwrap.dedent("""
    import sys, time
    import numpy as np
    from rt.recording.writer import SessionRecorder
    path, progress_path = sys.argv[1], sys.argv[2]
    progress = np.memmap(progress_path, dtype=np.int64, mode="r+", shape=(1,))
    rec = SessionRecorder(path, {"protocol_name": "bench", "protocol_version": "1",
                                 "parameters": {}, "patient_id": "bench",
                                 "robot_description": "talus_nominal"})
    t0, k = time.perf_counter(), 0
    while True:                       # 1 kHz wrench until SIGKILL
        wait = t0 + k / 1000 - time.perf_counter()
        if wait > 0:
            time.sleep(wait)
        rec.wrench(k / 1000, 1.0, 2.0, 3.0, 0.0, 0.0, 0.0)
        k += 1
        progress[0] = k
""")


def crash_loss_ms(kills: int, tmp: Path) -> list[float]:
    """Data lost (ms of 1 kHz wrench) by recordings SIGKILLed after 1.5 s."""
    from rt.recording.reader import recover

    losses = []
    for n in range(kills):
        path, progress_path = tmp / f"crash{n}.mcap", tmp / f"progress{n}"
        np.zeros(1, np.int64).tofile(progress_path)
        child = subprocess.Popen([sys.executable, "-c", _CRASH_CHILD, str(path),
                                  str(progress_path)])
        progress = np.memmap(progress_path, dtype=np.int64, mode="r", shape=(1,))
        while progress[0] < 1500:
            time.sleep(0.001)
        os.kill(child.pid, signal.SIGKILL)
        child.wait()
        produced = int(progress[0])
        messages, _ = recover(path)
        losses.append(float(produced - len(messages.get("/robot/wrench", []))))
    return losses


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=5000)
    parser.add_argument("--crash", type=int, default=0, metavar="N",
                        help="also SIGKILL N recordings and report the data lost")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        result: dict[str, object] = {"calls": args.calls, "cost_us": {
            **estimator_and_references(args.calls), "rt_server_publish": publish(args.calls)}}
        result["recorder"] = recorder(args.calls, tmp)
        if args.crash:
            losses = crash_loss_ms(args.crash, tmp)
            result["crash_loss_ms"] = {"each": losses, "max": max(losses)}
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
