"""PCL-833 driver against the register-level fake; decode helpers; /dev/port errors."""
from __future__ import annotations

import ctypes.util
import os

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rt.devices import registry
from rt.drivers.fake_pcl833 import FakePcl833Port
from rt.drivers.pcl833 import (
    COUNTER_MODULUS,
    MIDPOINT,
    REG_CLOCK_CASCADE,
    REG_COUNTER_RESET,
    CountUnwrapper,
    InputMode,
    Pcl833Encoders,
    count_register,
    decode_counts,
    encode_position,
    latch_register,
    mode_register,
)
from rt.drivers.port_io import DevPortIO, check_ioperm
from rt.errors import BackendUnavailableError, ConfigurationError, HardwareError

M = 2e-5                 # m per count (thesis)
STROKE_M = 0.40          # slider stroke (DESIGN section 4)
BASE = 0x220


def make(port: FakePcl833Port | None = None, **kw) -> tuple[FakePcl833Port, Pcl833Encoders]:
    port = FakePcl833Port() if port is None else port
    return port, Pcl833Encoders(port_io=port, **kw)


# --- pure helpers ---------------------------------------------------------------------------

def test_decode_is_the_thesis_formula():
    # Thesis 3.2.2: ch1Dec = (InReg[2]*65536 + InReg[1]*256 + InReg[0] - 8388608) * 0.02/1000
    for count in (MIDPOINT, MIDPOINT + 1, MIDPOINT - 1, MIDPOINT + 20000, 0, COUNTER_MODULUS - 1):
        assert decode_counts(count) == pytest.approx((count - 8388608) * 0.02 / 1000)
    assert decode_counts(MIDPOINT + 100, sign=-1) == pytest.approx(-100 * M)
    assert decode_counts(MIDPOINT + 100, m_per_count=1e-6) == pytest.approx(100e-6)


def test_encode_examples():
    assert encode_position(0.0) == MIDPOINT
    assert encode_position(STROKE_M) == MIDPOINT + 20000
    assert encode_position(-1e-5 + 1e-12) == MIDPOINT          # half a count rounds up
    assert encode_position(0.1, sign=-1) == MIDPOINT - 5000


@settings(derandomize=True, max_examples=300, deadline=None)
@given(position=st.floats(-1.0, 1.0), m_per_count=st.floats(1e-6, 1e-4),
       sign=st.sampled_from((1, -1)))
def test_encode_decode_within_half_a_count(position, m_per_count, sign):
    count = encode_position(position, m_per_count=m_per_count, sign=sign)
    assert 0 <= count < COUNTER_MODULUS
    decoded = decode_counts(count, m_per_count=m_per_count, sign=sign)
    assert abs(decoded - position) <= 0.5 * m_per_count * (1 + 1e-9)


def test_encode_wraps_like_the_24_bit_counter():
    # 2**23 counts at 2e-5 m is 167.77216 m: one count further wraps to the other end.
    assert encode_position(2**23 * M - M) == COUNTER_MODULUS - 1
    assert encode_position(2**23 * M) == 0
    assert decode_counts(encode_position(2**23 * M)) == pytest.approx(-(2**23) * M)
    assert encode_position(-(2**23) * M) == 0


def test_decode_handles_underflow_of_a_counter_reset_to_zero():
    # With reset value "start" (0) one count down is 0xFFFFFF, which must read -1 count.
    assert decode_counts(0xFFFFFF, midpoint=0) == pytest.approx(-M)
    assert decode_counts(5, midpoint=0) == pytest.approx(5 * M)


def test_unwrapper_crosses_the_24_bit_boundary_both_ways():
    u = CountUnwrapper(reference=MIDPOINT, count=COUNTER_MODULUS - 3)
    start = u.displacement
    assert u.update(COUNTER_MODULUS - 1) - start == 2
    assert u.update(1) - start == 4              # 0xFFFFFF -> 0x000001 is +2
    assert u.update(COUNTER_MODULUS - 2) - start == 1
    u.reset()
    assert u.displacement == 0


@settings(derandomize=True, max_examples=200, deadline=None)
@given(start=st.integers(0, COUNTER_MODULUS - 1),
       steps=st.lists(st.integers(-(2**22), 2**22), min_size=1, max_size=50))
def test_unwrapper_is_the_sum_of_the_moves(start, steps):
    u = CountUnwrapper(reference=start, count=start)
    count, total = start, 0
    for step in steps:
        count = (count + step) % COUNTER_MODULUS
        total += step
        assert u.update(count) == total


# --- driver against the fake card -------------------------------------------------------------

