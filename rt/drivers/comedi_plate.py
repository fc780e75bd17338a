"""A force plate's analog outputs read through comedilib (the plate's amplifier → a DAQ card).

The plate's own electronics (AMTI/Bertec amplifiers, Kistler charge amplifiers) give ±10 V (or
±5 V) per channel; an analog-input card digitizes them. ``read_channels`` reads every channel
once with ``comedi_data_read`` (software-timed, one conversion per channel) and converts the
codes to volts with the range's limits, as ``comedi_to_phys`` does:
``V = min + code / maxdata (max - min)``. A calibration campaign records the plate at its
sample rate by calling it from a non-real-time thread at that rate, with the host's clock
stamped on every scan (the plate's clock as far as the fit is concerned).

comedilib reference (``comedi_data_read(3)``): ``int comedi_data_read(comedi_t *, unsigned
subdevice, unsigned chan, unsigned range, unsigned aref, lsampl_t *data)`` returns 1 on success,
-1 on error (``comedi_errno``). ``AREF_DIFF = 2`` (``comedi.h``): plate amplifiers are read
differentially.
"""
from __future__ import annotations

import ctypes
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from rt.devices.interfaces import ForcePlate
from rt.drivers.pci1720 import load_comedilib
from rt.errors import ConfigurationError, HardwareError

AREF_GROUND = 0
AREF_DIFF = 2


@dataclass(frozen=True)
class _Input:
    number: int
    v_min: float
    v_max: float
    maxdata: int


class ComediForcePlate(ForcePlate):
    """Raw plate channels (V) from a comedi analog-input subdevice.

    Parameters: ``device`` (comedi device file), ``subdevice`` (the AI subdevice), ``channels``
    (one AI channel per plate channel, in the plate description's order), ``range_index``
    (comedi range; must be in volts), ``aref`` (``AREF_DIFF`` by default), ``lib`` (comedilib
    or a double with the same functions; ``None`` loads the real library).

    ``read_channels(out)`` fills ``out`` (len = number of channels) with volts; a failed
    conversion raises ``HardwareError`` naming the channel and comedi's message, and a code at
    either end of the range sets ``saturated`` (the plate's amplifier is clipping).
    """

    def __init__(self, device: str = "/dev/comedi1", subdevice: int = 0,
                 channels: Sequence[int] = (0, 1, 2, 3, 4, 5), range_index: int = 0,
                 aref: int = AREF_DIFF, lib: Any = None) -> None:
        numbers = tuple(int(c) for c in channels)
        if not numbers or len(set(numbers)) != len(numbers):
            raise ConfigurationError(f"channels must name distinct AI channels, got {numbers}")
        self.device = device
        self.subdevice = int(subdevice)
        self.range_index = int(range_index)
        self.aref = int(aref)
        self.n_channels = len(numbers)
        self.saturated = False
        self._lib = load_comedilib() if lib is None else lib
        self._word = ctypes.c_uint(0)
        self._dev = self._lib.comedi_open(device.encode())
        if not self._dev:
            raise HardwareError(f"{device}: cannot open: {self._error()}")
        try:
            available = self._lib.comedi_get_n_channels(self._dev, self.subdevice)
            if available < 0:
                raise ConfigurationError(f"{device}: subdevice {self.subdevice} does not exist")
            self._inputs = tuple(self._probe(n, available) for n in numbers)
        except BaseException:
            self._lib.comedi_close(self._dev)
            self._dev = None
            raise

    def _error(self) -> str:
        return self._lib.comedi_strerror(self._lib.comedi_errno()).decode(errors="replace")

    def _probe(self, number: int, available: int) -> _Input:
        if not 0 <= number < available:
            raise ConfigurationError(f"{self.device}: AI channel {number} does not exist "
                                     f"(subdevice {self.subdevice} has {available})")
        rng = self._lib.comedi_get_range(self._dev, self.subdevice, number, self.range_index)
        if not rng:
            raise ConfigurationError(f"{self.device}: range {self.range_index} does not exist "
                                     f"on AI channel {number}")
        maxdata = int(self._lib.comedi_get_maxdata(self._dev, self.subdevice, number))
        return _Input(number, float(rng.contents.min), float(rng.contents.max), maxdata)

    def read_channels(self, out: np.ndarray) -> np.ndarray:
        self._check_open()
        saturated = False
        for k, ch in enumerate(self._inputs):
            ok = self._lib.comedi_data_read(self._dev, self.subdevice, ch.number,
                                            self.range_index, self.aref,
                                            ctypes.byref(self._word))
            if ok < 0:
                raise HardwareError(f"{self.device}: AI channel {ch.number}: read failed: "
                                    f"{self._error()}")
            code = int(self._word.value)
            saturated |= code <= 0 or code >= ch.maxdata
            out[k] = ch.v_min + code / ch.maxdata * (ch.v_max - ch.v_min)
        self.saturated = saturated
        return out

    def _close(self) -> None:
        if self._dev is not None:
            self._lib.comedi_close(self._dev)
            self._dev = None
