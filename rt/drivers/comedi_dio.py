"""Hardware stop inputs (e-stop chain, patient's hand-held stop) on a comedi digital input.

The thesis rig's cards give no usable input: the PCI-1720's only digital input is its 4-bit
BoardID switch (comedi ``adv_pci1720`` subdevice 1) and the PCL-833's DI1 is an interrupt
source. So the rig is assumed to carry an isolated digital I/O card that comedi drives (an
Advantech PCI-1730/PCI-1756 through ``adv_pci_dio``, or any 8255-type port), with:

* the **hardware e-stop chain** wired to one input, the **hand-held stop** to another;
* both wired **normally closed**: the contact holds the input at ``healthy_level`` (1 by
  default) while nobody presses; pressing, a cut wire or an unpowered chain reads the other
  level, i.e. *pressed* (fail-safe, IEC 60204-1 §10.7);
* the same card's outputs as the drive-enable lines of the two PCI-1720 cards (see
  ``rt.drivers.pci1720.EnableLine``), since the PCI-1720 has no digital output.

The hardware chain cuts the amplifiers' power by itself; reading it here lets the supervisor
latch a hard stop with its cause and keep the drives disabled until an explicit reset.

comedilib calls used: ``comedi_open``, ``comedi_get_n_channels``, ``comedi_dio_config(dev,
sub, chan, COMEDI_INPUT)`` and ``comedi_dio_read(dev, sub, chan, unsigned int *bit)`` (1 on
success, -1 on error), ``comedi_close``. A failed read reports both stops pressed: an input
the loop cannot see is treated as a stop.
"""
from __future__ import annotations

import ctypes
from typing import Any

from rt.devices.interfaces import DigitalInputs, DigitalInputState
from rt.drivers.pci1720 import (COMEDI_INPUT, comedi_error_text, comedi_open_device,
                                load_comedilib)
from rt.errors import ConfigurationError


class ComediDigitalInputs(DigitalInputs):
    """The rig's stop inputs read from a comedi digital-I/O subdevice.

    Parameters (fixed after construction): ``device`` (comedi device file), ``subdevice`` (a
    DIO or DI subdevice), ``estop_channel`` and ``hand_stop_channel`` (its lines),
    ``healthy_level`` (the level a closed, unpressed contact gives: 1 or 0), ``lib`` (comedilib
    or a double with its functions; ``None`` loads the library).

    ``read_failures`` counts reads that failed (each reported as both stops pressed).
    """

    def __init__(self, device: str = "/dev/comedi2", subdevice: int = 0,
                 estop_channel: int = 0, hand_stop_channel: int = 1, healthy_level: int = 1,
                 lib: Any = None) -> None:
        if healthy_level not in (0, 1):
            raise ConfigurationError(f"healthy_level must be 0 or 1, got {healthy_level}")
        if estop_channel == hand_stop_channel:
            raise ConfigurationError("the e-stop and the hand-held stop need distinct inputs")
        self.device = device
        self.subdevice = int(subdevice)
        self.channels = (int(estop_channel), int(hand_stop_channel))
        self.healthy_level = healthy_level
        self.read_failures = 0
        self._lib = load_comedilib() if lib is None else lib
        self._bit = ctypes.c_uint(0)
        self._bit_ptr = ctypes.pointer(self._bit)      # allocated once, reused every read
        try:
            self._dev = comedi_open_device(self._lib, device, "stop-input card")
        except BaseException:
            self._closed = True
            raise
        try:
            n = self._lib.comedi_get_n_channels(self._dev, self.subdevice)
            for ch in self.channels:
                if not 0 <= ch < n:
                    raise ConfigurationError(
                        f"{device} subdevice {self.subdevice} has {max(n, 0)} lines; no line "
                        f"{ch}")
                if self._lib.comedi_dio_config(self._dev, self.subdevice, ch, COMEDI_INPUT) < 0:
                    raise ConfigurationError(
                        f"cannot make {device} subdevice {self.subdevice} line {ch} an input: "
                        f"{comedi_error_text(self._lib)}")
        except BaseException:
            self._lib.comedi_close(self._dev)
            self._closed = True
            raise

    def _pressed(self, channel: int) -> bool:
        if self._lib.comedi_dio_read(self._dev, self.subdevice, channel, self._bit_ptr) < 0:
            self.read_failures += 1
            return True
        return self._bit.value != self.healthy_level

    def read(self, out: DigitalInputState) -> DigitalInputState:
        self._check_open()
        out.hardware_estop = self._pressed(self.channels[0])
        out.hand_stop = self._pressed(self.channels[1])
        return out

    def _close(self) -> None:
        self._lib.comedi_close(self._dev)