def test_open_configures_the_card_as_the_thesis_does():
    port, enc = make()
    for channel in (1, 2, 3):
        # x1 input (1) with reset value "middle" (bit 3), software-read latch.
        assert port.register(mode_register(channel)) == InputMode.X1 | 0x08
        assert port.register(latch_register(channel)) == 0
    assert port.register(REG_CLOCK_CASCADE) == 0          # 8 MHz, 24-bit (no cascade)
    reset_writes = [v for p, v in port.writes if p == BASE + REG_COUNTER_RESET]
    assert reset_writes == [0x07, 0x00]                   # reset all, then release
    assert enc.read_counts() == (MIDPOINT,) * 3
    assert all(BASE <= p < BASE + 16 for p, _ in port.writes)


@pytest.mark.parametrize("sign", [1, -1])
def test_whole_stroke_decodes_within_one_count(sign):
    port = FakePcl833Port(m_per_count=M, sign=sign)
    port.set_positions_m([0.0, 0.0, 0.0])                  # robot at the bottom at start-up
    _, enc = make(port, m_per_count=M, sign=sign)
    out = np.empty(3)
    for q in np.linspace(0.0, STROKE_M, 4001):
        positions = (q, STROKE_M - q, 0.5 * q)
        port.set_positions_m(positions)
        enc.read_positions_m(out)
        assert np.max(np.abs(out - positions)) <= M
    # and back down to the bottom
    port.set_positions_m([0.0, 0.0, 0.0])
    assert np.allclose(enc.read_positions_m(out), 0.0, atol=M)


@settings(derandomize=True, max_examples=60, deadline=None)
@given(path=st.lists(st.tuples(*(st.floats(0.0, STROKE_M),) * 3), min_size=1, max_size=30),
       m_per_count=st.tuples(*(st.sampled_from((1e-5, 2e-5, 5e-5)),) * 3),
       sign=st.tuples(*(st.sampled_from((1, -1)),) * 3))
def test_any_trajectory_decodes_within_one_count(path, m_per_count, sign):
    port = FakePcl833Port(m_per_count=m_per_count, sign=sign)
    _, enc = make(port, m_per_count=m_per_count, sign=sign)
    out = np.empty(3)
    for positions in path:
        port.set_positions_m(positions)
        enc.read_positions_m(out)
        for i in range(3):
            assert abs(out[i] - positions[i]) <= m_per_count[i]


def test_reset_returns_to_the_midpoint_and_zero():
    port, enc = make()
    port.set_positions_m([0.1, 0.2, 0.3])
    out = enc.read_positions_m(np.empty(3))
    assert np.allclose(out, [0.1, 0.2, 0.3], atol=M)
    enc.reset()
    assert enc.read_counts() == (MIDPOINT,) * 3
    assert np.allclose(enc.read_positions_m(out), 0.0)
    port.set_positions_m([0.15, 0.2, 0.25])               # positions are now relative to reset
    assert np.allclose(enc.read_positions_m(out), [0.05, 0.0, -0.05], atol=M)


def test_counts_below_the_reset_point_do_not_underflow():
    port, enc = make()
    port.set_positions_m([0.2, 0.2, 0.2])
    enc.reset()
    port.set_positions_m([0.0, 0.1, 0.2])                 # move down from the reset point
    counts = enc.read_counts()
    assert counts == (MIDPOINT - 10000, MIDPOINT - 5000, MIDPOINT)
    assert np.allclose(enc.read_positions_m(np.empty(3)), [-0.2, -0.1, 0.0], atol=M)


def test_driver_follows_a_counter_through_the_24_bit_wrap():
    port, enc = make()
    out = np.empty(3)
    port.set_count(0, COUNTER_MODULUS - 2)                # back door: near the top
    enc.read_positions_m(out)
    before = out[0]
    port.move_counts(0, 5)                                # ... 0xFFFFFE -> 0x000003
    assert port.count(0) == 3
    enc.read_positions_m(out)
    assert out[0] - before == pytest.approx(5 * M)
    port.move_counts(0, -10)
    enc.read_positions_m(out)
    assert out[0] - before == pytest.approx(-5 * M)


def test_channel_mapping_and_per_axis_scale():
    port = FakePcl833Port(m_per_count=(1e-5, 2e-5, 4e-5))
    # axis 0 on card channel 3, axis 1 on channel 1, axis 2 on channel 2
    _, enc = make(port, channels=(3, 1, 2), m_per_count=(4e-5, 1e-5, 2e-5))
    port.set_positions_m([0.01, 0.02, 0.03])               # card channels 1, 2, 3
    assert np.allclose(enc.read_positions_m(np.empty(3)), [0.03, 0.01, 0.02], atol=4e-5)


def test_reset_on_open_false_keeps_the_counted_position():
    port, enc = make()
    port.set_positions_m([0.1, 0.2, 0.3])
    enc.close()
    enc2 = Pcl833Encoders(port_io=port, reset_on_open=False)
    assert np.allclose(enc2.read_positions_m(np.empty(3)), [0.1, 0.2, 0.3], atol=M)


