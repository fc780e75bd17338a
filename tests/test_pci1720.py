"""PCI-1720 DAC driver against a comedilib double (no library, no card needed)."""
from __future__ import annotations

import ctypes
import ctypes.util
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rt.devices import registry
from rt.drivers.fake_comedi import FakeComedi
from rt.drivers.pci1720 import (
    AREF_GROUND,
    COMEDI_OUTPUT,
    MISSING_LIBRARY_MESSAGE,
    EnableLine,
    Pci1720Outputs,
    code_to_volts,
    load_comedilib,
    volts_to_code,
)
from rt.errors import BackendUnavailableError, ConfigurationError, HardwareError, InputError

LSB_V = 20.0 / 4095          # one code on the ±10 V range
ZERO_CODE = 2048             # floor(2047.5 + 0.5)


@pytest.fixture
def lib() -> FakeComedi:
    return FakeComedi()


@pytest.fixture
def dac(lib) -> Pci1720Outputs:
    return Pci1720Outputs(lib=lib)


# --- conversion ----------------------------------------------------------------------------

def test_volt_to_code_on_the_10v_range():
    assert volts_to_code(-10.0) == 0
    assert volts_to_code(10.0) == 4095
    assert volts_to_code(0.0) == ZERO_CODE
    assert volts_to_code(6.0) == 3276                     # (16/20)*4095 = 3276.0
    assert volts_to_code(-6.0) == 819                     # (4/20)*4095 = 819.0
    assert volts_to_code(12.0) == 4095 and volts_to_code(-12.0) == 0      # DAC range clamp
    for v in (-9.3, -1.0, 0.37, 4.2):
        assert volts_to_code(v) == round((v + 10) / 20 * 4095)


@settings(derandomize=True, max_examples=500, deadline=None)
@given(v=st.floats(-10.0, 10.0))
def test_quantization_error_is_at_most_half_an_lsb(v):
    # Codes sit on a uniform grid of step LSB = 20/4095 V from -10 V to +10 V, and
    # volts_to_code rounds to the nearest grid point, so |error| <= LSB/2 everywhere inside
    # the range (the grid ends are exactly -10 and +10 V, so clamping adds no error there).
    code = volts_to_code(v)
    assert 0 <= code <= 4095
    assert abs(code_to_volts(code) - v) <= 0.5 * LSB_V + 1e-12


def test_thesis_resolution_matches_one_lsb():
    assert LSB_V == pytest.approx(0.0048, abs=1e-4)       # thesis 3.1.2: 0.0048 V


# --- driver ----------------------------------------------------------------------------------

def test_opens_disabled_with_zero_volts_on_every_channel(lib, dac):
    assert not dac.enabled
    assert lib.opened[0][0] == b"/dev/comedi0"
    assert [(w[1], w[2], w[3], w[4], w[5]) for w in lib.writes] == [
        (0, c, 3, AREF_GROUND, ZERO_CODE) for c in (0, 1, 2)]
    assert dac.lsb_v == pytest.approx((LSB_V,) * 3)


def test_writes_codes_on_the_configured_channels(lib, dac):
    dac.enable()
    dac.write_volts([1.0, -2.5, 0.0])
    assert lib.codes() == [volts_to_code(1.0), volts_to_code(-2.5), ZERO_CODE]
    assert all(w[3] == 3 and w[4] == AREF_GROUND for w in lib.writes)
    assert dac.last_volts[0] == pytest.approx(1.0, abs=0.5 * LSB_V)


def test_commands_are_clamped_to_plus_minus_6_volts(lib, dac):
    dac.enable()
    dac.write_volts([7.5, -9.0, 5.9])
    assert lib.codes() == [volts_to_code(6.0), volts_to_code(-6.0), volts_to_code(5.9)]
    assert dac.clamped == [True, True, False]
    assert max(abs(v) for v in dac.last_volts) <= 6.0 + 0.5 * LSB_V


@settings(derandomize=True, max_examples=200, deadline=None)
@given(volts=st.tuples(*(st.floats(-50.0, 50.0),) * 3))
def test_output_never_exceeds_the_limit(volts):
    lib = FakeComedi()
    dac = Pci1720Outputs(lib=lib, limit_v=6.0)
    dac.enable()
    dac.write_volts(volts)
    for code, v in zip(lib.codes(), volts):
        out = code_to_volts(code)
        assert abs(out) <= 6.0 + 0.5 * LSB_V
        assert abs(out - max(-6.0, min(6.0, v))) <= 0.5 * LSB_V + 1e-12


def test_writes_are_refused_while_disabled(lib, dac):
    n = len(lib.writes)
    with pytest.raises(HardwareError, match="disabled"):
        dac.write_volts([0.0, 0.5, 0.0])
    assert len(lib.writes) == n                           # nothing reached the card
    dac.write_volts([0.0, 0.0, 0.0])                      # zero is always allowed


def test_disable_writes_zero_to_every_channel(lib, dac):
    dac.enable()
    dac.write_volts([3.0, -3.0, 1.0])
    dac.disable()
    assert not dac.enabled
    assert lib.codes() == [ZERO_CODE] * 3
    with pytest.raises(HardwareError):
        dac.write_volts([1.0, 0.0, 0.0])
    dac.disable()                                         # safe to repeat


