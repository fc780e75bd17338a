"""RDT codec, twin RDT server and UDP client over real loopback sockets, and the CLI."""
from __future__ import annotations

import json
import math
import os
import selectors
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rt.ati import rdt
from rt.ati.rdt import (
    CMD_SET_SOFTWARE_BIAS,
    CMD_START_BUFFERED,
    CMD_START_REALTIME,
    CMD_STOP,
    RECORD_SIZE,
    STATUS_ANY_ERROR,
    STATUS_FT_OUT_OF_RANGE,
    CountsPerUnit,
    RdtRecord,
)
from rt.ati.rdt_client import RdtForceTorqueSensor
from rt.ati.rdt_server import RdtServer
from rt.ati.twin_sensor import AtiSensorParams, TwinAtiSensorModel
from rt.devices.interfaces import Wrench
from rt.errors import HardwareError, InputError, ProtocolError

REPO = Path(__file__).resolve().parents[1]
LOAD = (10.0, -20.0, -50.0, 1.0, -2.0, 3.0)
# Default scale is 1e6 counts per N and per N m: one count is 1e-6, so a value survives the
# round trip to within half a count (plus float rounding); 1e-6 is a safe bound.
QUANTUM = 1e-6

uint32 = st.integers(0, 2**32 - 1)
int32 = st.integers(-(2**31), 2**31 - 1)


@pytest.fixture(autouse=True)
def no_leftover_threads():
    yield
    deadline = time.monotonic() + 2.0
    while time.monotonic() < deadline:
        alive = [t.name for t in threading.enumerate() if t.name.startswith(("rdt-", "ati-"))]
        if not alive:
            return
        time.sleep(0.01)
    pytest.fail(f"threads left running: {alive}")


