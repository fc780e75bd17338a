"""ATI Net F/T CAN protocol: codec, and client <-> twin responder on python-can's virtual bus."""
from __future__ import annotations

import itertools
import threading
import time
from collections.abc import Callable

import can
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rt.ati import can_protocol as cp
from rt.ati.can_client import AtiCanForceTorqueSensor, AtiCanResponder
from rt.ati.rdt import STATUS_ANY_ERROR, STATUS_FT_OUT_OF_RANGE, CountsPerUnit
from rt.ati.twin_sensor import TwinAtiSensorModel
from rt.devices.interfaces import Wrench
from rt.errors import HardwareError, InputError, ProtocolError

LOAD = (10.0, -20.0, -50.0, 1.0, -2.0, 3.0)
BASE = 0x120
# Short format defaults: 16 counts/N and 500 counts/(N m); rounding to the nearest count
# leaves at most half a count: 1/32 N and 1/1000 N m.
TOL = (1 / 32,) * 3 + (1 / 1000,) * 3
_channels = itertools.count()

int16 = st.integers(-(2**15), 2**15 - 1)
uint16 = st.integers(0, 2**16 - 1)


@pytest.fixture(autouse=True)
def no_leftover_threads():
    yield
    deadline = time.monotonic() + 2.0
    while time.monotonic() < deadline:
        alive = [t.name for t in threading.enumerate() if t.name.startswith("ati-can")]
        if not alive:
            return
        time.sleep(0.01)
    pytest.fail(f"threads left running: {alive}")


@pytest.fixture
def channel() -> str:
    """A fresh virtual-bus channel per test, so tests never hear each other."""
    return f"talus-test-{next(_channels)}"


