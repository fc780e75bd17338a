"""Figures for the session report of a long recording: time and peak memory to render it.

    .venv/bin/python bench/reports.py --minutes 60            # make the recording, render it
    .venv/bin/python bench/reports.py --recording X.mcap      # render an existing one

The recording is made synthetically with the recorder API (``SessionRecorder``), as the
session writes it: /robot/state from a ring (1 kHz), /robot/wrench and /protocol/reference
through the queue (1 kHz each), the metadata first. The motion is a session-like mix: the
platform pitching ±10° at 0.1 Hz (slider references from inverse kinematics) while the force
follows 300 ± 100 N at 1 Hz with noise. The render runs in a child process so its peak
resident memory (``ru_maxrss``) is the report's alone; the child's RSS after imports is
printed too, so the reading's own share is the difference.
"""
from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

# This file is bench/reports.py: its folder must not shadow the ``reports`` package.
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).parent.resolve()]

RATE_HZ = 1000


class _GeneratedRing:
    """A RingSource whose rows are computed on demand (no ring to overrun)."""

    def __init__(self, table: np.ndarray):
        self.table = table          # one period of state rows without t (n × 15)
        self.written = 0

    def drain(self, start: int) -> tuple[np.ndarray, int]:
        end = self.written
        idx = np.arange(start, end)
        rows = np.empty((len(idx), 16))
        rows[:, 0] = idx / RATE_HZ
        rows[:, 1:] = self.table[idx % len(self.table)]
        return rows, end


def make_recording(path: Path, minutes: float) -> dict:
    from rt.model import RobotModel
    from rt.recording.writer import SessionRecorder

    kin = RobotModel.load().kin
    period = 10 * RATE_HZ                       # 10 s: the pitch motion's period
    t = np.arange(period) / RATE_HZ
    pitch = np.radians(10.0) * np.sin(2 * np.pi * 0.1 * t)
    q = np.array([kin.ik(0.63, 0.0, float(p), check=False).q for p in pitch])
    qd = np.gradient(q, 1.0 / RATE_HZ, axis=0)
    table = np.hstack([q + 2e-5 * np.sin(7 * t)[:, None], qd, q, np.full((period, 3), 150.0),
                       np.full((period, 3), 0.5)])
    ring = _GeneratedRing(table)
    meta = {"protocol_name": "Synthetic 60-min session", "protocol_version": "1",
            "parameters": {"kind": "sine_fz", "amplitude_n": 100.0, "mean_n": 300.0},
            "patient_id": "BENCH-0001", "robot_description": "talus-3prs-nominal-twin"}
    n = int(minutes * 60 * RATE_HZ)
    rng = np.random.default_rng(0)
    t0 = time.perf_counter()
    rec = SessionRecorder(path, meta, start_wall_ns=1_790_000_000 * 10**9)
    rec.attach_state_ring(ring, start=0)
    step = 1000
    for k0 in range(0, n, step):
        k = np.arange(k0, min(n, k0 + step))
        tt = k / RATE_HZ
        ref = 300.0 + 100.0 * np.sin(2 * np.pi * tt)
        meas = ref + rng.normal(0.0, 1.5, len(k))
        phase = "play" if 0 < k0 < n - step else ("approach" if k0 == 0 else "return")
        for ti, fz_ref, fz in zip(tt.tolist(), ref.tolist(), meas.tolist()):
            rec.wrench(ti, 0.0, 0.0, -fz, 0.0, 0.0, 0.0)
            rec.reference(ti, [0.0, 0.0, fz_ref], phase=phase)
        ring.written = int(k[-1]) + 1
        # Paced like a session: the next second waits until the writer has taken this one
        # (bench only: a queue fed faster than the writer drains it would drop messages).
        while rec._queue:
            time.sleep(0.002)
    info = rec.close()
    return {"write_s": time.perf_counter() - t0, "bytes": info["bytes"],
            "dropped": info["dropped_total"], "messages": sum(info["messages"].values())}


def render(path: Path, out: Path) -> dict:
    """Child process: read and render, report time and peak RSS."""
    from reports.session_data import session_input_from_recording
    from reports.session_report import render_session_report

    rss_imports = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    t0, c0 = time.perf_counter(), time.process_time()
    inp = session_input_from_recording(path)
    t_read = time.perf_counter() - t0
    pages = render_session_report(inp, out, force=True)
    t_all = time.perf_counter() - t0
    # CPU time too: on a shared, loaded machine the wall time says more about the neighbours.
    return {"read_s": t_read, "render_s": t_all - t_read, "total_s": t_all, "pages": pages,
            "cpu_s": time.process_time() - c0,
            "samples": inp.figures["samples"] if inp.figures else 0,
            "rss_after_imports_mb": rss_imports,
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
            "pdf_bytes": out.stat().st_size}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--minutes", type=float, default=60.0)
    ap.add_argument("--recording", type=Path, default=None)
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    if args.child:
        print(json.dumps(render(args.recording, args.out)))
        return 0
    tmp = Path(tempfile.mkdtemp(prefix="talus-bench-reports-"))
    rec = args.recording
    if rec is None:
        rec = tmp / f"synthetic_{args.minutes:g}min.mcap"
        w = make_recording(rec, args.minutes)
        print(f"recording: {args.minutes:g} min at 1 kHz, {w['messages']} messages, "
              f"{w['bytes'] / 1e6:.1f} MB, written in {w['write_s']:.0f} s, "
              f"dropped {w['dropped']}")
    out = args.out or tmp / "report.pdf"
    proc = subprocess.run([sys.executable, __file__, "--child", "--recording", str(rec),
                           "--out", str(out)], check=False, capture_output=True, text=True)
    if proc.returncode:
        sys.stderr.write(proc.stderr)
        return proc.returncode
    r = json.loads(proc.stdout.strip().splitlines()[-1])
    print(f"report: {r['pages']} pages, {r['pdf_bytes'] / 1e3:.0f} kB, {r['samples']} samples")
    print(f"  time: read {r['read_s']:.1f} s + render {r['render_s']:.1f} s = "
          f"{r['total_s']:.1f} s wall, {r['cpu_s']:.1f} s CPU")
    print(f"  peak RSS {r['peak_rss_mb']:.0f} MB (after imports {r['rss_after_imports_mb']:.0f}"
          f" MB: the report's share {r['peak_rss_mb'] - r['rss_after_imports_mb']:.0f} MB)")
    print(f"  files in {tmp}" if args.recording is None else "")
    return 0


if __name__ == "__main__":
    sys.exit(main())
