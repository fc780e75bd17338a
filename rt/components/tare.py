"""Taring the force/torque sensor on an unloaded platform before force work.

The ATI's reading on an unloaded platform is not zero: the tool-side half of the transducer, its
adapter and tip hang on the gauges (≈ 0.4 kg: Fz ≈ −3.9 N at level), and the gauges drift with
temperature (a few N on z over a session). A force protocol that tracks 10-400 N would carry that
offset into every sample. So the session start tares the sensor where the program starts, in
the approach phase, while the foot does not yet load the platform: the mean of
:data:`TARE_SAMPLES` readings becomes the zero, subtracted from every later reading by the loop's
force reader (a software bias, as the Net F/T's own; the device itself is not touched, so a
later tare replaces it and nothing persists in the sensor).

Refusal: a loaded platform must not be tared, or the load would vanish from the readings and
the force law would push that much harder on the foot. The tare is refused when the mean force
magnitude exceeds :data:`TARE_MAX_LOAD_N` (the unloaded reading is the tool's weight plus the
sensor's drift: a few N; a resting foot or a hand on the platform is tens of N), or when the
readings are not steady (standard deviation of any force axis above :data:`TARE_MAX_SIGMA_N`:
someone is touching it; the Delta's noise is 0.25 N on z), or when no reading arrives (stale or
invalid sensor). A refused tare changes nothing (the previous zero stays).
"""
from __future__ import annotations

import math
from enum import IntEnum

import numpy as np
from numba import njit

#: Readings averaged (at 1 kHz: 0.1 s; the mean's noise is σ/10, 0.025 N on z).
TARE_SAMPLES = 100
#: Cycles the tare may wait for valid readings before it is refused (a stale sensor).
TARE_MAX_CYCLES = 500
#: Largest unloaded force magnitude accepted (N): tool weight + drift, with margin.
TARE_MAX_LOAD_N = 20.0
#: Largest per-axis standard deviation of the force over the tare window (N).
TARE_MAX_SIGMA_N = 2.0


class TareState(IntEnum):
    """Where a tare stands (carried as a float on the force reader's ``tare`` port)."""

    NONE = 0        # never tared: readings are the sensor's own
    MEASURING = 1
    DONE = 2
    REFUSED = 3


class TareRefusal(IntEnum):
    """Why a tare was refused (carried as a float beside the state)."""

    NONE = 0
    LOADED = 1
    UNSTEADY = 2
    NO_READING = 3


def refusal_message(code: int, mean_force_n: float) -> str:
    """The reason of a refused tare, from what the force reader's ``tare`` port carries."""
    if code == TareRefusal.LOADED:
        return (f"platform loaded: the force sensor reads {mean_force_n:.1f} N (unloaded at most "
                f"{TARE_MAX_LOAD_N:g} N); unload the platform and start again")
    if code == TareRefusal.UNSTEADY:
        return "force not steady during the tare: something touches the platform"
    return "no valid force reading for the tare (sensor stale or invalid)"


# The tare's numbers in one float64 array (``Tare._buf``), so a cycle is one compiled call
# (:func:`tare_cycle`): state, tares done, valid readings summed, cycles measured, the request
# seen last cycle, samples wanted, cycle budget; then the offset (6), the sums (6) and the sums
# of squares of the force (3). Integers are exact in float64.
_STATE, _COUNT, _N, _CYCLES, _REQUESTED, _SAMPLES, _MAX_CYCLES = range(7)
_OFFSET, _SUM, _SQ, _BUF_SIZE = 7, 13, 19, 22
_MEASURING = float(TareState.MEASURING)

#: :func:`tare_cycle`'s answer when the measurement ended this cycle (Python finishes it).
TARE_ENDED = 1