def test_non_finite_or_wrong_length_commands_change_nothing(lib, dac):
    dac.enable()
    dac.write_volts([1.0, 1.0, 1.0])
    before = list(lib.writes)
    for bad in ([math.nan, 0.0, 0.0], [0.0, math.inf, 0.0], [1.0, 1.0]):
        with pytest.raises(InputError):
            dac.write_volts(bad)
    assert lib.writes == before


def test_enable_line_follows_enable_and_disable(lib):
    dac = Pci1720Outputs(lib=lib, enable_line=EnableLine(subdevice=2, channel=5))
    handle = lib.opened[0][1]
    assert lib.dio_config == [(handle, 2, 5, COMEDI_OUTPUT)]
    assert lib.dio[-1] == (handle, 2, 5, 0)               # starts dropped
    dac.enable()
    assert lib.dio[-1] == (handle, 2, 5, 1)
    dac.write_volts([2.0, 0.0, 0.0])
    n_writes = len(lib.writes)
    dac.disable()
    # zero volts first, then the line drops
    assert lib.codes() == [ZERO_CODE] * 3 and len(lib.writes) == n_writes + 3
    assert lib.dio[-1] == (handle, 2, 5, 0)


def test_active_low_enable_line_on_another_device(lib):
    dac = Pci1720Outputs(lib=lib, enable_line={"subdevice": 2, "channel": 0,
                                               "device": "/dev/comedi1", "active_high": False})
    assert [p for p, _ in lib.opened] == [b"/dev/comedi0", b"/dev/comedi1"]
    other = lib.opened[1][1]
    assert lib.dio[-1] == (other, 2, 0, 1)                # inactive = high
    dac.enable()
    assert lib.dio[-1] == (other, 2, 0, 0)
    dac.close()
    assert set(lib.closed) == {h for _, h in lib.opened}


def test_close_zeroes_outputs_closes_once_and_is_idempotent(lib, dac):
    dac.enable()
    dac.write_volts([1.0, 2.0, 3.0])
    with dac:
        pass
    dac.close()
    assert lib.codes() == [ZERO_CODE] * 3
    assert len(lib.closed) == 1
    with pytest.raises(HardwareError, match="closed"):
        dac.write_volts([0.0, 0.0, 0.0])


def test_write_failure_is_a_hardware_error(lib, dac):
    dac.enable()
    lib.fail_writes = True
    with pytest.raises(HardwareError, match="fake comedi error 5"):
        dac.write_volts([1.0, 0.0, 0.0])


def test_missing_device_file_is_backend_unavailable(lib, tmp_path):
    lib.fail_open = True
    with pytest.raises(BackendUnavailableError, match="does not exist"):
        Pci1720Outputs(device=str(tmp_path / "comedi9"), lib=lib)


@pytest.mark.parametrize("kwargs, message", [
    ({"range_index": 0}, "does not fit range"),           # 0-5 V cannot hold ±6 V
    ({"range_index": 7}, "no range 7"),
    ({"channels": (0, 1, 4)}, "channels 0-3"),
    ({"channels": (0, 0, 1)}, "distinct"),
    ({"subdevice": 1}, "no subdevice 1"),
    ({"limit_v": -1.0}, "positive"),
    ({"enable_line": EnableLine(subdevice=0, channel=0)}, "digital output"),
])
def test_bad_configuration_is_refused(lib, kwargs, message):
    with pytest.raises(ConfigurationError, match=message):
        Pci1720Outputs(lib=lib, **kwargs)
    assert len(lib.closed) == len(lib.opened)             # nothing left open


# --- missing library -------------------------------------------------------------------------

def test_missing_comedilib_is_one_clear_error(monkeypatch):
    monkeypatch.setattr(ctypes.util, "find_library", lambda name: None)
    with pytest.raises(BackendUnavailableError) as info:
        Pci1720Outputs()
    assert str(info.value) == MISSING_LIBRARY_MESSAGE
    assert info.value.__cause__ is None and info.value.__context__ is None   # no chain
    with pytest.raises(BackendUnavailableError, match="comedilib not found"):
        registry.create("actuators", "pci1720")


def test_unloadable_comedilib_is_the_same_error(monkeypatch):
    monkeypatch.setattr(ctypes.util, "find_library", lambda name: "libcomedi-missing.so.99")
    with pytest.raises(BackendUnavailableError, match="comedilib not found") as info:
        load_comedilib()
    assert info.value.__cause__ is None


def test_registered_as_pci1720_actuators(lib):
    dac = registry.create("actuators", "pci1720", lib=lib)
    assert isinstance(dac, Pci1720Outputs)
    dac.close()


def test_enable_line_drops_even_when_zeroing_fails(lib):
    dac = Pci1720Outputs(lib=lib, enable_line=EnableLine(subdevice=2, channel=1))
    dac.enable()
    lib.fail_writes = True                                 # e.g. the card stopped answering
    with pytest.raises(HardwareError):
        dac.disable()
    assert lib.dio[-1][3] == 0 and not dac.enabled
    dac.enable()
    with pytest.raises(HardwareError):
        dac.close()
    assert lib.dio[-1][3] == 0 and dac.closed and len(lib.closed) == 1
    dac.disable()                                          # after close: a harmless no-op
