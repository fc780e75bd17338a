"""Clinical sessions run by the RT process (a real `talus rt serve` subprocess): pre-flight
there, recording by it, summary published; refusals; abort; the owner killed mid-session while
another client heartbeats; `talus session run` as a client with an embedded RT process."""
from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from test_rt_process import (
    LOADED_MACHINE_SLACK_S,
    TEST_HEARTBEAT_TIMEOUT_S,
    latched_event,
    start_rt,
    stop_rt,
    tolerant_config,
)

from protocols.bench_force import SINE
from protocols.library import LIBRARY_DIR
from protocols.rt_session import protocol_document
from rt.errors import InputError
from rt.ipc.client import RtClient, Subscriber
from rt.recording.reader import read_recording


def _short_sine(tmp_path: Path, cycles: int = 2) -> dict:
    path = tmp_path / "short_sine.yaml"
    path.write_text(SINE.format(f=1.0, cycles=cycles))
    return protocol_document(path)


def _wait_end(client: RtClient, sid: str, timeout_s: float = 120.0) -> dict:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        st = client.session_status()
        if st["session"] != sid:
            assert st["last_summary"]["session_id"] == sid
            return st["last_summary"]
        time.sleep(0.1)
    raise AssertionError(f"session {sid} did not end in {timeout_s} s")


@pytest.fixture()
def fast_rt(tmp_path):
    """An RT process running the twin back to back (the heartbeat timeout is widened for a
    loaded machine; the latency test below uses the real-time default)."""
    proc, endpoint, pub = start_rt("--fast", "--heartbeat-timeout", "1.0", "--recordings-dir",
                                   str(tmp_path / "recordings"))
    try:
        yield proc, endpoint, pub
    finally:
        stop_rt(proc)


def test_session_round_trip_recorded_by_the_rt_process(fast_rt, tmp_path):
    proc, endpoint, pub = fast_rt
    sub = Subscriber(pub, ["event", "telemetry"])
    doc = _short_sine(tmp_path)
    with RtClient(endpoint, timeout_s=2.0) as client:
        client.control_acquire("test")
        client.start_heartbeat(0.05)
        t0 = time.monotonic()
        started = client.session_start(doc, {"id": "P-007", "weight_kg": 70.0})
        start_latency = time.monotonic() - t0
        sid = started["session_id"]
        assert started["protocol"] == doc["name"] and started["preflight"]["duration_s"] > 5.0
        rec = Path(started["recording"])
        assert rec.parent == tmp_path / "recordings" and rec.suffix == ".mcap"
        assert "P-007" in rec.name
        st = client.session_status()
        assert st["session"] == sid and st["state"] == "running"
        s = _wait_end(client, sid)
    print(f"\nsession_start round trip (pre-flight of a {started['duration_s']:.1f} s protocol "
          f"on the twin): {start_latency:.2f} s")
    assert s["outcome"] == "completed" and s["stops"] == [] and s["completed"]
    assert s["rms_error_pct"] <= 3.0 and 350.0 <= s["peak_force_n"] <= 420.0
    assert s["rt"]["pid"] == proc.pid and s["patient_id"] == "P-007"
    assert s["recording"]["path"] == str(rec)
    assert s["recording"]["sha256"] == hashlib.sha256(rec.read_bytes()).hexdigest()
    meta = read_recording(rec, ["/protocol/metadata"])["/protocol/metadata"][0]
    assert meta["rt"]["pid"] == proc.pid and meta["patient_id"] == "P-007"
    assert meta["session_id"] == sid and meta["limits"]["max_force_n"] == 800.0
    # The approach (from rest at q = 0.2 m to the protocol's start, ~4 mm lower) runs before
    # the twin's patient foot is strapped: it loads nothing. Placed at the start pose while the
    # platform still stood at rest, the foot's heel pad (1e5 N/m) pressed ~360 N here.
    got_rows = read_recording(rec, ["/robot/wrench", "/protocol/reference"])
    approach = {round(r["t"], 6) for r in got_rows["/protocol/reference"]
                if r["phase"] == "approach"}
    fz_approach = [w["fz"] for w in got_rows["/robot/wrench"] if round(w["t"], 6) in approach]
    assert len(fz_approach) > 50
    assert max(abs(f) for f in fz_approach) < 30.0
    # The published end event carries the same summary; telemetry flowed meanwhile.
    got = {"telemetry": 0, "end": None}
    end = time.monotonic() + 5.0
    while time.monotonic() < end and got["end"] is None:
        msg = sub.recv(0.2)
        if msg is None:
            continue
        if msg["topic"] == "telemetry":
            got["telemetry"] += 1
        elif msg.get("kind") == "session_end":
            got["end"] = msg
    sub.close()
    assert got["end"] is not None and got["end"]["summary"]["session_id"] == sid
    assert got["telemetry"] > 10