@njit(cache=True)
def tare_cycle(wrench, valid, requested, port, buf):
    """One cycle of :meth:`Tare.cycle` on ``buf`` (layout above): a rising edge of
    ``requested`` starts a measurement, a measuring tare adds the reading (when ``valid``),
    the zero is subtracted from ``wrench`` in place and ``port``'s state and count are set.
    Returns :data:`TARE_ENDED`, before subtracting anything, when this reading ended the
    measurement (enough samples, or the cycle budget spent): :meth:`Tare.cycle` then judges
    it in Python (once per tare) and completes the cycle; 0 otherwise."""
    if requested and buf[_REQUESTED] == 0.0:
        for k in range(_SUM, _BUF_SIZE):
            buf[k] = 0.0
        buf[_N] = 0.0
        buf[_CYCLES] = 0.0
        buf[_STATE] = _MEASURING
    buf[_REQUESTED] = 1.0 if requested else 0.0
    if buf[_STATE] == _MEASURING:
        buf[_CYCLES] += 1.0
        if valid:
            for k in range(6):
                buf[_SUM + k] += wrench[k]
            for i in range(3):
                buf[_SQ + i] += wrench[i] * wrench[i]
            buf[_N] += 1.0
        if buf[_N] >= buf[_SAMPLES] or buf[_CYCLES] >= buf[_MAX_CYCLES]:
            return TARE_ENDED
    for k in range(6):
        wrench[k] -= buf[_OFFSET + k]
    port[0] = buf[_STATE]
    port[1] = buf[_COUNT]
    return 0


