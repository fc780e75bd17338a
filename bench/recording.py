"""The recorder's encodings side by side: encoding cost per message, bytes per message, MB/h.

Run:  .venv/bin/python bench/recording.py [--seconds 10] [--from RECORDING.mcap]
          [--encodings json,protobuf-f32,protobuf-v2,protobuf-v3,protobuf] [--per-channel]
          [--flush-interval 0.25,1]

The stream is either a recording's own 1 kHz channels (``--from``: e.g. a twin session's file,
read back and re-recorded) or the session-like generated stream of the tests
(``tests/test_recording_encoding.session_signals``: encoder-quantized positions, noisy velocity,
forces with noise). The stream is recorded as the RT process records a session: the state
from a ring drained by the writer, the wrench and the reference queued as blocks of 50 rows
(the session pump's 50 ms), with the source's own stale/saturated flags, phases and modes.
For each encoding (``json``: recordings before issue 16; ``protobuf-f32``: float32 protobuf,
issue 16's first round; ``protobuf-v2``: fixed point with ``t_us``, 25 November 2026;
``protobuf-v3``: ``talus.v3``, no time in the payloads, volts as DAC codes; ``protobuf``:
today's ``talus.v4``, one message per cycle, the instruments' quanta) it prints one JSON line:

* ``encode_us`` — the encoding cost per message, median and p99, as the recorder pays it:
  state, one drained block of 20 ring rows (the 20 ms drain period at 1 kHz) divided by its
  rows; wrench, the same for protobuf (the writer encodes a pump's queued samples as one
  block) and one message at a time for JSON; reference, one message (protobuf: in
  ``publish()``, the producer's thread; JSON: in the writer thread); for v4 also ``cycle``:
  joining a drained block's three parts by cycle time and assembling each cycle's message
  (``rt.recording.cycle``), per cycle;
* ``writer_cpu_us_per_message`` — the recorder thread's whole CPU per message (encoding,
  mcap records, compression, writing) from ``SessionRecorder.close()``;
* ``bytes_per_message`` (per MCAP message: per cycle for v4, per channel message before) and
  ``mb_per_hour`` of the finished file, extrapolated from the stream's duration, and
  ``mb_per_hour_at_1khz``: bytes per cycle × 3.6 million cycles (a loop that missed cycles
  made fewer per second than 1000: this is the figure of an hour at a true 1 kHz);
* with ``--per-channel``, ``mb_per_hour_by_channel``: each 1 kHz channel recorded alone, less
  a recording of nothing (the metadata), so the three add up to the file's data;
* with ``--flush-interval``, the same per flush interval (the writer closes a chunk at each
  flush: the crash-loss window against zstd's context).

Wall-clock figures: ±30 % run to run on these shared VMs.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

# This file is bench/recording.py: its folder must not shadow packages; tests/ holds the
# generated stream shared with the tests.
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).parent.resolve()]
sys.path.append(str(Path(__file__).resolve().parent.parent / "tests"))

META = {"protocol_name": "bench", "protocol_version": "1", "parameters": {},
        "patient_id": "bench", "robot_description": "talus_nominal"}


def _stream_from(path: Path) -> dict[str, Any]:
    """A recording's state, wrench and reference as the generated stream's arrays, with the
    wrench's flags and the reference's phase and mode."""
    from rt.recording.channels import REFERENCE, STATE, WRENCH
    from rt.recording.reader import read_recording

    data = read_recording(path, topics=[STATE, WRENCH, REFERENCE])

    def num(x: Any) -> float:
        return float("nan") if x is None else float(x)
    state = np.array([[m["t"], *m["q"], *m["qd"], *m["q_ref"], *m["tau"], *m["volts"]]
                      for m in data[STATE]], dtype=float)
    n = min(len(state), len(data[WRENCH]), len(data[REFERENCE]))
    wrench = np.array([[m["t"], *(num(m[k]) for k in ("fx", "fy", "fz", "tx", "ty", "tz"))]
                       for m in data[WRENCH][:n]], dtype=float)
    flags = np.array([[m["stale"], m["saturated"]] for m in data[WRENCH][:n]], dtype=float)
    refs = data[REFERENCE][:n]
    fz_ref = np.array([num((m.get("force") or [0.0, 0.0, 0.0])[2]) for m in refs])
    return {"state": state[:n], "wrench": wrench, "fz_ref": fz_ref, "flags": flags,
            "phase": [m.get("phase", "") for m in refs], "mode": [m.get("mode", "") for m in refs]}


class _Ring:
    """The state ring: rows made available as the loop writes them."""

    def __init__(self, rows: np.ndarray):
        self.rows = rows
        self.written = 0

    def drain(self, start: int) -> tuple[np.ndarray, int]:
        end = self.written
        return self.rows[start:end].copy(), end


#: Rows per block the session pump hands to the recorder (its 50 ms at 1 kHz).
PUMP_BLOCK = 50


def record_like_a_session(path: Path, sig: dict[str, Any], encoding: str,
                          channels: tuple[str, ...] = ("state", "wrench", "reference"),
                          flush_interval_s: float | None = None) -> dict[str, Any]:
    """Record ``sig`` as ``rt.service``'s session does (ring + ``wrench_rows`` +
    ``reference_rows``), only ``channels``; the recorder's summary."""
    from rt.recording.writer import DEFAULT_FLUSH_INTERVAL_S, SessionRecorder

    n = len(sig["state"])
    flags = sig.get("flags")
    flags = np.zeros((n, 2)) if flags is None else flags
    phase = sig.get("phase") or ["play"] * n
    mode = sig.get("mode") or ["force"] * n
    ring = _Ring(sig["state"])
    rec = SessionRecorder(path, META, encoding=encoding, loop_t0=float(sig["state"][0, 0]),
                          flush_interval_s=flush_interval_s or DEFAULT_FLUSH_INTERVAL_S)
    if "state" in channels:
        rec.attach_state_ring(ring, start=0)
    force = np.zeros((n, 3))
    force[:, 2] = sig["fz_ref"]
    for k0 in range(0, n, PUMP_BLOCK):
        k1 = min(n, k0 + PUMP_BLOCK)
        if "wrench" in channels:
            rec.wrench_rows(np.column_stack([sig["wrench"][k0:k1], flags[k0:k1]]))
        if "reference" in channels:
            rec.reference_rows(sig["state"][k0:k1, 0], force[k0:k1], phase[k0:k1],
                               mode[k0:k1])
        ring.written = k1
        if not rec.wait_for_room(0.01, timeout_s=30.0):
            raise RuntimeError("the recorder did not keep up")
    summary = rec.close()
    if not summary["complete"] or summary["dropped_total"]:
        raise RuntimeError(f"recording incomplete: {summary}")
    return summary


