"""The twin as a hardware backend ("sim"): the same device interfaces as the real rig.

Every backend shares one ``Twin`` and calls ``twin.sync()`` before it reads, so the physics
advances in lockstep with the clock given to the twin. The encoder and DAC backends run the
real drivers (``Pcl833Encoders``, ``Pci1720Outputs``) against the twin's register-level fakes.
"""
from __future__ import annotations

import math

import numpy as np

from rt.ati.rdt import STATUS_ANY_ERROR
from rt.devices.interfaces import (ActuatorOutputs, DigitalInputs, DigitalInputState,
                                   EncoderBank, ForceTorqueSensor, Wrench)
from rt.drivers.pci1720 import Pci1720Outputs
from rt.drivers.pcl833 import Pcl833Encoders, decode_counts
from rt.errors import HardwareError
from rt.twin.twin import Twin


class TwinEncoders(EncoderBank):
    """The PCL-833 driver reading the twin's emulated card (homed: positions are absolute)."""

    def __init__(self, twin: Twin):
        self.twin = twin
        self._driver = Pcl833Encoders(port_io=twin.encoder_port, m_per_count=twin.m_per_count)
        twin.home_encoders()

    def read_counts(self) -> tuple[int, ...]:
        self._check_open()
        self.twin.sync()
        delayed, _ = self.twin.delayed()
        return delayed if delayed is not None else self._driver.read_counts()

    def read_positions_m(self, out: np.ndarray) -> np.ndarray:
        self._check_open()
        self.twin.sync()
        delayed, _ = self.twin.delayed()
        if delayed is None:
            return self._driver.read_positions_m(out)
        for i, count in enumerate(delayed):
            out[i] = decode_counts(count, m_per_count=self.twin.m_per_count)
        return out

    def reset(self) -> None:
        self._driver.reset()

    def _close(self) -> None:
        self._driver.close()


class TwinActuators(ActuatorOutputs):
    """One of the twin's two PCI-1720 cards (``card`` 0 or 1), through the real driver."""

    def __init__(self, twin: Twin, card: int = 0, limit_v: float | None = None):
        if card not in (0, 1):
            raise HardwareError(f"the twin has DAC cards 0 and 1, not {card}")
        self.twin = twin
        self.card = card
        limit = twin.command_limit_v if limit_v is None else limit_v
        self._driver = Pci1720Outputs(device=f"/dev/comedi{card}", lib=twin.dac_libs[card],
                                      limit_v=limit)

    def enable(self) -> None:
        self._check_open()
        self._driver.enable()
        self.twin.set_card_enabled(self.card, True)

    def disable(self) -> None:
        if self.closed:
            return
        self._driver.disable()
        self.twin.set_card_enabled(self.card, False)

    @property
    def enabled(self) -> bool:
        return self._driver.enabled

    def write_volts(self, volts) -> None:
        self._check_open()
        self._driver.write_volts(volts)

    @property
    def last_volts(self) -> list[float]:
        """The quantized voltages the last write produced (V)."""
        return list(self._driver.last_volts)

    def _close(self) -> None:
        self.twin.set_card_enabled(self.card, False)
        self._driver.close()


class TwinForceTorque(ForceTorqueSensor):
    """The twin's ATI sensor read in-process (the RDT/CAN servers expose it on the wire).

    ``stale`` is set when the sensor's sample counter has not advanced for ``timeout_s``.
    """

    def __init__(self, twin: Twin, timeout_s: float = 0.05):
        self.twin = twin
        self.timeout_s = timeout_s
        self._streaming = False
        self._bias = np.zeros(6)
        self._last_seq = -1
        self._last_new_t = -math.inf

    def start(self) -> None:
        self._check_open()
        self._streaming = True

    def stop(self) -> None:
        self._streaming = False

    def bias(self) -> None:
        """Software bias: subtract the current reading from later ones."""
        self._check_open()
        self.twin.sync()
        _, sample = self.twin.delayed()
        if sample is not None:
            self._bias[:] = sample.wrench

    def read(self, out: Wrench) -> Wrench:
        self._check_open()
        self.twin.sync()
        t = self.twin.t
        _, sample = self.twin.delayed()
        if not self._streaming or sample is None:
            out.stale = True
            return out
        if sample.ft_sequence != self._last_seq:
            self._last_seq = sample.ft_sequence
            self._last_new_t = t
        w = sample.wrench
        b = self._bias
        out.fx, out.fy, out.fz = w[0] - float(b[0]), w[1] - float(b[1]), w[2] - float(b[2])
        out.tx, out.ty, out.tz = w[3] - float(b[3]), w[4] - float(b[4]), w[5] - float(b[5])
        out.t = t
        out.sequence = sample.ft_sequence
        out.status = sample.status
        out.saturated = bool(sample.status & STATUS_ANY_ERROR)
        out.stale = (t - self._last_new_t) > self.timeout_s
        return out

    def _close(self) -> None:
        self._streaming = False


class TwinDigitalInputs(DigitalInputs):
    """The twin's stop inputs (set by the fault plan: ``hardware_estop``, ``hand_stop``)."""

    def __init__(self, twin: Twin):
        self.twin = twin

    def read(self, out: DigitalInputState) -> DigitalInputState:
        self._check_open()
        self.twin.sync()
        out.hardware_estop = self.twin.inputs.hardware_estop
        out.hand_stop = self.twin.inputs.hand_stop
        return out

    def _close(self) -> None:
        pass