def wait_until(pred: Callable[[], bool], timeout: float = 30.0) -> bool:
    """Poll ``pred`` until true; the timeout only guards against a hang."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return True
        time.sleep(0.002)
    return pred()


def constant(wrench=LOAD, status=0):
    return lambda: (wrench, status)


# ==================================================================== codec
def test_request_bytes_match_the_manual_layout():
    assert rdt.encode_request(CMD_START_REALTIME) == bytes.fromhex("1234 0002 00000000")
    assert rdt.encode_request(CMD_START_BUFFERED, 10) == bytes.fromhex("1234 0003 0000000a")
    assert rdt.encode_request(CMD_SET_SOFTWARE_BIAS) == bytes.fromhex("1234 0042 00000000")
    assert rdt.encode_request(CMD_STOP) == bytes.fromhex("1234 0000 00000000")


def test_record_bytes_match_the_manual_layout():
    data = rdt.encode_record(1, 2, 0x80000000, (1, -1, 3, 4, 5, 6))
    assert len(data) == RECORD_SIZE == 36
    assert data[:12] == bytes.fromhex("00000001 00000002 80000000")
    assert data[12:20] == bytes.fromhex("00000001 ffffffff")  # int32 big-endian, two's complement


@settings(derandomize=True, max_examples=200, deadline=None)
@given(command=st.sampled_from(sorted(rdt.COMMANDS)), count=uint32)
def test_request_round_trip(command, count):
    assert rdt.decode_request(rdt.encode_request(command, count)) == (command, count)


@settings(derandomize=True, max_examples=200, deadline=None)
@given(records=st.lists(st.builds(RdtRecord, uint32, uint32, uint32,
                                  st.tuples(int32, int32, int32, int32, int32, int32)),
                        min_size=1, max_size=40))
def test_record_and_datagram_round_trip(records):
    data = rdt.encode_datagram(records)
    assert len(data) == RECORD_SIZE * len(records)
    assert rdt.decode_datagram(data) == records
    assert rdt.decode_record(data, RECORD_SIZE * (len(records) - 1)) == records[-1]


@settings(derandomize=True, max_examples=200, deadline=None)
@given(n=st.integers(0, 400).filter(lambda n: n % RECORD_SIZE != 0 or n == 0))
def test_datagrams_of_wrong_length_are_refused(n):
    with pytest.raises(ProtocolError, match=f"wrong length: {n} bytes"):
        rdt.decode_datagram(bytes(n))


@pytest.mark.parametrize("data, message", [
    (bytes.fromhex("1234 0002 000000"), "wrong length: 7 bytes"),
    (bytes.fromhex("1234 0002 00000000 00"), "wrong length: 9 bytes"),
    (bytes.fromhex("4321 0002 00000000"), "wrong header 0x4321"),
    (bytes.fromhex("1234 0041 00000000"), "unknown command 0x0041"),
    (bytes.fromhex("1234 0099 00000000"), "unknown command 0x0099"),
])
def test_malformed_requests_are_refused_with_the_reason(data, message):
    with pytest.raises(ProtocolError, match=message):
        rdt.decode_request(data)


def test_encoding_bad_requests_is_refused():
    with pytest.raises(InputError, match="unknown RDT command 0x0005"):
        rdt.encode_request(5)
    with pytest.raises(InputError, match="sample count"):
        rdt.encode_request(CMD_START_REALTIME, 2**32)
    with pytest.raises(InputError, match="positive"):
        CountsPerUnit(0.0, 1.0)


@settings(derandomize=True, max_examples=300, deadline=None)
@given(values=st.tuples(*[st.floats(-2000.0, 2000.0)] * 6),
       cpf=st.sampled_from([1e6, 1e5, 1.0e3]), cpt=st.sampled_from([1e6, 2e4]))
def test_counts_round_trip_within_half_a_count(values, cpf, cpt):
    scale = CountsPerUnit(cpf, cpt)
    back = scale.to_si(scale.to_counts(values), [0.0] * 6)
    for i, (v, b) in enumerate(zip(values, back)):
        q = 1.0 / (cpf if i < 3 else cpt)
        assert abs(v - b) <= 0.5 * q + 1e-9  # rounding to the nearest count; 1e-9: float slack


def test_counts_saturate_at_int32():
    assert CountsPerUnit().to_counts((1e9, -1e9, 0, 0, 0, 0))[:2] == (2**31 - 1, -(2**31))


def test_sequence_gap_handles_wrap_repeats_and_restarts():
    assert rdt.sequence_gap(5, 6) == 0
    assert rdt.sequence_gap(5, 10) == 4
    assert rdt.sequence_gap(2**32 - 1, 0) == 0  # uint32 wrap
    assert rdt.sequence_gap(2**32 - 2, 1) == 2
    assert rdt.sequence_gap(5, 5) == -1
    assert rdt.sequence_gap(500, 1) == -1  # restarted stream, not a loss


# ==================================================================== server alone
def raw_socket() -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.settimeout(1.0)
    return s


def test_server_streams_to_the_requester_and_ignores_malformed_requests():
    with RdtServer(constant(), port=0) as server, raw_socket() as s:
        assert server.port != 0
        for junk in (b"\x12\x34", bytes.fromhex("4321 0002 00000000"),
                     bytes.fromhex("1234 0041 00000000")):
            s.sendto(junk, server.address)
        assert wait_until(lambda: server.counters.malformed_requests == 3)
        s.settimeout(0.1)
        with pytest.raises(socket.timeout):  # the device does not reply to bad requests
            s.recvfrom(1024)
        s.settimeout(1.0)
        s.sendto(rdt.encode_request(CMD_START_REALTIME, 3), server.address)
        records = [rdt.decode_datagram(s.recvfrom(1024)[0]) for _ in range(3)]
        assert [r[0].rdt_sequence for r in records] == [1, 2, 3]
        assert records[0][0].counts == (10_000_000, -20_000_000, -50_000_000,
                                        1_000_000, -2_000_000, 3_000_000)
        assert wait_until(lambda: not server.streaming)
        assert server.counters.requests == 4 and server.counters.records_sent == 3
    server.close()  # second close is harmless


def test_server_refuses_bad_configuration():
    with pytest.raises(InputError, match="rate"):
        RdtServer(constant(), port=0, rate_hz=0.0)
    with pytest.raises(InputError, match="buffer_records"):
        RdtServer(constant(), port=0, buffer_records=41)


# ==================================================================== client <-> server
@pytest.fixture
def pair():
    """A constant-load server and a client connected to it; both closed afterwards."""
    server = RdtServer(constant(), port=0, rate_hz=1000.0, buffer_records=8)
    client = RdtForceTorqueSensor("127.0.0.1", server.port, timeout_s=0.05)
    yield server, client
    client.close()
    server.close()


def test_streaming_delivers_the_load_in_si(pair):
    _server, client = pair
    w = client.read(Wrench())
    assert w.stale and w.sequence == -1 and all(math.isnan(v) for v in w.as_tuple())  # NaN until read
    t0 = time.monotonic()
    client.start()
    assert wait_until(lambda: client.counters.received >= 100)
    elapsed = time.monotonic() - t0
    w = client.read(Wrench())
    assert w.as_tuple() == pytest.approx(LOAD, abs=QUANTUM)
    assert w.sequence >= 100 and not w.saturated and w.status == 0
    assert t0 <= w.t <= time.monotonic()            # stamped on receipt, on this clock
    # Pacing: the server must not dump records as fast as it can (100 would take ~ms); at
    # 1 kHz the 100th leaves ≥ 99 ms after the first. Only a lower bound: a loaded machine
    # is slower, never faster.
    assert elapsed >= 0.099 - 0.002
    assert client.counters.sequence_gaps == 0 and client.counters.malformed == 0


def test_sample_count_is_honoured(pair):
    server, client = pair
    samples = client.read_samples(25, timeout_s=1.0, start=True)
    assert [s.sequence for s in samples] == list(range(1, 26))
    assert wait_until(lambda: not server.streaming)
    time.sleep(0.05)  # 50 records' worth at 1 kHz: none may come
    assert client.counters.received == 25 and server.counters.records_sent == 25


def test_stop_ends_the_stream(pair):
    server, client = pair
    client.start()
    assert wait_until(lambda: client.counters.received >= 20)
    client.stop()
    assert wait_until(lambda: not server.streaming)
    time.sleep(0.02)  # let datagrams already in flight land
    n = client.counters.received
    time.sleep(0.1)
    assert client.counters.received == n
    assert client.read(Wrench()).stale  # 0.1 s > timeout_s 0.05 s without data


def test_bias_zeroes_the_reading(pair):
    _server, client = pair
    client.start()
    assert wait_until(lambda: client.counters.received >= 5)
    client.bias()
    # Bias is handled between records; wait for records stamped after it.
    seq = client.read(Wrench()).sequence
    assert wait_until(lambda: client.read(Wrench()).sequence >= seq + 5)
    assert client.read(Wrench()).as_tuple() == pytest.approx((0.0,) * 6, abs=QUANTUM)


def test_bias_of_a_noisy_twin_leaves_only_noise():
    model = TwinAtiSensorModel(seed=2)  # default noise sigma: 0.125 N (x, y), 0.25 N (z)
    with RdtServer(model.make_source(LOAD), port=0) as server, \
            RdtForceTorqueSensor("127.0.0.1", server.port) as client:
        client.bias()
        samples = client.read_samples(200, start=True)
    fz = [s.fz for s in samples]
    # Reading = noise - (one noise sample taken at bias): |bias error| < 4 sigma = 1 N for
    # any sane seed; the mean of 200 readings is that constant plus 0.25/sqrt(200) = 0.018 N.
    assert abs(sum(fz) / len(fz)) < 1.0
    assert abs(sum(s.fx for s in samples) / len(samples)) < 0.5


def test_buffered_mode_packs_records(pair):
    server, client = pair
    client.buffered = True
    samples = client.read_samples(20, timeout_s=1.0, start=True)
    assert [s.sequence for s in samples] == list(range(1, 21))
    assert all(s.as_tuple() == pytest.approx(LOAD, abs=QUANTUM) for s in samples)
    assert wait_until(lambda: server.counters.datagrams_sent == 3)
    # 20 records in datagrams of 8: 8 + 8 + the last 4 when the count runs out.
    assert client.counters.datagrams == 3 and client.counters.received == 20
    assert client.counters.sequence_gaps == 0


def test_sequence_gaps_are_counted(pair):
    server, client = pair
    client.start()
    assert wait_until(lambda: client.counters.received >= 10)
    server.skip_sequence(5)
    assert wait_until(lambda: client.counters.sequence_gaps == 5)
    server.skip_sequence(2)
    server.skip_sequence(1)
    assert wait_until(lambda: client.counters.sequence_gaps == 8)
    time.sleep(0.02)
    assert client.counters.sequence_gaps == 8 and client.counters.malformed == 0


def test_dropout_makes_the_reading_stale_after_the_timeout():
    model = TwinAtiSensorModel(seed=4)
    with RdtServer(model.make_source(LOAD), port=0) as server, \
            RdtForceTorqueSensor("127.0.0.1", server.port, timeout_s=0.05) as client:
        client.start()
        assert wait_until(lambda: not client.read(Wrench()).stale)
        model.set_fault("dropout")
        t_off = time.monotonic()
        assert wait_until(lambda: client.read(Wrench()).stale)
        # Not stale before timeout_s has passed since the last record.
        assert time.monotonic() - t_off >= 0.05 - 0.002
        assert client.counters.stale_events == 1
        n = client.counters.received
        time.sleep(0.05)
        assert client.counters.received == n  # the server really stopped sending
        assert server.counters.dropouts > 0
        model.set_fault("dropout", False)
        assert wait_until(lambda: not client.read(Wrench()).stale)


def test_frozen_samples_are_stale_although_datagrams_arrive():
    model = TwinAtiSensorModel(seed=4)
    with RdtServer(model.make_source(LOAD), port=0) as server, \
            RdtForceTorqueSensor("127.0.0.1", server.port, timeout_s=0.05) as client:
        client.start()
        assert wait_until(lambda: not client.read(Wrench()).stale)
        model.set_fault("stale")
        assert wait_until(lambda: client.read(Wrench()).stale)
        n = client.counters.received
        assert wait_until(lambda: client.counters.received > n + 10)  # still streaming
        assert client.read(Wrench()).stale


def test_overload_sets_the_saturated_flag():
    model = TwinAtiSensorModel(AtiSensorParams(noise_sigma=(0.0,) * 6,
                                               drift_rate=(0.0,) * 6), seed=0)
    with RdtServer(model.make_source((0.0, 0.0, -2500.0, 0.0, 0.0, 0.0)), port=0) as server, \
            RdtForceTorqueSensor("127.0.0.1", server.port) as client:
        (w,) = client.read_samples(1, start=True)
    assert w.saturated and w.status == STATUS_ANY_ERROR | STATUS_FT_OUT_OF_RANGE
    assert w.fz == pytest.approx(-1980.0, abs=QUANTUM)  # clipped at the Delta's Fz range


def test_saturate_fault_sets_the_flag_through_the_protocol():
    model = TwinAtiSensorModel(seed=0)
    model.set_fault("saturate")
    with RdtServer(model.make_source(LOAD), port=0) as server, \
            RdtForceTorqueSensor("127.0.0.1", server.port) as client:
        samples = client.read_samples(3, start=True)
    assert all(s.saturated for s in samples)


def test_client_rejects_and_counts_malformed_datagrams():
    with raw_socket() as fake, RdtForceTorqueSensor("127.0.0.1", fake.getsockname()[1]) as client:
        good = rdt.encode_record(7, 70, 0, (1_000_000,) * 6)
        for junk in (b"", b"\x00" * 35, good + b"\x00", b"\x12\x34\x00\x02"):
            fake.sendto(junk, client.local_address)
        fake.sendto(good, client.local_address)
        assert wait_until(lambda: client.counters.received == 1)
        assert client.counters.malformed == 4 and client.counters.datagrams == 1
        assert "wrong length" in client.last_error
        w = client.read(Wrench())
        assert w.sequence == 7 and w.fx == pytest.approx(1.0, abs=QUANTUM)


def test_client_without_a_sensor_raises_a_clear_error():
    with raw_socket() as placeholder:
        port = placeholder.getsockname()[1]
    with (
        RdtForceTorqueSensor("127.0.0.1", port) as client,
        pytest.raises(HardwareError, match="no RDT data from 127.0.0.1"),
    ):
        client.read_samples(1, timeout_s=0.1, start=True)
    with pytest.raises(HardwareError, match="closed"):
        client.start()


def test_backends_register_lazily():
    from rt.devices.registry import backend_class

    assert backend_class("force_torque", "ati_rdt") is RdtForceTorqueSensor


# ==================================================================== CLI end to end
def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    return env


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _read_line(proc: subprocess.Popen, timeout: float) -> str:
    sel = selectors.DefaultSelector()
    sel.register(proc.stdout, selectors.EVENT_READ)
    try:
        if not sel.select(timeout):
            raise AssertionError("no output from the server within the timeout")
        return proc.stdout.readline()
    finally:
        sel.close()


def _talus(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "talus", *args], cwd=REPO, env=_env(),
                          check=False, capture_output=True, text=True, timeout=90)


def test_cli_reads_the_twin_served_over_rdt():
    port = _free_udp_port()
    server = subprocess.Popen(
        [sys.executable, "-m", "talus", "twin", "serve-ati", "--port", str(port),
         "--seconds", "120", "--seed", "3"],
        cwd=REPO, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        serving = json.loads(_read_line(server, 60.0))
        assert serving["serving"]["port"] == port

        done = _talus("ati", "read", "--host", "127.0.0.1", "--port", str(port),
                      "--samples", "5")
        assert done.returncode == 0, done.stdout + done.stderr
        lines = [json.loads(x) for x in done.stdout.splitlines()]
        assert len(lines) == 5
        assert set(lines[0]) == {"t", "seq", "fx", "fy", "fz", "tx", "ty", "tz", "status"}
        assert [x["seq"] for x in lines] == [1, 2, 3, 4, 5]
        # Default load Fz = -50 N; noise sigma 0.25 N and drift < 0.1 N in these few seconds:
        # 1.5 N is > 5 sigma.
        assert all(abs(x["fz"] + 50.0) < 1.5 and x["status"] == 0 for x in lines)

        biased = _talus("ati", "read", "--host", "127.0.0.1", "--port", str(port),
                        "--samples", "3", "--bias")
        assert biased.returncode == 0, biased.stdout + biased.stderr
        # Biased: noise minus the noise sample taken at bias, |.| < 6 * 0.25 * sqrt(2) ~ 2 N.
        assert all(abs(json.loads(x)["fz"]) < 2.0 for x in biased.stdout.splitlines())
    finally:
        server.send_signal(signal.SIGTERM)
        out, err = server.communicate(timeout=30)
    assert server.returncode == 0, err
    stopped = json.loads(out.splitlines()[-1])["stopped"]
    assert stopped["records_sent"] == 8 and stopped["malformed_requests"] == 0


def test_cli_reports_a_silent_sensor_with_exit_code_2():
    done = _talus("ati", "read", "--host", "127.0.0.1", "--port", str(_free_udp_port()),
                  "--samples", "2", "--timeout", "0.2")
    assert done.returncode == 2
    assert "no RDT data" in json.loads(done.stdout.splitlines()[-1])["error"]
