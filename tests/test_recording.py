"""Session recording to MCAP (rt.recording): round trip, schemas, non-blocking hand-off, drops
under a stalled disk, crash recovery after SIGKILL, garbage refused, CSV export, CLI."""
from __future__ import annotations

import csv
import hashlib
import json
import math
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
from datetime import datetime
from pathlib import Path

import numpy as np
import pytest

from rt.components.blocks import RecorderTap
from rt.errors import InputError
from rt.recording import writer as writer_mod
from rt.recording.channels import (
    CHANNELS,
    CYCLE,
    EVENTS,
    METADATA,
    REFERENCE,
    STATE,
    WRENCH,
    log_time_ns,
)
from rt.recording.reader import (
    RecordingFileError,
    RecordingScan,
    TruncatedRecordingError,
    export_csv,
    read_recording,
    recover,
)
from rt.recording.writer import SessionRecorder
from rt.safety.events import EventLog, Reaction, SafetyEvent
from talus.cli import main as talus_main

RATE_HZ = 1000
DURATION_S = 5.0
N_ROWS = int(DURATION_S * RATE_HZ)
START_WALL_NS = 1_790_000_000_123_456_789
METADATA_IN = {"protocol_name": "ankle_sine", "protocol_version": "1.2",
               "parameters": {"amplitude_m": 0.01, "frequency_hz": 0.5},
               "patient_id": "P-7f3a", "robot_description": "talus_nominal"}


def synthetic_row(k: int) -> list[float]:
    """Row k of a deterministic 1 kHz state: t, q, qd, q_ref, tau, volts (16 floats)."""
    t = k / RATE_HZ
    row = [t]
    for j in range(5):
        row += [0.2 + 0.01 * math.sin(2 * math.pi * 0.5 * t + j), 0.001 * j - t,
                (k % 97) * 0.125 - 3.0 * j]
    return row


#: Fixed-point quanta of today's encoding (rt.recording.channels): positions and speeds in
#: µm and µm/s, forces in mN, torques in mN·m; volts are the DAC's codes (:func:`dac`).
UM, MN = 1e-6, 1e-3
#: talus.v4's quanta of the velocity and the actuator forces (rt.recording.channels:
#: V4_SPEED_QUANTUM_M_S, V4_TAU_QUANTUM_N; the ATI's: 1/16 N, 2 mN·m).
QD4, TAU4 = 1e-4, 0.1


def dac(values: list[float]) -> list[float]:
    """What ``talus.v3`` reads back for drive commands: the voltage of the PCI-1720 code the
    driver writes for each (clamped to its ±10 V range)."""
    from rt.drivers.pci1720 import code_to_volts, volts_to_code
    return [code_to_volts(volts_to_code(v)) for v in values]


def fixed(values: list[float], quantum: float) -> list[float]:
    """What a fixed-point field reads back: the nearest count of ``quantum`` as the decimal
    double (exact, not a tolerance)."""
    per = round(1 / quantum)
    return [float(np.rint(v * per)) / per for v in values]


def bound_tap(capacity: int = 65536) -> tuple[RecorderTap, list[np.ndarray]]:
    """A RecorderTap whose five inputs are bound to arrays the test fills (no graph needed)."""
    tap = RecorderTap("recorder", capacity=capacity)
    arrays = [np.zeros(3) for _ in tap.ports]
    for port, a in zip(tap.ports, arrays):
        port.data = a
    return tap, arrays


def push(tap: RecorderTap, arrays: list[np.ndarray], k: int) -> None:
    row = synthetic_row(k)
    for j, a in enumerate(arrays):
        a[:] = row[1 + 3 * j:4 + 3 * j]
    tap.update(row[0], 1.0 / RATE_HZ)


# ------------------------------------------------------------------ a 5 s session, shared

def record_session(path: Path, encoding: str = "protobuf") -> dict:
    """5 s of 1 kHz state, 1 kHz wrench, safety events through EventLog, references."""
    tap, arrays = bound_tap()
    rec = SessionRecorder(path, METADATA_IN, start_wall_ns=START_WALL_NS, encoding=encoding)
    rec.attach_state_ring(tap)
    log = EventLog(listener=rec.event)
    events_in = []
    for k in range(N_ROWS):
        push(tap, arrays, k)
        t = k / RATE_HZ
        rec.wrench(t, 1.0 + t, -2.0, 600.0 * t, 0.1, -0.2, 0.3, stale=k % 10 == 0)
        if k % 1000 == 500:
            ev = SafetyEvent(t=t, kind="warn", cause="rom_roll_max", reaction=Reaction.WARN,
                             message="roll near its limit", values={"roll_rad": 0.3 + t})
            log.append(ev)
            events_in.append(ev.as_dict())
        if k % 100 == 0:
            rec.reference(t, force=[0.0, 0.0, 100.0 * t])
        if k % 250 == 0:
            time.sleep(0.002)   # let the writer thread interleave, as with a real loop
    summary = rec.close()
    return {"path": path, "summary": summary, "events": events_in, "recorder": rec}


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """The session in today's encoding (protobuf 1 kHz channels)."""
    return record_session(tmp_path_factory.mktemp("rec") / "session.mcap")