class Tare:
    """Software zero of a 6-axis wrench; no allocation per sample (the loop's cycle).

    ``offset`` (N, N m) is subtracted by :meth:`apply`; :meth:`start` begins a new measurement,
    :meth:`add` feeds one reading per cycle and returns the state; ``reason`` says why a tare
    was refused, ``mean_force_n`` is the force magnitude the last measurement saw.

    :meth:`cycle` (the loop's) is one compiled call (:func:`tare_cycle`) except in the cycle a
    measurement ends; :meth:`cycle_interpreted` is the same in Python, the reference. Both work
    on the same numbers.
    """

    def __init__(self, samples: int = TARE_SAMPLES, max_load_n: float = TARE_MAX_LOAD_N,
                 max_sigma_n: float = TARE_MAX_SIGMA_N, max_cycles: int = TARE_MAX_CYCLES):
        if samples < 2 or max_cycles < samples:
            raise ValueError(f"tare needs 2 <= samples <= max_cycles, got {samples}, "
                             f"{max_cycles}")
        self._buf = np.zeros(_BUF_SIZE)
        self._buf[_SAMPLES] = samples
        self._buf[_MAX_CYCLES] = max_cycles
        self.samples = samples
        self.max_load_n = max_load_n
        self.max_sigma_n = max_sigma_n
        self.max_cycles = max_cycles
        self.offset = self._buf[_OFFSET:_OFFSET + 6]
        self._sum = self._buf[_SUM:_SUM + 6]
        self._sq = self._buf[_SQ:_SQ + 3]
        self.state = TareState.NONE
        self.reason = ""
        self.refusal = TareRefusal.NONE
        self.mean_force_n = math.nan
        # Compile (or load from numba's cache) now, not in the first cycle (on a copy).
        tare_cycle(np.zeros(6), True, False, np.zeros(10), self._buf.copy())

    # The scalar state lives in ``_buf`` (read and written by the compiled cycle too).
    @property
    def state(self) -> TareState:
        return TareState(int(self._buf[_STATE]))

    @state.setter
    def state(self, value: TareState) -> None:
        self._buf[_STATE] = float(value)

    @property
    def count(self) -> int:
        """Completed tares."""
        return int(self._buf[_COUNT])

    @count.setter
    def count(self, value: int) -> None:
        self._buf[_COUNT] = value

    @property
    def _n(self) -> int:
        return int(self._buf[_N])

    @_n.setter
    def _n(self, value: int) -> None:
        self._buf[_N] = value

    @property
    def _cycles(self) -> int:
        return int(self._buf[_CYCLES])

    @_cycles.setter
    def _cycles(self, value: int) -> None:
        self._buf[_CYCLES] = value

    @property
    def _requested(self) -> bool:
        return bool(self._buf[_REQUESTED])

    @_requested.setter
    def _requested(self, value: bool) -> None:
        self._buf[_REQUESTED] = 1.0 if value else 0.0

    def start(self) -> None:
        self._sum[:] = 0.0
        self._sq[:] = 0.0
        self._n = 0
        self._cycles = 0
        self.state = TareState.MEASURING

    def add(self, raw: np.ndarray, valid: bool) -> TareState:
        """One cycle's raw reading (the sensor's own, before this zero); ``valid``: fresh and
        finite. Returns the state after it."""
        if self.state != TareState.MEASURING:
            return self.state
        self._cycles += 1
        if valid:
            self._sum += raw
            sq = self._sq
            for i in range(3):
                sq[i] += raw[i] * raw[i]
            self._n += 1
        self._judge()
        return self.state

    def _judge(self) -> None:
        if self._n >= self.samples:
            self._finish()
        elif self._cycles >= self.max_cycles:
            self._refuse(TareRefusal.NO_READING)

    def _finish(self) -> None:
        n = self._n
        mean = self._sum / n
        var = np.maximum(self._sq / n - mean[:3] * mean[:3], 0.0)
        sigma = float(np.sqrt(var.max()))
        load = float(np.linalg.norm(mean[:3]))
        self.mean_force_n = load
        if load > self.max_load_n:
            self._refuse(TareRefusal.LOADED)
        elif sigma > self.max_sigma_n:
            self._refuse(TareRefusal.UNSTEADY)
        else:
            self.offset[:] = mean
            self.reason = ""
            self.refusal = TareRefusal.NONE
            self.count += 1
            self.state = TareState.DONE

    def _refuse(self, code: TareRefusal) -> None:
        # The message is built only on refusal (never in a normal cycle).
        self.refusal = code
        self.reason = refusal_message(code, self.mean_force_n)
        self.state = TareState.REFUSED

    def cycle(self, wrench: np.ndarray, valid: bool, requested: bool,
              port: np.ndarray) -> None:
        """One loop cycle of the force reader: a rising edge of ``requested`` starts a tare,
        ``wrench`` (the raw reading) feeds it, then the zero is subtracted from ``wrench`` in
        place; ``port`` (float64[10]) gets [state, tares done, refusal, mean force magnitude
        (N), offset (6)] — what the sequencer reads. One compiled call
        (:func:`tare_cycle`), and Python only in the cycle a measurement ends."""
        if tare_cycle(wrench, valid, requested, port, self._buf) == TARE_ENDED:
            self._end_cycle(wrench, port)

    def _end_cycle(self, wrench: np.ndarray, port: np.ndarray) -> None:
        """The rest of a cycle whose reading ended the measurement (already added)."""
        self._judge()
        self._report(port)
        self.apply(wrench)
        port[0] = float(self.state)
        port[1] = float(self.count)

    def _report(self, port: np.ndarray) -> None:
        port[2] = float(self.refusal)
        port[3] = self.mean_force_n
        port[4:] = self.offset

    def cycle_interpreted(self, wrench: np.ndarray, valid: bool, requested: bool,
                          port: np.ndarray) -> None:
        """:meth:`cycle` in Python (the reference of ``tests/test_device_compiled.py``)."""
        if requested and not self._requested:
            self.start()
        self._requested = requested
        if self.state == TareState.MEASURING and self.add(wrench, valid) != TareState.MEASURING:
            self._report(port)
        self.apply(wrench)
        port[0] = float(self.state)
        port[1] = float(self.count)

    def apply(self, wrench: np.ndarray) -> None:
        """Subtract the zero in place (NaN readings stay NaN)."""
        wrench -= self.offset