def _percentiles(us: list[float]) -> dict[str, float]:
    a = np.array(us)
    return {"median": round(float(np.median(a)), 3), "p99": round(float(np.percentile(a, 99)), 3)}


def encode_costs(encoding: str, sig: dict[str, np.ndarray]) -> dict[str, dict[str, float]]:
    """µs per message of the writer thread's encoding step, per channel."""
    from rt.recording.channels import PROTOS, REFERENCE, STATE, WRENCH, Encoding
    from rt.recording.writer import STATE_LAYOUT, encode_json

    protos = PROTOS[Encoding(encoding)]
    state, wrench, fz_ref = sig["state"], sig["wrench"], sig["fz_ref"]
    encode_rows: Callable[[np.ndarray], list[bytes]] = (
        STATE_LAYOUT.encode if encoding == "json"
        else protos[STATE].row_encoder(STATE_LAYOUT.fields))
    block = 20
    out: dict[str, list[float]] = {"state": [], "wrench": [], "reference": []}
    for k in range(0, len(state) - block, block):
        rows = state[k:k + block]
        t0 = time.perf_counter_ns()
        encode_rows(rows)
        out["state"].append((time.perf_counter_ns() - t0) / 1e3 / block)
    one = encode_json if encoding == "json" else None
    if one is None:
        wrench_rows = protos[WRENCH].row_encoder([(n, 1) for n in (
            "t", "fx", "fy", "fz", "tx", "ty", "tz", "stale", "saturated")])
        for k in range(0, len(wrench) - block, block):
            queued = [(float(w[0]), *map(float, w[1:]), False, False)
                      for w in wrench[k:k + block]]
            t0 = time.perf_counter_ns()
            rows = np.array(queued, dtype=float)       # what the writer does with the queue
            wrench_rows(rows[np.isfinite(rows[:, 1:7]).all(axis=1)])
            out["wrench"].append((time.perf_counter_ns() - t0) / 1e3 / block)
    for k in range(len(wrench)):
        w = wrench[k].tolist()
        msg = {"t": w[0], "fx": w[1], "fy": w[2], "fz": w[3], "tx": w[4], "ty": w[5],
               "tz": w[6], "stale": False, "saturated": False}
        ref = {"t": w[0], "force": [0.0, 0.0, float(fz_ref[k])], "phase": "play",
               "mode": "force"}
        t0 = time.perf_counter_ns()
        if one is not None:
            one(msg)
        t1 = time.perf_counter_ns()
        (one or protos[REFERENCE].encode)(ref)
        t2 = time.perf_counter_ns()
        if one is not None:
            out["wrench"].append((t1 - t0) / 1e3)
        out["reference"].append((t2 - t1) / 1e3)
    if encoding == "protobuf":
        out["cycle"] = _cycle_costs(sig, block)
    return {k: _percentiles(v) for k, v in out.items()}