def test_two_sessions_never_share_a_recording(fast_rt, tmp_path):
    _, endpoint, _ = fast_rt
    doc = _short_sine(tmp_path, cycles=1)
    paths = []
    with RtClient(endpoint, timeout_s=2.0) as client:
        client.control_acquire("test")
        client.start_heartbeat(0.05)
        for _ in range(2):
            started = client.session_start(doc, {"id": "P-1"}, {"dir": str(tmp_path)})
            _wait_end(client, started["session_id"])
            paths.append(Path(started["recording"]))
    assert paths[0] != paths[1] and all(p.parent == tmp_path and p.exists() for p in paths)


def test_session_refusals_name_the_reason_and_record_nothing(fast_rt, tmp_path):
    _, endpoint, _ = fast_rt
    with RtClient(endpoint, timeout_s=2.0) as client:
        client.control_acquire("test")
        client.start_heartbeat(0.05)
        rom = protocol_document(LIBRARY_DIR / "ankle_rom.yaml")
        narrow = {"roll_min_deg": -2.0, "roll_max_deg": 2.0, "pitch_min_deg": -2.0,
                  "pitch_max_deg": 2.0}
        with pytest.raises(InputError, match="refused by pre-flight.*ROM"):
            client.session_start(rom, {"id": "P-1", "limits": narrow}, {"dir": str(tmp_path)})
        with pytest.raises(InputError, match="mean_n"):
            client.session_start({**_short_sine(tmp_path), "mean_n": -5.0}, {"id": "P-1"},
                                 {"dir": str(tmp_path)})
        with pytest.raises(InputError, match="bad patient limits.*max_force_n"):
            client.session_start(rom, {"id": "P-1", "limits": {"max_force_n": -1.0}})
        with pytest.raises(InputError, match="does not exist"):
            client.session_start(rom, {"id": "P-1"}, {"dir": str(tmp_path / "nope")})
        with pytest.raises(InputError, match="id"):
            client.session_start(rom, {"id": "Núñez Gómez"})    # a code, never a name
        assert not list(tmp_path.glob("*.mcap"))
        assert client.session_status()["session"] is None
    # The pre-flight alone, for a GUI before Start: anyone may ask, nothing moves.
    with RtClient(endpoint, timeout_s=2.0) as viewer:
        pre = viewer.session_preflight(_short_sine(tmp_path), {"id": "P-1"})
        assert pre["ok"] and 350.0 < pre["predicted"]["peak_platform_force_n"] < 420.0
        with pytest.raises(InputError, match="refused by pre-flight.*ROM"):
            viewer.session_preflight(rom, {"id": "P-1", "limits": narrow})
        assert viewer.status()["phase_name"] == "rest"