@pytest.fixture(scope="module")
def json_session(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """The session as recordings were made before issue 16 (all JSON, every index)."""
    return record_session(tmp_path_factory.mktemp("rec") / "session_json.mcap", "json")


def test_round_trip_counts_and_exact_values(session: dict) -> None:
    s = session["summary"]
    assert s["complete"] and s["error"] is None and s["dropped_total"] == 0
    assert s["messages"][STATE] == N_ROWS and s["messages"][WRENCH] == N_ROWS
    data = read_recording(session["path"])
    assert len(data[STATE]) == N_ROWS
    for k in (0, 1, 1234, N_ROWS - 1):
        row = synthetic_row(k)
        m = data[STATE][k]
        assert m["t"] == row[0]                   # whole µs: exact
        # Fixed point: the nearest count of each field's quantum (channels.py says why each
        # quantum is below its sensor's or actuator's resolution).
        assert m["q"] == fixed(row[1:4], UM) and m["qd"] == fixed(row[4:7], QD4)
        assert m["q_ref"] == fixed(row[7:10], UM)
        assert m["tau"] == fixed(row[10:13], TAU4) and m["volts"] == dac(row[13:16])
        assert "qd_ref" not in m                  # optional, not recorded
    assert [m["t"] for m in data[STATE]] == [k / RATE_HZ for k in range(N_ROWS)]
    assert len(data[WRENCH]) == N_ROWS
    assert data[WRENCH][10] == {"t": 0.01, "fx": 1.0, "fy": -2.0, "fz": 6.0, "tx": 0.1,
                                "ty": -0.2, "tz": 0.3, "stale": True, "saturated": False}
    assert data[EVENTS] == [{**e, "values": e["values"]} for e in session["events"]]
    assert len(data[EVENTS]) == 5 and data[EVENTS][0]["reaction"] == "warn"
    assert len(data[REFERENCE]) == N_ROWS // 100
    assert data[REFERENCE][3] == {"t": 0.3, "force": [0.0, 0.0, 30.0]}
    (meta,) = data[METADATA]
    for key, value in METADATA_IN.items():
        assert meta[key] == value
    assert meta["software_version"]
    # The injected start time, whatever today's date (no test depends on the calendar).
    started = datetime.fromisoformat(meta["start_wall_time"])
    assert abs(started.timestamp() - START_WALL_NS / 1e9) <= 1e-6     # microsecond stamp


def test_log_times_are_start_wall_clock_plus_loop_time(session: dict) -> None:
    scan = RecordingScan(session["path"], topics=[STATE, METADATA])
    seen = {}
    for rec in scan:
        seen.setdefault(rec.topic, []).append(rec.log_time_ns)
    assert seen[METADATA] == [START_WALL_NS]
    assert seen[STATE][:3] == [START_WALL_NS, START_WALL_NS + 1_000_000,
                               START_WALL_NS + 2_000_000]
    assert seen[STATE][-1] == log_time_ns((N_ROWS - 1) / RATE_HZ, START_WALL_NS)


def test_sha256_is_the_finished_files(session: dict) -> None:
    s = session["summary"]
    assert s["sha256"] == hashlib.sha256(session["path"].read_bytes()).hexdigest()
    assert s["bytes"] == session["path"].stat().st_size
    assert session["recorder"].close() is s          # safe twice, same summary


def test_writer_cost_and_file_size_are_reported(session: dict) -> None:
    s = session["summary"]
    n = sum(s["messages"].values())
    # PLATFORM: ≈ 24 µs per JSON message: a figure (bench/costs.py), not a bound.
    assert s["writer_us_per_message"] > 0 and s["writer_busy_s"] > 0
    print(f"\nwriter thread: {s['writer_us_per_message']:.1f} µs/message, "
          f"{s['bytes'] / n:.1f} B/message on disk, {s['flushes']} flushes")


# ------------------------------------------------------------------ schemas

def _check_schema(schema: dict) -> None:
    """The subset of JSON Schema we use is well formed (jsonschema's check when installed)."""
    try:
        import jsonschema
    except ImportError:
        jsonschema = None
    if jsonschema is not None:
        jsonschema.Draft202012Validator.check_schema(schema)
    assert schema["type"] == "object" and isinstance(schema["properties"], dict)
    assert set(schema["required"]) <= set(schema["properties"])
    for name, sub in schema["properties"].items():
        assert sub["type"] in ("number", "string", "boolean", "array", "object"), name
        assert sub.get("description"), f"{name} has no description"
        if sub["type"] == "array":
            assert sub["items"]["type"] == "number"


_PY_TYPES = {"number": (int, float), "string": str, "boolean": bool, "array": list,
             "object": dict}


def _validate(schema: dict, msg: dict) -> None:
    try:
        import jsonschema
    except ImportError:
        jsonschema = None
    if jsonschema is not None:
        jsonschema.validate(msg, schema, cls=jsonschema.Draft202012Validator)
        return
    assert isinstance(msg, dict)
    for key in schema["required"]:
        assert key in msg, key
    for key, value in msg.items():
        sub = schema["properties"].get(key)
        if sub is None:
            continue
        assert isinstance(value, _PY_TYPES[sub["type"]]), (key, value)
        if sub["type"] == "number":
            assert not isinstance(value, bool), key
        if sub["type"] == "array":
            assert all(isinstance(v, (int, float)) for v in value), key
            assert sub.get("minItems", 0) <= len(value) <= sub.get("maxItems", 1 << 30), key


def test_schemas_are_json_schema_objects_with_units() -> None:
    for spec in CHANNELS.values():
        _check_schema(spec.schema)
    units = json.dumps(CHANNELS[STATE].schema)
    for unit in (", m", "m/s", ", N", ", V", ", s"):
        assert unit in units


def test_every_recorded_message_validates_against_its_channels_schema(session: dict) -> None:
    scan = RecordingScan(session["path"])
    counted = 0
    for i, rec in enumerate(scan):
        if rec.topic in (STATE, WRENCH) and i % 50:
            continue   # a sample of the 1 kHz channels, every rare message
        schema = scan.schema_for(rec.topic)
        assert schema == CHANNELS[rec.topic].schema
        _validate(schema, rec.payload)
        counted += 1
    assert counted > 200


def test_nan_is_written_as_null(tmp_path: Path) -> None:
    tap, arrays = bound_tap()
    with SessionRecorder(tmp_path / "nan.mcap", METADATA_IN) as rec:
        rec.attach_state_ring(tap)
        push(tap, arrays, 0)
        arrays[1][2] = float("nan")
        tap.update(0.001, 0.001)
        rec.wrench(0.0, float("nan"), 0, 0, 0, 0, 0)         # no sample yet: not written
        rec.wrench(0.001, 1.0, 0, 0, 0, 0, 0)
    data = read_recording(tmp_path / "nan.mcap")
    assert data[STATE][1]["qd"][2] is None and data[STATE][0]["qd"][2] is not None
    # The wrench schema says numbers: a wrench without a sample is counted, not written.
    assert [w["t"] for w in data[WRENCH]] == [0.001] and data[WRENCH][0]["fx"] == 1.0
    assert rec.close()["wrench_without_sample"] == 1


# ------------------------------------------------------------------ never blocking the loop

def test_enqueue_takes_every_message_up_to_capacity(tmp_path: Path) -> None:
    """Cost per enqueue (≈ 0.3-1 µs) is a figure printed by bench/costs.py; that it never
    waits for the disk is shown with a stalled disk below."""
    with SessionRecorder(tmp_path / "q.mcap", METADATA_IN, queue_capacity=100_000) as rec:
        ev = SafetyEvent(t=0.0, kind="warn", cause="x", reaction=Reaction.WARN,
                         message="m").as_dict()
        for k in range(5000):
            assert rec.wrench(k * 1e-3, 1.0, 2.0, 3.0, 0.0, 0.0, 0.0)
            assert rec.event(ev)
    s = rec.close()
    assert s["messages"][WRENCH] == 5000 and s["messages"][EVENTS] == 5000
    assert s["dropped_total"] == 0


class _StallingFile:
    """A file whose writes block while ``gate`` is clear: a disk that stopped answering."""

    def __init__(self, path: Path):
        self.raw = open(path, "wb")  # noqa: SIM115 - owned by this wrapper, closed by close()
        self.gate = threading.Event()
        self.gate.set()
        self.blocked = threading.Event()

    def write(self, data: bytes) -> int:
        if not self.gate.is_set():
            self.blocked.set()
            self.gate.wait(10)
        return self.raw.write(data)

    def flush(self) -> None:
        self.raw.flush()

    def fileno(self) -> int:
        return self.raw.fileno()

    def close(self) -> None:
        self.raw.close()


def test_stalled_disk_gives_counted_drops_not_blocking(tmp_path: Path,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    files: list[_StallingFile] = []

    def open_stalling(path: Path) -> _StallingFile:
        files.append(_StallingFile(path))
        return files[-1]

    monkeypatch.setattr(writer_mod, "_open_output", open_stalling)
    tap, arrays = bound_tap(capacity=256)
    rec = SessionRecorder(tmp_path / "stall.mcap", METADATA_IN, queue_capacity=200,
                          flush_interval_s=0.02, drain_period_s=0.005)
    rec.attach_state_ring(tap)
    (disk,) = files
    disk.gate.clear()                        # the disk stops answering
    push(tap, arrays, 0)
    assert disk.blocked.wait(5), "the writer thread never reached the disk"
    accepted, refused = 0, 0
    for k in range(1, 3001):                 # 3 s worth of 1 kHz data while stalled
        push(tap, arrays, k)
        ok = rec.event({"t": k / RATE_HZ, "kind": "warn", "cause": "c", "reaction": "warn",
                        "message": "m", "values": {}})
        accepted += ok
        refused += not ok
    assert refused > 0 and accepted <= 200
    # All 3000 were handed over while the disk was still stalled: the producer never waited
    # for it (a blocking enqueue would have hung here until the gate opened).
    assert not disk.gate.is_set() and disk.blocked.is_set()
    disk.gate.set()                          # the disk comes back
    s = rec.close()
    assert s["complete"], s["error"]
    assert s["dropped"][EVENTS] == refused
    assert s["messages"][EVENTS] == accepted
    # The 256-row ring was overrun: the lost rows are counted, the rest recorded in order.
    assert s["dropped"][STATE] > 0
    assert s["messages"][STATE] + s["dropped"][STATE] == 3001
    ts = [m["t"] for m in read_recording(tmp_path / "stall.mcap")[STATE]]
    assert ts == sorted(ts) and len(ts) == s["messages"][STATE]


class _RacingRing:
    """A ring source (t, position[3]) whose producer writes 3 rows while the first drain
    copies: the rows it may have overwritten must be dropped and counted, not recorded."""

    capacity = 8

    def __init__(self) -> None:
        self.ring = np.zeros((self.capacity, 4))
        self.written = 0
        self.race = True

    def produce(self, n: int) -> None:
        for _ in range(n):
            self.ring[self.written % self.capacity] = [self.written / RATE_HZ] + [
                float(self.written)] * 3
            self.written += 1

    def drain(self, start: int) -> tuple[np.ndarray, int]:
        end = self.written
        start = max(start, end - self.capacity)
        rows = self.ring[np.arange(start, end) % self.capacity].copy()
        if self.race:
            self.race = False
            self.produce(3)
        return rows, end


def test_generic_ring_rows_overwritten_during_the_copy_are_dropped(tmp_path: Path) -> None:
    ring = _RacingRing()
    ring.produce(8)                                   # full: rows 0..7
    with SessionRecorder(tmp_path / "ring.mcap", METADATA_IN) as rec:
        rec.attach_ring(REFERENCE, ring, (("t", 1), ("position", 3)), start=0)
        time.sleep(0.1)                               # a few drain periods
    s = rec.close()
    got = read_recording(tmp_path / "ring.mcap")[REFERENCE]
    # Rows 0..2 shared their slots with rows 8..10 written during the copy.
    assert [m["t"] for m in got] == [k / RATE_HZ for k in range(3, 11)]
    assert got[0]["position"] == [3.0, 3.0, 3.0] and "force" not in got[0]
    assert s["dropped"][REFERENCE] == 3 and s["messages"][REFERENCE] == 8


# ------------------------------------------------------------------ crash recovery

CHILD = textwrap.dedent("""
    import sys, time
    import numpy as np
    sys.path.insert(0, sys.argv[3])
    from test_recording import bound_tap, push, METADATA_IN
    from rt.recording.writer import SessionRecorder

    path, progress_path = sys.argv[1], sys.argv[2]
    progress = np.memmap(progress_path, dtype=np.int64, mode="r+", shape=(1,))
    tap, arrays = bound_tap()
    rec = SessionRecorder(path, METADATA_IN)
    rec.attach_state_ring(tap)
    t0 = time.perf_counter()
    k = 0
    while True:                     # a 1 kHz loop that only a SIGKILL ends
        wait = t0 + k / 1000 - time.perf_counter()
        if wait > 0:
            time.sleep(wait)
        push(tap, arrays, k)
        k += 1
        progress[0] = k             # rows handed to the recorder so far
""")


def _record_then_sigkill(tmp_path: Path, kill_after_rows: int) -> tuple[Path, int]:
    path, progress_path = tmp_path / "crash.mcap", tmp_path / "progress"
    np.zeros(1, np.int64).tofile(progress_path)
    child = subprocess.Popen([sys.executable, "-c", CHILD, str(path), str(progress_path),
                              str(Path(__file__).parent)])
    progress = np.memmap(progress_path, dtype=np.int64, mode="r", shape=(1,))
    try:
        deadline = time.monotonic() + 20
        while progress[0] < kill_after_rows:
            assert child.poll() is None, "the recording child died on its own"
            assert time.monotonic() < deadline, "the recording child did not start"
            time.sleep(0.001)
    finally:
        os.kill(child.pid, signal.SIGKILL)
        child.wait()
    assert child.returncode == -signal.SIGKILL
    return path, int(progress[0])


@pytest.mark.parametrize("kill_after_rows", [1400, 2150])
def test_sigkilled_recording_is_recovered_up_to_the_last_chunk(tmp_path: Path,
                                                               kill_after_rows: int) -> None:
    path, produced = _record_then_sigkill(tmp_path, kill_after_rows)
    with pytest.raises(TruncatedRecordingError, match="recover"):
        read_recording(path)
    messages, info = recover(path)
    assert not info["complete"] and info["chunks"] >= 2 and info["tail"]
    state = messages[STATE]
    n = len(state)
    # An exact prefix of what the loop produced: every row, in order, no gap, exact values.
    assert [m["t"] for m in state] == [k / RATE_HZ for k in range(n)]
    for k in (0, n // 2, n - 1):
        assert state[k]["q"] == fixed(synthetic_row(k)[1:4], UM)
        assert state[k]["volts"] == dac(synthetic_row(k)[13:16])
    assert messages[METADATA][0]["patient_id"] == METADATA_IN["patient_id"]
    loss_s = (produced - n) / RATE_HZ
    print(f"\nSIGKILL after {produced} rows: recovered {n} in {info['chunks']} chunks, "
          f"lost {loss_s * 1e3:.0f} ms ({info['tail']})")
    # What is lost is the tail only (a prefix was recovered above); how much depends on the
    # writer thread's scheduling, a figure (bench/costs.py --crash), not asserted here.
    assert n > 0 and loss_s >= 0


def test_a_file_cut_inside_a_chunk_recovers_the_chunks_before_the_cut(session: dict,
                                                                      tmp_path: Path) -> None:
    data = session["path"].read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    messages, info = recover(cut)
    assert not info["complete"] and "cut short" in info["tail"]
    n = len(messages[STATE])
    assert 0 < n < N_ROWS
    assert [m["t"] for m in messages[STATE]] == [k / RATE_HZ for k in range(n)]
    assert info["messages"][STATE] == n and info["lost_tail_bytes"] > 0


def test_complete_file_recovers_everything(session: dict) -> None:
    messages, info = recover(session["path"])
    assert info["complete"] and info["tail"] is None and info["lost_tail_bytes"] == 0
    assert len(messages[STATE]) == N_ROWS


# ------------------------------------------------------------------ garbage refused

@pytest.mark.parametrize("content, reason", [
    (b"", "empty file"),
    (os.urandom(4096), "not an MCAP recording"),
    (b"\x89MCAP0\r\n" + b"\x06" + (123).to_bytes(8, "little") + b"x" * 200,
     "first record is not a Header"),
])
def test_garbage_is_refused_with_a_clear_error(tmp_path: Path, content: bytes,
                                               reason: str) -> None:
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(content)
    for read in (read_recording, recover):
        with pytest.raises(RecordingFileError, match=reason) as err:
            read(bad)
        assert str(bad) in str(err.value) and isinstance(err.value, InputError)


# ------------------------------------------------------------------ CSV export, CLI

def test_csv_export_of_state(session: dict, tmp_path: Path) -> None:
    out = tmp_path / "state.csv"
    result = export_csv(session["path"], STATE, out)
    assert result["rows"] == N_ROWS and result["complete"]
    with open(out, newline="") as f:
        rows = list(csv.reader(f))
    header = rows[0]
    assert header[:6] == ["log_time_ns", "t", "q0", "q1", "q2", "qd0"]
    assert header[-3:] == ["volts0", "volts1", "volts2"]
    assert len(rows) == N_ROWS + 1
    col = {name: i for i, name in enumerate(header)}
    for k in (0, 777, N_ROWS - 1):
        r, expected = rows[k + 1], synthetic_row(k)
        assert float(r[col["t"]]) == expected[0]
        assert [float(r[col[f"q{i}"]]) for i in range(3)] == fixed(expected[1:4], UM)
        assert [float(r[col[f"tau{i}"]]) for i in range(3)] == fixed(expected[10:13], TAU4)
        assert r[col["qd_ref0"]] == ""           # optional field, not recorded
        assert int(r[col["log_time_ns"]]) == log_time_ns(expected[0], START_WALL_NS)


def test_csv_export_of_events_and_truncated_file(session: dict, tmp_path: Path) -> None:
    out = tmp_path / "events.csv"
    export_csv(session["path"], EVENTS, out)
    with open(out, newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 5 and rows[0]["cause"] == "rom_roll_max"
    assert json.loads(rows[0]["values"]) == session["events"][0]["values"]
    cut = tmp_path / "cut.mcap"
    blob = session["path"].read_bytes()
    # Cut inside the data (its size varies with how the writer joined the cycles' parts: a
    # part that arrives late is written alone), not at a fixed offset that may lie past it.
    cut.write_bytes(blob[: len(blob) // 2])
    result = export_csv(cut, STATE, tmp_path / "cut.csv")
    assert not result["complete"] and result["rows"] == len(recover(cut)[0][STATE])
    with pytest.raises(InputError, match="no channel"):
        export_csv(session["path"], "/nope", tmp_path / "nope.csv")
    assert not (tmp_path / "nope.csv").exists()


def test_cli_info_and_export(session: dict, tmp_path: Path,
                             capsys: pytest.CaptureFixture[str]) -> None:
    assert talus_main(["record", "info", str(session["path"])]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["complete"] and info["messages"][STATE] == N_ROWS
    assert info["duration_s"] == pytest.approx(DURATION_S - 1e-3)
    out = tmp_path / "o.csv"
    assert talus_main(["record", "export", str(session["path"]), "--channel", WRENCH,
                       "--out", str(out)]) == 0
    assert json.loads(capsys.readouterr().out)["rows"] == N_ROWS
    cut = tmp_path / "cut.mcap"
    blob = session["path"].read_bytes()
    cut.write_bytes(blob[: len(blob) // 2])           # inside the data, whatever its size
    assert talus_main(["record", "info", str(cut)]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["complete"] is False and 0 < info["messages"][STATE] < N_ROWS
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"hello, not a recording")
    assert talus_main(["record", "info", str(bad)]) == 2
    err = json.loads(capsys.readouterr().out)["error"]
    assert str(bad) in err and "not an MCAP recording" in err


# ------------------------------------------------------------------ construction, lifecycle

def test_bad_metadata_and_unknown_channels_are_refused(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="patient_id"):
        SessionRecorder(tmp_path / "m.mcap", {k: v for k, v in METADATA_IN.items()
                                              if k != "patient_id"})
    with pytest.raises(InputError, match="compression"):
        SessionRecorder(tmp_path / "m.mcap", METADATA_IN, compression="gzip")
    with (
        SessionRecorder(tmp_path / "m.mcap", METADATA_IN) as rec,
        pytest.raises(InputError, match="unknown channel"),
    ):
        rec.publish("/nope", {"t": 0.0})
    assert rec.closed and not rec.event({"t": 1.0}) and rec.close()["dropped"][EVENTS] == 0
    # (a drop after close is counted by dropped(), not in the frozen summary)
    assert rec.dropped()[EVENTS] == 1


def test_a_channel_is_added_by_one_dict_entry(tmp_path: Path) -> None:
    from rt.recording.channels import ChannelSpec
    spec = ChannelSpec("/robot/temperature", "talus.Temperature", {
        "type": "object", "required": ["t", "celsius"],
        "properties": {"t": {"type": "number", "description": "loop time, s"},
                       "celsius": {"type": "number", "description": "motor 1 temperature, °C"}}})
    with SessionRecorder(tmp_path / "x.mcap", METADATA_IN,
                         extra_channels={spec.topic: spec}) as rec:
        assert rec.publish(spec.topic, {"t": 0.5, "celsius": 41.5})
    data = read_recording(tmp_path / "x.mcap")
    assert data["/robot/temperature"] == [{"t": 0.5, "celsius": 41.5}]
    assert set(CHANNELS) < set(data)


# ------------------------------------------------------------------ damage detected, nothing lost

def _records(data: bytes) -> list[tuple[int, int, int]]:
    """(opcode, offset, body length) of every record of an MCAP file (framing only)."""
    out, offset = [], 8
    while offset + 9 <= len(data):
        opcode, length = int(data[offset]), int.from_bytes(data[offset + 1:offset + 9], "little")
        out.append((opcode, offset, length))
        offset += 9 + length
    return out


def _flip(src: Path, dst: Path, opcode: int, which: int, at: float) -> int:
    """Copy ``src`` to ``dst`` with two bytes flipped inside the ``which``-th record of
    ``opcode``, at fraction ``at`` of its body; returns the record's offset."""
    data = bytearray(src.read_bytes())
    _, offset, length = [r for r in _records(bytes(data)) if r[0] == opcode][which]
    k = offset + 9 + int(at * length)
    data[k] ^= 0xFF
    data[k + 1] ^= 0x5A
    dst.write_bytes(bytes(data))
    return offset


CHUNK, MESSAGE_INDEX, STATISTICS = 0x06, 0x07, 0x0B


def _a_middle_chunk_holding(path: Path, topic: str) -> int:
    """Index (among chunks) of a chunk holding ``topic`` messages, neither first nor last of
    them (chunk boundaries follow the writer's flush timer, so they are looked up)."""
    import io

    from mcap.data_stream import ReadDataStream
    from mcap.records import Chunk, Message
    from mcap.stream_reader import breakup_chunk

    data = path.read_bytes()
    scan = RecordingScan(path)
    for _ in scan:
        pass
    (channel_id,) = [i for i, c in scan.channels.items() if c.topic == topic]
    chunks = [(offset, length) for op, offset, length in _records(data) if op == CHUNK]
    holding = [k for k, (offset, length) in enumerate(chunks)
               if any(isinstance(r, Message) and r.channel_id == channel_id
                      for r in breakup_chunk(Chunk.read(ReadDataStream(
                          io.BytesIO(data[offset + 9:offset + 9 + length])))))]
    assert len(holding) >= 3
    return holding[len(holding) // 2]


def test_sequence_numbers_count_each_channel_from_one(session: dict) -> None:
    from mcap.reader import make_reader

    last: dict[str, int] = {}
    with open(session["path"], "rb") as f:
        for _, channel, message in make_reader(f, validate_crcs=True).iter_messages():
            assert message.sequence == last.get(channel.topic, 0) + 1
            last[channel.topic] = message.sequence
    # talus.v4: one channel, one message per cycle (the state, wrench and reference inside).
    assert last[CYCLE] == N_ROWS and STATE not in last and WRENCH not in last


def test_an_undamaged_recording_checks_every_crc(session: dict, capsys) -> None:
    assert talus_main(["record", "info", str(session["path"])]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["complete"] and not info["corrupt"] and info["data_crc_checked"]
    assert info["first_bad_chunk"] is None and info["sequence_gaps"] == {}


def test_flipped_bytes_in_a_chunk_are_reported_and_salvaged(session: dict, tmp_path: Path,
                                                           capsys) -> None:
    bad = tmp_path / "flipped.mcap"
    which = _a_middle_chunk_holding(session["path"], CYCLE)
    offset = _flip(session["path"], bad, CHUNK, which=which, at=0.5)
    assert talus_main(["record", "info", str(bad)]) == 2
    info = json.loads(capsys.readouterr().out)
    assert info["corrupt"] and info["first_bad_chunk"]["offset"] == offset
    assert info["first_bad_chunk"]["record"] == f"chunk {which}" and str(offset) in info["error"]
    # Without --salvage the export refuses and writes nothing.
    out = tmp_path / "state.csv"
    assert talus_main(["record", "export", str(bad), "--out", str(out)]) == 2
    assert f"chunk {which} at byte" in json.loads(capsys.readouterr().out)["error"]
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == [bad.name]
    # --salvage keeps every other chunk; the sequence numbers count what the bad one held.
    assert talus_main(["record", "export", str(bad), "--out", str(out), "--salvage"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["bad_chunks"][0]["offset"] == offset and len(result["bad_chunks"]) == 1
    assert 0 < result["rows"] < N_ROWS
    assert result["rows"] + result["sequence_gaps"] == N_ROWS
    with open(out, newline="") as f:
        assert len(list(csv.reader(f))) == result["rows"] + 1


@pytest.mark.parametrize("encoding, opcode, which, message", [
    # Message indexes (outside any chunk) are only in JSON recordings, made before issue 16.
    ("json", MESSAGE_INDEX, 3, "data section CRC mismatch"),
    ("protobuf", STATISTICS, 0, "summary section CRC mismatch"),        # in the summary
    ("json", STATISTICS, 0, "summary section CRC mismatch"),
])
def test_flipped_bytes_outside_chunks_are_caught_by_the_section_crcs(
        session: dict, json_session: dict, tmp_path: Path, encoding: str, opcode: int,
        which: int, message: str) -> None:
    bad = tmp_path / "flipped.mcap"
    recorded = session if encoding == "protobuf" else json_session
    _flip(recorded["path"], bad, opcode, which, at=0.7)
    assert talus_main(["record", "info", str(bad)]) == 2
    from rt.recording.reader import recording_info

    info = recording_info(bad)
    assert info["corrupt"] and message in info["problem"]
    with pytest.raises(RecordingFileError, match=message):
        export_csv(bad, STATE, tmp_path / "x.csv")
    assert not (tmp_path / "x.csv").exists()


def test_a_damaged_record_length_in_a_finished_file_is_damage_not_a_crash(
        session: dict, tmp_path: Path) -> None:
    from rt.recording.reader import recording_info

    data = bytearray(session["path"].read_bytes())
    _, offset, _ = [r for r in _records(bytes(data)) if r[0] == CHUNK][1]
    data[offset + 1 + 5] ^= 0x40            # the chunk's length field: framing breaks there
    bad = tmp_path / "length.mcap"
    bad.write_bytes(bytes(data))
    info = recording_info(bad)
    assert not info["complete"] and info["corrupt"]
    assert f"break at byte {offset}" in info["problem"]


def test_export_never_overwrites_or_eats_its_input(session: dict, tmp_path: Path,
                                                   capsys) -> None:
    rec = tmp_path / "rec.mcap"
    rec.write_bytes(session["path"].read_bytes())
    digest = hashlib.sha256(rec.read_bytes()).hexdigest()
    link = tmp_path / "link.mcap"
    link.symlink_to(rec)
    for out in (rec, link):               # the recording itself, by any name: never
        for force in ([], ["--force"]):
            assert talus_main(["record", "export", str(rec), "--out", str(out)] + force) == 2
            assert "is also an input" in json.loads(capsys.readouterr().out)["error"]
    assert hashlib.sha256(rec.read_bytes()).hexdigest() == digest
    out = tmp_path / "state.csv"
    out.write_text("precious\n")
    # An existing output: refused without --force; a mistyped channel never touches it.
    assert talus_main(["record", "export", str(rec), "--out", str(out)]) == 2
    assert "exists" in json.loads(capsys.readouterr().out)["error"]
    assert talus_main(["record", "export", str(rec), "--out", str(out), "--force",
                       "--channel", "/robot/stat"]) == 2
    assert "no channel" in json.loads(capsys.readouterr().out)["error"]
    assert out.read_text() == "precious\n"
    assert talus_main(["record", "export", str(rec), "--out", str(out), "--force"]) == 0
    assert json.loads(capsys.readouterr().out)["rows"] == N_ROWS
    assert out.read_text().startswith("log_time_ns,t,q0")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link.mcap", "rec.mcap", "state.csv"]


def test_a_recording_replaces_a_file_only_once_complete(tmp_path: Path) -> None:
    old = tmp_path / "s.mcap"
    old.write_bytes(b"previous session")
    with pytest.raises(InputError, match="exists"):
        SessionRecorder(old, METADATA_IN)
    rec = SessionRecorder(old, METADATA_IN, force=True)
    rec.wrench(0.0, 1.0, 2.0, 3.0, 0.0, 0.0, 0.0)
    assert old.read_bytes() == b"previous session"      # still there while recording
    summary = rec.close()
    assert summary["complete"] and read_recording(old)[WRENCH][0]["fz"] == 3.0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.mcap"]
    protocol = tmp_path / "p.yaml"
    protocol.write_text("kind: sine_fz\n")
    with pytest.raises(InputError, match="is also an input"):
        SessionRecorder(protocol, METADATA_IN, force=True, inputs=[protocol])
    assert protocol.read_text() == "kind: sine_fz\n"