def _cycle_costs(sig: dict[str, Any], block: int) -> list[float]:
    """µs per cycle of v4's join: a block's encoded parts into the joiner, the ready cycles
    out, each cycle's message assembled (what the writer adds to v3's per-part encoding)."""
    from rt.recording.channels import PROTOS, REFERENCE, STATE, WRENCH, Encoding
    from rt.recording.cycle import CYCLE_V4, CycleJoiner
    from rt.recording.writer import STATE_LAYOUT

    protos = PROTOS[Encoding.PROTOBUF]
    state = protos[STATE].row_encoder(STATE_LAYOUT.fields)
    wrench = protos[WRENCH].row_encoder([(n, 1) for n in (
        "t", "fx", "fy", "fz", "tx", "ty", "tz", "stale", "saturated")])
    ref = protos[REFERENCE].row_encoder([("t", 1), ("force", 3)])
    suffix = protos[REFERENCE].encode_strings({"phase": "play", "mode": "force"})
    n = len(sig["state"])
    flags = np.zeros((n, 2))
    force = np.zeros((n, 3))
    force[:, 2] = sig["fz_ref"]
    wrench_rows = np.column_stack([sig["wrench"], flags])
    ref_rows = np.column_stack([sig["state"][:, 0], force])
    joiner = CycleJoiner(3)
    out = []
    for k in range(0, n - block, block):
        parts = (state(sig["state"][k:k + block]), wrench(wrench_rows[k:k + block]),
                 [r + suffix for r in ref(ref_rows[k:k + block])])
        keys = np.rint(sig["state"][k:k + block, 0] * 1e6).astype(np.int64).tolist()
        ts = sig["state"][k:k + block, 0].tolist()
        t0 = time.perf_counter_ns()
        for p, encoded in enumerate(parts):
            for key, t, data in zip(keys, ts, encoded):
                joiner.add(p, key, t, data)
        for _, cycle_parts in joiner.ready():
            CYCLE_V4.encode(cycle_parts)
        out.append((time.perf_counter_ns() - t0) / 1e3 / block)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=10.0,
                    help="length of the generated stream (s, default %(default)s)")
    ap.add_argument("--from", dest="source", type=Path, default=None,
                    help="take the stream from this recording instead of generating it")
    ap.add_argument("--encodings", default="json,protobuf-f32,protobuf-v2,protobuf-v3,protobuf")
    ap.add_argument("--per-channel", action="store_true",
                    help="also each 1 kHz channel's share (MB/h)")
    ap.add_argument("--flush-interval", default="",
                    help="comma-separated flush intervals (s) to compare (default: the "
                         "writer's)")
    args = ap.parse_args()
    if args.seconds <= 0:
        ap.error("--seconds must be positive")
    from test_recording_encoding import session_signals

    if args.source is not None:
        sig, source = _stream_from(args.source), str(args.source)
    else:
        sig, source = session_signals(args.seconds), f"generated {args.seconds:g} s"
    duration = float(sig["state"][-1, 0] - sig["state"][0, 0]) + 1e-3
    tmp = Path(tempfile.mkdtemp(prefix="talus-bench-recording-"))
    flushes = [float(x) for x in args.flush_interval.split(",") if x] or [None]

    def mb_h(nbytes: int) -> float:
        return round(nbytes / duration * 3600 / 1e6, 1)
    for flush in flushes:
        for encoding in args.encodings.split(","):
            tag = f"{encoding}-{flush}"
            summary = record_like_a_session(tmp / f"{tag}.mcap", sig, encoding,
                                            flush_interval_s=flush)
            n = summary["mcap_messages"]
            cycles = len(sig["state"])
            line: dict[str, Any] = {
                "encoding": encoding, "source": source, "seconds": round(duration, 3),
                "cycles": cycles, "flush_interval_s": flush, "messages": n,
                "encode_us": encode_costs(encoding, sig),
                "writer_cpu_us_per_message": round(summary["writer_us_per_message"], 2),
                "writer_cpu_us_per_cycle": round(1e6 * summary["writer_busy_s"] / cycles, 2),
                "bytes_per_message": round(summary["bytes"] / n, 2),
                "mb_per_hour": mb_h(summary["bytes"]),
                "mb_per_hour_at_1khz": round(summary["bytes"] / cycles * 3.6e6 / 1e6, 1)}
            if args.per_channel:
                empty = record_like_a_session(tmp / f"{tag}-none.mcap", sig, encoding, (),
                                              flush)["bytes"]
                line["mb_per_hour_by_channel"] = {
                    ch: mb_h(record_like_a_session(tmp / f"{tag}-{ch}.mcap", sig, encoding,
                                                   (ch,), flush)["bytes"] - empty)
                    for ch in ("state", "wrench", "reference")}
            print(json.dumps(line), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
