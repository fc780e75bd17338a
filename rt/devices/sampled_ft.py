"""A force/torque sensor read by polling the device's latest sample (the twin in-process, the
rig over shared memory): software bias, and staleness from a sample counter that stopped."""
from __future__ import annotations

import abc
import math
from collections.abc import Sequence

import numpy as np

from rt.ati.rdt import STATUS_ANY_ERROR
from rt.devices.interfaces import ForceTorqueSensor, Wrench


class SampledForceTorque(ForceTorqueSensor):
    """Subclasses give ``_sample()`` → (wrench N/N·m, sample counter, status, time s) or
    ``None`` when there is no sample; ``stale`` is set when the counter has not advanced for
    ``timeout_s`` (s, on the sample's time base)."""

    def __init__(self, timeout_s: float = 0.05):
        self.timeout_s = timeout_s
        self._streaming = False
        self._bias = np.zeros(6)
        self._last_seq = -1
        self._last_new_t = -math.inf

    @abc.abstractmethod
    def _sample(self) -> tuple[Sequence[float], int, int, float] | None:
        """The device's latest sample, refreshed."""

    def start(self) -> None:
        self._check_open()
        self._streaming = True

    def stop(self) -> None:
        self._streaming = False

    def bias(self) -> None:
        """Software bias: subtract the current reading from later ones."""
        self._check_open()
        sample = self._sample()
        if sample is not None:
            self._bias[:] = sample[0]

    def read(self, out: Wrench) -> Wrench:
        self._check_open()
        sample = self._sample()
        if not self._streaming or sample is None:
            out.stale = True
            return out
        w, seq, status, t = sample
        if seq != self._last_seq:
            self._last_seq = seq
            self._last_new_t = t
        b = self._bias
        out.fx, out.fy, out.fz = float(w[0] - b[0]), float(w[1] - b[1]), float(w[2] - b[2])
        out.tx, out.ty, out.tz = float(w[3] - b[3]), float(w[4] - b[4]), float(w[5] - b[5])
        out.t = t
        out.sequence = seq
        out.status = status
        out.saturated = bool(status & STATUS_ANY_ERROR)
        out.stale = (t - self._last_new_t) > self.timeout_s
        return out

    def _close(self) -> None:
        self._streaming = False
