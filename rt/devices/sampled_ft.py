"""A force/torque sensor read by polling the device's latest sample (the twin in-process, the
rig over shared memory): software bias, and staleness from a sample counter that stopped."""
from __future__ import annotations

import abc
import math
from collections.abc import Sequence

import numpy as np
from numba import njit

from rt.ati.rdt import STATUS_ANY_ERROR
from rt.devices.interfaces import (
    FT_READ_SIZE,
    FT_SATURATED,
    FT_SEQUENCE,
    FT_STALE,
    FT_STATUS,
    FT_T,
    ForceTorqueSensor,
    Wrench,
)
from rt.epoch import bump

# The polled sensor's own state (float64[9]): last sample counter (integers are exact in
# float64), the time it last changed (s), the stale timeout (s), the software bias (6).
_LAST_SEQ, _LAST_NEW_T, _TIMEOUT, _BIAS, _ST_SIZE = 0, 1, 2, 3, 9


@njit(cache=True)
def _read_sample(w, seq, status, t, st, out):
    """:meth:`SampledForceTorque.read`'s arithmetic on a fresh sample into ``out`` (layout
    ``FT_*``): the wrench minus the software bias, the sample's time, counter and status,
    saturated from the status word, stale when the counter has not moved for the timeout."""
    if seq != st[_LAST_SEQ]:
        st[_LAST_SEQ] = seq
        st[_LAST_NEW_T] = t
    for k in range(6):
        out[k] = w[k] - st[_BIAS + k]
    out[FT_T] = t
    out[FT_SEQUENCE] = seq
    out[FT_STATUS] = status
    out[FT_SATURATED] = 1.0 if (status & STATUS_ANY_ERROR) != 0 else 0.0
    out[FT_STALE] = 1.0 if (t - st[_LAST_NEW_T]) > st[_TIMEOUT] else 0.0


class SampledForceTorque(ForceTorqueSensor):
    """Subclasses give ``_sample()`` → (wrench N/N·m, sample counter, status, time s) or
    ``None`` when there is no sample; ``stale`` is set when the counter has not advanced for
    ``timeout_s`` (s, on the sample's time base)."""

    def __init__(self, timeout_s: float = 0.05):
        self._streaming = False
        self._st = np.zeros(_ST_SIZE)
        self._st[:3] = (-1.0, -math.inf, timeout_s)
        self._bias = self._st[_BIAS:_BIAS + 6]
        # Compile (or load from numba's cache) now, not in a cycle: the wrench as an array
        # (shared memory) and as a tuple of floats (the twin's sample).
        scratch = np.zeros(FT_READ_SIZE)
        for w in (np.zeros(6), (0.0,) * 6):
            _read_sample(w, 0, 0, 0.0, self._st.copy(), scratch)

    @property
    def timeout_s(self) -> float:
        return float(self._st[_TIMEOUT])

    @timeout_s.setter
    def timeout_s(self, value: float) -> None:
        self._st[_TIMEOUT] = value

    @property
    def _last_seq(self) -> int:
        return int(self._st[_LAST_SEQ])

    @_last_seq.setter
    def _last_seq(self, value: int) -> None:
        self._st[_LAST_SEQ] = value

    @property
    def _last_new_t(self) -> float:
        return float(self._st[_LAST_NEW_T])

    @_last_new_t.setter
    def _last_new_t(self, value: float) -> None:
        self._st[_LAST_NEW_T] = value

    @abc.abstractmethod
    def _sample(self) -> tuple[Sequence[float], int, int, float] | None:
        """The device's latest sample, refreshed."""

    def start(self) -> None:
        self._check_open()
        self._streaming = True
        bump()

    def stop(self) -> None:
        self._streaming = False
        bump()

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

    def read_array(self, out: np.ndarray) -> np.ndarray:
        """:meth:`read` into the loop's array (layout ``FT_*``): one compiled call on the
        device's sample; the same values and the same shared state as :meth:`read`."""
        self._check_open()
        sample = self._sample()
        if not self._streaming or sample is None:
            out[FT_STALE] = 1.0
            return out
        w, seq, status, t = sample
        _read_sample(w, seq, status, t, self._st, out)
        return out

    def _close(self) -> None:
        self._streaming = False
