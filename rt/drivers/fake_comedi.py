"""A comedilib double for the PCI-1720: the same function names, arguments and return
conventions as the C library, so the real driver code path (volts -> 12-bit codes) runs in tests
and in the digital twin without a card."""
from __future__ import annotations

import ctypes

from rt.drivers.pci1720 import ComediRange


class FakeComedi:
    """comedilib's functions with the same names, arguments and return conventions, for a
    PCI-1720 (adv_pci1720: subdevice 0 = AO, 4 channels, maxdata 4095, ranges 0-5, 0-10,
    ±5, ±10 V) plus an optional digital-output subdevice 2 on the same "device".

    Records ``writes`` as (handle, subdevice, channel, range, aref, code) and ``dio`` as
    (handle, subdevice, channel, bit). ``fail_open`` / ``fail_writes`` inject errors.
    """

    RANGES = ((0.0, 5.0), (0.0, 10.0), (-5.0, 5.0), (-10.0, 10.0))

    def __init__(self, keep_log: bool = True) -> None:
        # The twin keeps no log (it runs for hours); tests keep every write.
        self.keep_log = keep_log
        self.last_code: dict[int, int] = {}
        self.writes: list[tuple] = []
        self.dio: list[tuple] = []
        self.dio_config: list[tuple] = []
        self.opened: list[object] = []
        self.closed: list[object] = []
        self.fail_open = False
        self.fail_writes = False
        self._errno = 0
        # comedi_get_range returns a pointer valid until close; keep the structures alive.
        self._ranges = [ComediRange(lo, hi, 0) for lo, hi in self.RANGES]

    def comedi_open(self, path: bytes):
        assert isinstance(path, bytes)
        if self.fail_open:
            self._errno = 2
            return None                                # NULL
        handle = object()
        self.opened.append((path, handle))
        return handle

    def comedi_close(self, handle) -> int:
        self.closed.append(handle)
        return 0

    def comedi_get_n_channels(self, handle, subdevice: int) -> int:
        return {0: 4, 2: 8}.get(subdevice, -1)

    def comedi_get_maxdata(self, handle, subdevice: int, channel: int) -> int:
        return 4095 if subdevice == 0 else 1

    def comedi_get_range(self, handle, subdevice: int, channel: int, rng: int):
        if subdevice != 0 or not 0 <= rng < len(self._ranges):
            return ctypes.POINTER(ComediRange)()       # NULL
        return ctypes.pointer(self._ranges[rng])

    def comedi_data_write(self, handle, subdevice, channel, rng, aref, data) -> int:
        if self.fail_writes:
            self._errno = 5
            return -1
        if not 0 <= data <= 4095:
            self._errno = 22
            return -1
        if subdevice == 0:
            self.last_code[channel] = data
        if self.keep_log:
            self.writes.append((handle, subdevice, channel, rng, aref, data))
        return 1

    def comedi_dio_config(self, handle, subdevice, channel, direction) -> int:
        if subdevice != 2:
            self._errno = 22
            return -1
        self.dio_config.append((handle, subdevice, channel, direction))
        return 1

    def comedi_dio_write(self, handle, subdevice, channel, bit) -> int:
        self.dio.append((handle, subdevice, channel, bit))
        return 1

    def comedi_errno(self) -> int:
        return self._errno

    def comedi_strerror(self, errnum: int) -> bytes:
        return f"fake comedi error {errnum}".encode()

    def codes(self, n: int = 3) -> list[int]:
        """The last code written to each of channels 0..n-1."""
        return [self.last_code.get(c) for c in range(n)]