# --- the fake card's own behaviour (what the driver relies on) --------------------------------

def test_high_byte_read_latches_the_counter():
    port = FakePcl833Port()
    _, enc = make(port)
    port.set_count(0, 0x12FFFF)
    msb = port.inb(BASE + count_register(1, 2))           # latches 0x12FFFF
    port.set_count(0, 0x130000)                           # counter moves on
    lsb = port.inb(BASE + count_register(1, 0))
    mid = port.inb(BASE + count_register(1, 1))
    assert (msb, mid, lsb) == (0x12, 0xFF, 0xFF)          # one instant, not a torn 0x12FF00
    assert enc.read_counts()[0] == 0x130000


def test_reset_bits_hold_the_counter_until_released():
    port, _enc = make()
    port.outb(BASE + REG_COUNTER_RESET, 0x01)             # hold channel 1 only
    port.set_positions_m([0.1, 0.1, 0.1])
    assert (port.count(0), port.count(1)) == (MIDPOINT, MIDPOINT + 5000)
    port.outb(BASE + REG_COUNTER_RESET, 0x00)
    port.set_positions_m([0.2, 0.2, 0.2])
    assert port.count(0) == MIDPOINT + 5000               # pulses while held were lost


def test_disabled_or_frozen_channels_do_not_count():
    port = FakePcl833Port()
    port.set_positions_m([0.1, 0.1, 0.1])                 # power-up: inputs disabled
    assert [port.count(i) for i in range(3)] == [0, 0, 0]
    _, enc = make(port)
    port.set_frozen(2)
    port.set_positions_m([0.2, 0.2, 0.2])
    assert np.allclose(enc.read_positions_m(np.empty(3)), [0.1, 0.1, 0.0], atol=M)


def test_wrong_base_address_is_caught_by_the_strict_fake():
    with pytest.raises(HardwareError, match="not a PCL-833 register"):
        Pcl833Encoders(port_io=FakePcl833Port(base=0x300), base=0x220)


# --- lifecycle, configuration, registry -------------------------------------------------------

def test_close_is_idempotent_and_leaves_an_injected_port_open():
    port, enc = make()
    with enc:
        pass
    enc.close()
    assert enc.closed and not port.closed
    with pytest.raises(HardwareError, match="closed"):
        enc.read_counts()


@pytest.mark.parametrize("kwargs", [
    {"base": 0x3F8}, {"sign": (1, 2, 1)}, {"m_per_count": 0.0}, {"channels": (1, 1, 2)},
    {"input_mode": 0}, {"m_per_count": (1e-5, 2e-5)},
])
def test_bad_configuration_is_refused(kwargs):
    with pytest.raises(ConfigurationError):
        Pcl833Encoders(port_io=FakePcl833Port(), **kwargs)


def test_registered_as_pcl833_encoders():
    port = FakePcl833Port()
    enc = registry.create("encoders", "pcl833", port_io=port)
    assert isinstance(enc, Pcl833Encoders)
    assert enc.read_counts() == (MIDPOINT,) * 3


# --- /dev/port ------------------------------------------------------------------------------

def test_dev_port_missing_gives_one_clear_error(tmp_path):
    missing = str(tmp_path / "no-such-port")
    with pytest.raises(BackendUnavailableError, match="does not exist.*'sim' backend"):
        DevPortIO(missing)
    with pytest.raises(BackendUnavailableError, match="does not exist"):
        Pcl833Encoders(port_path=missing)


def test_dev_port_permission_denied_says_root_is_needed(monkeypatch):
    def deny(*args, **kwargs):
        raise PermissionError(13, "Permission denied")
    monkeypatch.setattr(os, "open", deny)
    with pytest.raises(BackendUnavailableError, match="needs root"):
        DevPortIO("/dev/port")


def test_dev_port_reads_and_writes_bytes_at_the_port_offset(tmp_path):
    # A plain file stands in for /dev/port: same pread/pwrite at offset = port, no real I/O.
    path = tmp_path / "ports"
    path.write_bytes(bytes(0x400))
    with DevPortIO(str(path)) as io:
        io.outb(0x223, 0xAB)
        assert io.inb(0x223) == 0xAB
        assert io.inb(0x222) == 0
        with pytest.raises(HardwareError):
            io.outb(0x223, 256)
    assert path.read_bytes()[0x223] == 0xAB
    io.close()                                            # idempotent


def test_ioperm_probe_validates_the_range_and_reports_a_missing_libc(monkeypatch):
    # No real ioperm() call here: the range is refused first, then libc is "missing".
    with pytest.raises(ConfigurationError):
        check_ioperm(0xFFFF, 16)
    monkeypatch.setattr(ctypes.util, "find_library", lambda name: None)
    with pytest.raises(BackendUnavailableError, match="ioperm"):
        check_ioperm(BASE, 16)
