"""The twin as a hardware backend ("sim"): the same device interfaces as the real rig.

Every backend shares one ``Twin`` and calls ``twin.sync()`` before it reads, so the physics
advances in lockstep with the clock given to the twin. The encoder and DAC backends run the
real drivers (``Pcl833Encoders``, ``Pci1720Outputs``) against the twin's register-level fakes.
"""
from __future__ import annotations

import numpy as np

from rt.devices.interfaces import (
    ActuatorOutputs,
    DigitalInputs,
    DigitalInputState,
    EncoderBank,
    WatchReplaced,
    replaced,
)
from rt.devices.sampled_ft import SampledForceTorque
from rt.drivers.pci1720 import Pci1720Outputs
from rt.drivers.pcl833 import Pcl833Encoders, decode_counts
from rt.errors import HardwareError
from rt.twin.kernels import ATI_PENDING as _ATI_PENDING
from rt.twin.twin import Twin

# The methods each block calls on its backend (and what they call): replaced on an instance,
# the compiled hooks step aside (``rt.devices.interfaces.replaced``), and the assignment bumps
# ``rt.epoch`` (``WatchReplaced``: the fused cycle's fast path leaves at its next cycle).
ENCODER_READS = ("read_positions_m", "read_counts")
FT_READS = ("read_array", "read", "_sample")
INPUT_READS = ("read_array", "read")
ACTUATOR_WRITES = ("write_volts",)


class TwinEncoders(WatchReplaced, EncoderBank):
    """The PCL-833 driver reading the twin's emulated card (homed: positions are absolute)."""

    REPLACEABLE = frozenset(ENCODER_READS)

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
        twin = self.twin
        twin.sync()
        if not twin.faults.faults:                  # no latency fault: the card as it is
            return self._driver.read_positions_m(out)
        delayed, _ = twin.delayed()
        if delayed is None:
            return self._driver.read_positions_m(out)
        for i, count in enumerate(delayed):
            out[i] = decode_counts(count, m_per_count=self.twin.m_per_count)
        return out

    def compiled_read(self) -> tuple | None:
        """The driver's arrays on the emulated card (``Pcl833Encoders.compiled_read``), the
        twin synced as :meth:`read_positions_m` syncs it; None under a fault (a latency fault
        delays the counts: the block decodes them), once closed, or when the read was
        replaced on the bank or its driver (:func:`replaced`)."""
        if self._closed or replaced(self, *ENCODER_READS) \
                or replaced(self._driver, "read_positions_m"):
            return None
        twin = self.twin
        twin.sync()
        if twin.faults.faults:
            return None
        return self._driver.compiled_read()

    def reset(self) -> None:
        self._driver.reset()

    def _close(self) -> None:
        self._driver.close()


class TwinActuators(WatchReplaced, ActuatorOutputs):
    """One of the twin's two PCI-1720 cards (``card`` 0 or 1), through the real driver."""

    REPLACEABLE = frozenset(ACTUATOR_WRITES)

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

    def compiled_write(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, int] | None:
        """The driver's compiled write on the twin's comedilib double
        (``Pci1720Outputs.compiled_write``); None once closed or when the write was replaced
        on the card or its driver (:func:`replaced`)."""
        if self._closed or replaced(self, *ACTUATOR_WRITES) \
                or replaced(self._driver, "write_volts"):
            return None
        return self._driver.compiled_write()

    def finish_compiled_write(self, volts: np.ndarray, rc: int, done: int) -> None:
        self._driver.finish_compiled_write(volts, rc, done)

    def _close(self) -> None:
        self.twin.set_card_enabled(self.card, False)
        self._driver.close()


class TwinForceTorque(WatchReplaced, SampledForceTorque):
    """The twin's ATI sensor read in-process (the RDT/CAN servers expose it on the wire).

    ``stale`` is set when the sensor's sample counter has not advanced for ``timeout_s``.
    """

    REPLACEABLE = frozenset(FT_READS)

    def __init__(self, twin: Twin, timeout_s: float = 0.05):
        super().__init__(timeout_s)
        self.twin = twin

    def compiled_sample(self) -> tuple | None:
        """The twin's latest sample where its fused period left it (``Twin.latest_ati``: the
        ATI model's packed wrench, counter and status, ``ATI_OUT:ATI_STATUS + 1``), the twin
        synced as :meth:`_sample` syncs it; None under a fault, before the first sample,
        when not streaming, once closed, or when a read was replaced (:func:`replaced`): the
        block reads it then."""
        if self._closed or not self._streaming or replaced(self, *FT_READS):
            return None
        twin = self.twin
        twin.sync()
        ati = twin.ati
        if twin.faults.faults or ati._packed[_ATI_PENDING] == 0.0:
            return None
        return ati._sample_view, self._st, twin.t

    def _sample(self):
        twin = self.twin
        twin.sync()
        if not twin.faults.faults:
            # No latency fault: the latest sample, read where the twin's period left it
            # (no ``AtiSample`` built every cycle; the same numbers).
            latest = twin.latest_ati()
            if latest is None:
                return None
            return latest[0], latest[1], latest[2], twin.t
        _, sample = twin.delayed()
        if sample is None:
            return None
        return sample.wrench, sample.ft_sequence, sample.status, twin.t


class TwinDigitalInputs(WatchReplaced, DigitalInputs):
    """The twin's stop inputs (set by the fault plan: ``hardware_estop``, ``hand_stop``)."""

    REPLACEABLE = frozenset(INPUT_READS)

    def __init__(self, twin: Twin):
        self.twin = twin

    def read(self, out: DigitalInputState) -> DigitalInputState:
        self._check_open()
        self.twin.sync()
        out.hardware_estop = self.twin.inputs.hardware_estop
        out.hand_stop = self.twin.inputs.hand_stop
        return out

    def compiled_levels(self) -> tuple[float, float] | None:
        if self._closed or replaced(self, *INPUT_READS):
            return None
        self.twin.sync()
        inputs = self.twin.inputs
        return (1.0 if inputs.hardware_estop else 0.0, 1.0 if inputs.hand_stop else 0.0)

    def read_array(self, out: np.ndarray) -> np.ndarray:
        self._check_open()
        self.twin.sync()
        inputs = self.twin.inputs
        out[0] = 1.0 if inputs.hardware_estop else 0.0
        out[1] = 1.0 if inputs.hand_stop else 0.0
        return out

    def _close(self) -> None:
        pass


