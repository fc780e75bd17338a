"""The amplifier inputs read back through a comedi analog-input card (optional on the rig).

The PCI-1720 cannot read its own outputs, so a DAC channel that accepts writes but outputs
nothing (a burnt output stage, a loose terminal) is invisible to it. The failover of thesis
3.7.3 needs to see that: ``RedundantDrive`` compares what it commanded with this monitor and
hands the outputs to the next card when a channel disagrees for a few cycles. The rig is
*assumed* to wire the three amplifier inputs (after the card-selecting relays) to three
single-ended inputs of an analog-input card that comedi drives (e.g. a PCI-1711 through
``adv_pci1710``); ``volts_per_volt`` scales what the card reads to amplifier-input volts (1
for a direct connection, other values for a divider or an isolation amplifier).

comedilib calls used: ``comedi_open``, ``comedi_get_n_channels``, ``comedi_get_maxdata``,
``comedi_get_range`` and ``comedi_data_read(dev, sub, chan, range, aref, lsampl_t *data)``
(1 on success, -1 on error); codes become volts as ``comedi_to_phys`` does. A failed read
raises ``HardwareError``: the drive block then faults instead of failing over on a guess.
"""
from __future__ import annotations

import ctypes
import math
from typing import Any, Sequence

from rt.devices.interfaces import Device
from rt.drivers.pci1720 import (AREF_GROUND, UNIT_VOLT, code_to_volts, comedi_error_text,
                                comedi_open_device, load_comedilib)
from rt.errors import ConfigurationError, HardwareError


class ComediAmplifierMonitor(Device):
    """Reads the three amplifier inputs (V). ``read_volts()`` returns a preallocated list.

    Parameters (fixed after construction): ``device`` (comedi device file), ``subdevice`` (the
    analog-input subdevice), ``channels`` (input of each axis), ``range_index`` (a range
    covering the ±6 V commands), ``volts_per_volt`` (amplifier-input V per measured V), ``lib``
    (comedilib or a double; ``None`` loads the library).
    """

    def __init__(self, device: str = "/dev/comedi3", subdevice: int = 0,
                 channels: Sequence[int] = (0, 1, 2), range_index: int = 0,
                 volts_per_volt: float = 1.0, lib: Any = None) -> None:
        self.channels = tuple(int(c) for c in channels)
        if len(self.channels) != 3 or len(set(self.channels)) != 3:
            raise ConfigurationError(f"channels must name 3 distinct inputs, got {channels}")
        if not (math.isfinite(volts_per_volt) and volts_per_volt != 0.0):
            raise ConfigurationError(f"volts_per_volt must be finite and non-zero, got "
                                     f"{volts_per_volt}")
        self.device, self.subdevice, self.range_index = device, int(subdevice), int(range_index)
        self.scale = float(volts_per_volt)
        self._lib = load_comedilib() if lib is None else lib
        self._data = ctypes.c_uint(0)
        self._data_ptr = ctypes.pointer(self._data)     # reused by every read
        self.volts = [math.nan] * 3
        try:
            self._dev = comedi_open_device(self._lib, device, "analog-input card")
        except BaseException:
            self._closed = True
            raise
        try:
            self._ranges = [self._probe(ch) for ch in self.channels]
        except BaseException:
            self._lib.comedi_close(self._dev)
            self._closed = True
            raise

    def _probe(self, channel: int) -> tuple[float, float, int]:
        lib, dev, sub = self._lib, self._dev, self.subdevice
        n = lib.comedi_get_n_channels(dev, sub)
        if not 0 <= channel < n:
            raise ConfigurationError(
                f"{self.device} subdevice {sub} has {max(n, 0)} inputs; no input {channel}")
        maxdata = int(lib.comedi_get_maxdata(dev, sub, channel))
        rng = lib.comedi_get_range(dev, sub, channel, self.range_index)
        if not rng or maxdata <= 0 or rng.contents.unit != UNIT_VOLT:
            raise ConfigurationError(
                f"{self.device} subdevice {sub} input {channel} has no voltage range "
                f"{self.range_index}: {comedi_error_text(lib)}")
        return float(rng.contents.min), float(rng.contents.max), maxdata

    def read_volts(self) -> list[float]:
        """The three amplifier inputs (V), written into ``self.volts`` and returned."""
        self._check_open()
        lib, dev, sub = self._lib, self._dev, self.subdevice
        for i, ch in enumerate(self.channels):
            if lib.comedi_data_read(dev, sub, ch, self.range_index, AREF_GROUND,
                                    self._data_ptr) < 0:
                raise HardwareError(f"comedi_data_read on {self.device} input {ch} failed: "
                                    f"{comedi_error_text(lib)}")
            lo, hi, maxdata = self._ranges[i]
            self.volts[i] = self.scale * code_to_volts(self._data.value, lo, hi, maxdata)
        return self.volts

    def _close(self) -> None:
        self._lib.comedi_close(self._dev)
