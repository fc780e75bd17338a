"""A comedilib double for a 16-bit analog-input card (Advantech PCI-1716-like: subdevice 0 =
AI, 16 channels, maxdata 65535, ranges 0: ±10 V, 1: ±5 V), so the force plate's DAQ path
(volts → codes → volts) runs in tests without a card. Tests set ``volts[channel]``;
``fail_reads`` injects a read error, ``fail_open`` an open error."""
from __future__ import annotations

import ctypes
import math

from rt.drivers.pci1720 import ComediRange


class FakeComediAnalogInput:
    RANGES = ((-10.0, 10.0), (-5.0, 5.0))
    N_CHANNELS = 16
    MAXDATA = 65535

    def __init__(self) -> None:
        self.volts: dict[int, float] = {}
        self.reads: list[tuple] = []
        self.opened: list[bytes] = []
        self.closed = 0
        self.fail_open = False
        self.fail_reads = False
        self._errno = 0
        self._ranges = [ComediRange(lo, hi, 0) for lo, hi in self.RANGES]

    def comedi_open(self, path: bytes):
        assert isinstance(path, bytes)
        if self.fail_open:
            self._errno = 2
            return None
        self.opened.append(path)
        return object()

    def comedi_close(self, handle) -> int:
        self.closed += 1
        return 0

    def comedi_get_n_channels(self, handle, subdevice: int) -> int:
        return self.N_CHANNELS if subdevice == 0 else -1

    def comedi_get_maxdata(self, handle, subdevice: int, channel: int) -> int:
        return self.MAXDATA

    def comedi_get_range(self, handle, subdevice: int, channel: int, rng: int):
        if subdevice != 0 or not 0 <= rng < len(self._ranges):
            return ctypes.POINTER(ComediRange)()
        return ctypes.pointer(self._ranges[rng])

    def comedi_data_read(self, handle, subdevice, channel, rng, aref, data_ptr) -> int:
        if self.fail_reads or subdevice != 0:
            self._errno = 5
            return -1
        lo, hi = self.RANGES[rng]
        v = self.volts.get(channel, 0.0)
        code = math.floor((v - lo) / (hi - lo) * self.MAXDATA + 0.5)
        code = max(0, min(self.MAXDATA, code))
        ctypes.cast(data_ptr, ctypes.POINTER(ctypes.c_uint))[0] = code
        self.reads.append((subdevice, channel, rng, aref))
        return 1

    def comedi_errno(self) -> int:
        return self._errno

    def comedi_strerror(self, errnum: int) -> bytes:
        return f"fake comedi error {errnum}".encode()