def test_start_reuses_the_passing_preflight_and_the_recording_says_which(fast_rt, tmp_path):
    """The GUI's flow: pre-flight on the Prescribe page (before taking control), take control,
    Start with the clinical record's snapshot of the same patient: the start runs on that
    pre-flight (no second one), the reply and the recording's metadata name it. A stop between
    a pre-flight and the start makes the start pre-flight again and say why
    (tests/test_preflight_reuse.py tests every invalidation on its own)."""
    from rt.safety.limits import PatientLimits

    _, endpoint, _ = fast_rt
    doc = _short_sine(tmp_path, cycles=1)
    patient = {"id": "P-1", "weight_kg": 70.0}
    with RtClient(endpoint, timeout_s=2.0) as client:
        pre = client.session_preflight(doc, patient)
        assert pre["ok"] and pre["kept_for_s"] > 0
        client.control_acquire("gui")
        client.start_heartbeat(0.05)
        record = {**patient, "limits": PatientLimits().model_dump()}
        started = client.session_start(doc, record, {"dir": str(tmp_path)})
        assert started["preflight_reused"] is True, started["preflight_not_reused"]
        assert started["preflight_id"] == pre["preflight_id"]
        assert started["preflight"] == pre["predicted"]
        s = _wait_end(client, started["session_id"])
        assert s["outcome"] == "completed" and s["preflight_run"]["id"] == pre["preflight_id"]
        meta = read_recording(Path(started["recording"]),
                              ["/protocol/metadata"])["/protocol/metadata"][0]
        run = meta["preflight_run"]
        assert run["id"] == pre["preflight_id"] and run["reused"] is True
        assert run["not_reused"] is None and 0.0 <= run["age_s"] < 120.0
        assert set(run["key"]) == {"protocol", "patient", "robot", "start"}

        pre2 = client.session_preflight(doc, patient)
        client.stop()
        end = time.monotonic() + 10.0
        while not client.status()["latched"] and time.monotonic() < end:
            time.sleep(0.02)
        client.reset()
        started2 = client.session_start(doc, patient, {"dir": str(tmp_path)})
        assert started2["preflight_reused"] is False
        assert "a fault (stop_client) happened since pre-flight " + pre2["preflight_id"] in \
            started2["preflight_not_reused"]
        assert started2["preflight_id"] not in (pre["preflight_id"], pre2["preflight_id"])
        _wait_end(client, started2["session_id"])


def test_session_abort_returns_to_rest(fast_rt, tmp_path):
    _, endpoint, _ = fast_rt
    with RtClient(endpoint, timeout_s=2.0) as client, \
            RtClient(endpoint, timeout_s=2.0) as other:
        client.control_acquire("test")
        client.start_heartbeat(0.05)
        started = client.session_start(_short_sine(tmp_path, cycles=20), {"id": "P-1"},
                                       {"dir": str(tmp_path)})
        sid = started["session_id"]
        assert _wait_for_phase(client, "play")
        assert other.session_abort()["aborted"] == sid           # anyone may stop a session
        s = _wait_end(client, sid)
        assert s["outcome"] == "aborted" and s["stops"] == [] and not s["completed"]
        st = client.status()
        assert st["state"] == "run" and st["phase_name"] == "rest"
        with pytest.raises(InputError, match="no session is running"):
            client.session_abort()


def _wait_for_phase(client: RtClient, phase: str, timeout_s: float = 60.0) -> bool:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if client.session_status().get("phase") == phase:
            return True
        time.sleep(0.05)
    return False