def wait_until(pred: Callable[[], bool], timeout: float = 2.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return True
        time.sleep(0.002)
    return pred()


def close_to(w: Wrench, expected) -> bool:
    return all(abs(a - b) <= t for a, b, t in zip(w.as_tuple(), expected, TOL))


# ==================================================================== codec
def test_request_frames_match_the_manual():
    assert cp.encode_request(cp.OP_REQUEST_SHORT) == b"\x02"
    assert cp.encode_request(cp.OP_BIAS) == b"\x04"
    assert cp.decode_request(BASE, BASE, b"\x02") == cp.OP_REQUEST_SHORT
    with pytest.raises(InputError, match="unknown ATI CAN opcode 0x01"):
        cp.encode_request(cp.OP_REQUEST_LONG)  # documented, not implemented


@pytest.mark.parametrize("arb, data, message", [
    (BASE + 1, b"\x02", "sent to id 0x121, expected base id 0x120"),
    (BASE, b"", "has 0 data bytes, expected 1"),
    (BASE, b"\x02\x00", "has 2 data bytes, expected 1"),
    (BASE, b"\x07", "unknown opcode 0x07"),
])
def test_malformed_requests_are_refused(arb, data, message):
    with pytest.raises(ProtocolError, match=message):
        cp.decode_request(BASE, arb, data)


def test_short_reply_layout_is_little_endian_fx_tx_fy_ty_then_fz_tz_status_sample():
    xy, z = cp.encode_short_response((1, 2, 3, 4, 5, -1), 0x8000, 0x1234)
    assert xy == bytes.fromhex("0100 0400 0200 0500")  # Fx, Tx, Fy, Ty
    assert z == bytes.fromhex("0300 ffff 0080 3412")  # Fz, Tz, status, sample number


@settings(derandomize=True, max_examples=200, deadline=None)
@given(counts=st.tuples(*[int16] * 6), status=uint16, sample=uint16)
def test_short_reply_round_trip(counts, status, sample):
    xy, z = cp.encode_short_response(counts, status, sample)
    fx, tx, fy, ty = cp.decode_short_xy(xy)
    fz, tz, s16, n = cp.decode_short_z(z)
    assert (fx, fy, fz, tx, ty, tz) == counts and (s16, n) == (status, sample)


@pytest.mark.parametrize("size", [0, 7, 9])
def test_reply_frames_of_wrong_length_are_refused(size):
    with pytest.raises(ProtocolError, match=f"{size} data bytes, expected 8"):
        cp.decode_short_xy(bytes(size))
    with pytest.raises(ProtocolError, match=f"{size} data bytes, expected 8"):
        cp.decode_short_z(bytes(size))


def test_scale_status_and_base_id_rules():
    assert cp.to_counts16((1e6, -1e6, 0.03, 0, 0, 0), cp.default_can_counts())[:3] == (
        32767, -32768, 0)  # clipped to int16; 0.03 N * 16 = 0.48 rounds to 0
    assert cp.status16_from_status32(STATUS_ANY_ERROR | STATUS_FT_OUT_OF_RANGE | 0xFF) == 0xC000
    assert cp.status32_from_status16(0xC000) == STATUS_ANY_ERROR | STATUS_FT_OUT_OF_RANGE
    assert cp.check_base_id(cp.MAX_BASE_ID) == 0x7F9
    with pytest.raises(InputError, match="base id"):
        cp.check_base_id(0x7FA)


# ==================================================================== on the virtual bus
def test_round_trip_and_bias(channel):
    with AtiCanResponder(lambda: (LOAD, 0), channel=channel, base_id=BASE) as responder, \
            AtiCanForceTorqueSensor(channel, "virtual", base_id=BASE, poll_rate_hz=500) as c:
        assert c.read(Wrench()).stale
        c.start()
        assert wait_until(lambda: c.counters.received >= 20)
        w = c.read(Wrench())
        assert close_to(w, LOAD) and not w.stale and not w.saturated and w.status == 0
        assert c.counters.malformed == 0 and responder.counters.malformed == 0

        c.bias()
        n = c.counters.received
        assert wait_until(lambda: c.counters.received >= n + 5)
        assert close_to(c.read(Wrench()), (0.0,) * 6)
        c.stop()
        n = c.counters.received
        time.sleep(0.05)  # 25 polls' worth at 500 Hz: none may be sent after stop
        assert c.counters.received <= n + 1  # one reply may already be on its way


def test_twin_sample_numbers_and_saturation_reach_the_client(channel):
    model = TwinAtiSensorModel(seed=1)
    with AtiCanResponder(model.make_source((0.0, 0.0, -2500.0, 0.0, 0.0, 0.0)),
                         channel=channel) as _, \
            AtiCanForceTorqueSensor(channel, "virtual") as c:
        c.start()
        assert wait_until(lambda: c.counters.received >= 5)
        w = c.read(Wrench())
    assert w.saturated and w.status == STATUS_ANY_ERROR | STATUS_FT_OUT_OF_RANGE
    assert abs(w.fz + 1980.0) <= TOL[2]  # clipped at the Delta's Fz range
    assert w.sequence >= 5  # the twin's ft_sequence, as 16-bit sample number


def test_dropout_gives_stale_readings_and_timeouts(channel):
    model = TwinAtiSensorModel(seed=1)
    with AtiCanResponder(model.make_source(LOAD), channel=channel) as responder, \
            AtiCanForceTorqueSensor(channel, "virtual", timeout_s=0.05) as c:
        c.start()
        assert wait_until(lambda: not c.read(Wrench()).stale)
        model.set_fault("dropout")
        assert wait_until(lambda: c.read(Wrench()).stale)
        assert wait_until(lambda: c.counters.timeouts >= 5)
        assert c.counters.stale_events == 1 and responder.counters.dropouts >= 5
        model.set_fault("dropout", False)
        assert wait_until(lambda: not c.read(Wrench()).stale)


def test_malformed_frames_are_rejected_and_counted(channel):
    with AtiCanResponder(lambda: (LOAD, 0), channel=channel, base_id=BASE) as responder, \
            AtiCanForceTorqueSensor(channel, "virtual", base_id=BASE) as c, \
            can.Bus(interface="virtual", channel=channel) as injector:
        def send(arb: int, data: bytes) -> None:
            injector.send(can.Message(arbitration_id=arb, data=data, is_extended_id=False))

        send(BASE + 6, bytes(8))  # Fz/Tz frame without its Fx/Fy frame
        send(BASE + 5, bytes(4))  # short Fx/Fy frame
        send(BASE + 6, bytes(8))  # ... so this one is orphaned as well
        send(0x300, bytes(8))  # someone else's traffic: ignored, not counted
        send(BASE, b"\x09")  # unknown opcode
        send(BASE, b"")  # request without opcode
        c.start()  # the client thread only reads the bus while started
        assert wait_until(lambda: c.counters.malformed == 3)
        assert wait_until(lambda: responder.counters.malformed == 2)
        assert wait_until(lambda: c.counters.received >= 5)
        assert close_to(c.read(Wrench()), LOAD)
        assert "without its Fx/Fy frame" in c.last_error
        assert "has 0 data bytes" in responder.last_error  # the last bad request


def test_shared_bus_is_not_shut_down_and_close_is_idempotent(channel):
    bus = can.Bus(interface="virtual", channel=channel)
    try:
        sensor = AtiCanForceTorqueSensor(bus=bus)
        sensor.close()
        sensor.close()
        bus.send(can.Message(arbitration_id=1, data=b"", is_extended_id=False))  # still open
        with pytest.raises(HardwareError, match="closed"):
            sensor.start()
    finally:
        bus.shutdown()


def test_unknown_interface_is_a_clear_hardware_error():
    with pytest.raises(HardwareError, match="cannot open CAN bus"):
        AtiCanForceTorqueSensor("can0", "no-such-interface")


def test_backend_registered_as_ati_can():
    from rt.devices.registry import backend_class

    assert backend_class("force_torque", "ati_can") is AtiCanForceTorqueSensor
    assert CountsPerUnit(16.0, 500.0) == cp.default_can_counts()