def test_owner_killed_mid_session_soft_stops_although_another_client_heartbeats(tmp_path):
    """The owner's heartbeat is the one that counts: an observer that keeps heartbeating does
    not keep a session going whose owner died (SIGKILL)."""
    proc, endpoint, _pub = start_rt("--recordings-dir", str(tmp_path), "--config",
                                   tolerant_config(tmp_path))
    doc = _short_sine(tmp_path, cycles=30)
    script = textwrap.dedent(f"""
        import json, sys, time
        from rt.ipc.client import RtClient
        c = RtClient({endpoint!r}, client_id="doomed-owner", timeout_s=120.0)
        c.control_acquire("owner about to be killed")
        c.start_heartbeat(0.05)
        r = c.session_start(json.loads(sys.stdin.readline()), {{"id": "P-9"}})
        print(r["session_id"], flush=True)
        time.sleep(300)
    """)
    child = subprocess.Popen([sys.executable, "-c", script], stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE, text=True)
    try:
        child.stdin.write(json.dumps(doc) + "\n")
        child.stdin.flush()
        sid = child.stdout.readline().strip()
        with RtClient(endpoint, client_id="observer", timeout_s=2.0) as observer:
            observer.start_heartbeat(0.05)
            assert _wait_for_phase(observer, "play")
            time.sleep(0.5)
            killed_at = time.time()
            os.kill(child.pid, signal.SIGKILL)
            child.wait()
            event = latched_event(endpoint, "heartbeat_lost")
            assert event is not None and event["reaction"] == "soft_stop"
            latency = event["wall"] - killed_at
            print(f"\nsession owner killed → soft stop: {latency * 1e3:.0f} ms (timeout "
                  f"{TEST_HEARTBEAT_TIMEOUT_S * 1e3:.0f} ms)")
            assert TEST_HEARTBEAT_TIMEOUT_S - 0.06 <= latency <= TEST_HEARTBEAT_TIMEOUT_S + \
                LOADED_MACHINE_SLACK_S
            s = _wait_end(observer, sid, timeout_s=30.0)
            assert s["outcome"] == "stopped"
            assert [x["cause"] for x in s["stops"]] == ["heartbeat_lost"]
            assert Path(s["recording"]["path"]).exists()
    finally:
        if child.poll() is None:
            child.kill()
        stop_rt(proc)


def test_session_cli_is_a_client_of_an_embedded_rt_process(tmp_path):
    out = tmp_path / "recordings"
    out.mkdir()
    proc = subprocess.run([sys.executable, "-m", "talus", "session", "run", "--protocol",
                           str(LIBRARY_DIR / "gait_replay.yaml"), "--patient-weight", "75",
                           "--record-dir", str(out), "--fast", "--json",
                           "--endpoint", "tcp://127.0.0.1:9"],   # nobody there: embedded
                          check=False, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    s = json.loads(proc.stdout)
    assert s["outcome"] == "completed" and s["rms_error_pct"] <= 3.0
    rec = Path(s["recording"]["path"])
    assert rec.parent == out and rec.exists()
    meta = read_recording(rec, ["/protocol/metadata"])["/protocol/metadata"][0]
    assert meta["rt"]["pid"] == s["rt"]["pid"] != os.getpid()
    assert meta["data_file"]["sha256"] and meta["patient_id"] == "twin-demo"


def test_rt_process_stopped_mid_session_closes_a_complete_recording(tmp_path):
    proc, endpoint, _ = start_rt("--fast", "--heartbeat-timeout", "1.0")
    try:
        with RtClient(endpoint, timeout_s=2.0) as client:
            client.control_acquire("test")
            client.start_heartbeat(0.05)
            started = client.session_start(_short_sine(tmp_path, cycles=30), {"id": "P-2"},
                                           {"dir": str(tmp_path)})
            assert _wait_for_phase(client, "play")
            proc.send_signal(signal.SIGTERM)                 # the owner is still there
            assert proc.wait(timeout=30) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
    rec = read_recording(Path(started["recording"]), ["/session/summary"])
    [last] = rec["/session/summary"]
    assert last["summary"]["outcome"] == "aborted"
    assert "shutting down" in last["summary"]["aborted_by"]


def test_the_preflight_worker_ends_when_its_rt_process_is_killed(tmp_path):
    """A SIGKILLed RT process cannot shut its pre-flight pool down: the spawned worker must
    notice and end by itself, not live on as an orphan holding a robot model."""
    script = textwrap.dedent("""
        import sys, time
        from protocols.rt_session import ProtocolSessions
        from rt.model.description import load_description
        sessions = ProtocolSessions()
        sessions.warm(load_description())
        pool = sessions._worker()
        while not pool._processes:
            time.sleep(0.01)
        print(next(iter(pool._processes)), flush=True)
        time.sleep(600)
    """)
    owner = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True,
                             cwd=Path(__file__).resolve().parents[1])
    try:
        assert owner.stdout is not None                       # stdout=PIPE
        worker_pid = int(owner.stdout.readline())
        os.kill(worker_pid, 0)                                # the worker is alive
    finally:
        owner.kill()
        owner.wait()
    # The worker polls its parent every 0.5 s; the bound is for a loaded machine.
    end = time.monotonic() + 30.0
    while time.monotonic() < end:
        try:
            os.kill(worker_pid, 0)
        except ProcessLookupError:
            return
        time.sleep(0.1)
    os.kill(worker_pid, signal.SIGKILL)
    raise AssertionError(f"pre-flight worker {worker_pid} outlived its killed RT process")


def _fifo_permitted() -> bool:
    code = "import os; os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))"
    probe = subprocess.run([sys.executable, "-c", code], capture_output=True, check=False)
    return probe.returncode == 0


def test_rt_process_threads_run_above_ordinary_processes_and_its_worker_below(tmp_path):
    """Every thread of the RT process shares the GIL with the loop: the loop is SCHED_FIFO 80,
    the others SCHED_FIFO 1 (a GIL holder is never descheduled for an ordinary process, which
    would make the loop wait, rt_hygiene.gil_peer); the pre-flight worker it spawned is an
    ordinary process at WORKER_NICE (its initializer resets what it inherited)."""
    if not _fifo_permitted():
        pytest.skip("SCHED_FIFO not permitted here")
    from protocols.rt_session import WORKER_NICE

    reset = getattr(os, "SCHED_RESET_ON_FORK", 0)
    config = tolerant_config(tmp_path)
    with open(config, "a") as f:
        f.write("service_priority: 1\n")
    proc, endpoint, _pub = start_rt("--config", config)
    try:
        with RtClient(endpoint, timeout_s=5.0) as c:
            assert c.status()["cycles"] > 0
        policies = {}
        for tid in map(int, os.listdir(f"/proc/{proc.pid}/task")):
            try:
                policies[tid] = (os.sched_getscheduler(tid) & ~reset,
                                 os.sched_getparam(tid).sched_priority)
            except ProcessLookupError:
                continue                       # a thread that ended meanwhile
        assert sorted(policies.values()).count((os.SCHED_FIFO, 80)) == 1   # the loop
        assert policies[proc.pid] == (os.SCHED_FIFO, 1)                     # main: telemetry
        fifo1 = [t for t, p in policies.items() if p == (os.SCHED_FIFO, 1)]
        assert len(fifo1) >= 2          # main, IPC server (and ZeroMQ's, the pool's ...)
        children: list[int] = []
        end = time.monotonic() + 60.0
        while time.monotonic() < end:
            children = []
            for tid in os.listdir(f"/proc/{proc.pid}/task"):
                try:
                    with open(f"/proc/{proc.pid}/task/{tid}/children") as f:
                        children += [int(x) for x in f.read().split()]
                    # The pool's worker (multiprocessing's resource tracker, a child too,
                    # sleeps: it keeps what it inherited).
                    children = [ch for ch in children
                                if b"spawn_main" in Path(f"/proc/{ch}/cmdline").read_bytes()]
                except FileNotFoundError:
                    continue
            # The worker starts with what it inherited; its initializer resets it.
            if children and all(os.getpriority(os.PRIO_PROCESS, ch) == WORKER_NICE
                                and os.sched_getscheduler(ch) & ~reset == os.SCHED_OTHER
                                for ch in children):
                break
            time.sleep(0.1)
        assert children, "no pre-flight worker"
        for ch in children:
            assert os.sched_getscheduler(ch) & ~reset == os.SCHED_OTHER
            assert os.getpriority(os.PRIO_PROCESS, ch) == WORKER_NICE
    finally:
        stop_rt(proc)
