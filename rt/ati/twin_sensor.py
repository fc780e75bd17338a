"""The twin's ATI force/torque sensor: physics, faults, and the device-side sample plumbing.

``TwinAtiSensorModel`` turns the true wrench acting on the sensor into what an ATI Net F/T
would report: constant bias, slow drift, Gaussian noise, per-axis overload (clipped value and
status bits) and injectable faults. ``SourceReader`` is the piece of "firmware" shared by the
twin's RDT server and CAN responder: it pulls samples from a ``WrenchSource``, numbers them
and applies the software bias the way the device does.

Units: forces in N, torques in N m, time in s, all in the sensor frame S.
"""
from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numba import njit

from rt.ati.rdt import STATUS_ANY_ERROR, STATUS_FT_OUT_OF_RANGE, STATUS_GAGE_OUT_OF_RANGE
from rt.errors import InputError

Wrench6 = tuple[float, float, float, float, float, float]

_BLOCK = 1024
#: Samples a software bias averages (talus choice; the manual does not say how many the device
#: uses): the bias's noise is σ/4, in 16 ms at 1 kHz.
BIAS_SAMPLES = 16

#: Fault switches of the twin sensor.
#: ``dropout``: no new samples (servers send nothing while it is on);
#: ``stale``: the previous sample is repeated with the same ft_sequence;
#: ``saturate``: the gage-saturation status flag is raised (values are passed through).
FAULTS: tuple[str, ...] = ("dropout", "stale", "saturate")

#: Measuring ranges of an ATI Delta SI-660-60 (N, N, N, N m, N m, N m).
DELTA_SI_660_60_RANGES: Wrench6 = (660.0, 660.0, 1980.0, 60.0, 60.0, 60.0)


class AtiSample(NamedTuple):
    """One sensor sample: measured ``wrench`` (N, N m), raw ``status`` word, ``ft_sequence``.

    A NamedTuple, so it is also a valid 3-tuple return value of a ``WrenchSource``.
    """

    wrench: Wrench6
    status: int
    ft_sequence: int


#: What a ``WrenchSource`` may return: ``None`` when no new sample exists (dropout),
#: ``(wrench6, status)`` (the server numbers the samples) or ``(wrench6, status, ft_sequence)``
#: (the source numbers them; a repeated ft_sequence marks a stale sample).
SourceResult = tuple[Sequence[float], int] | tuple[Sequence[float], int, int] | None
#: Zero-argument callable giving the sensor's current sample; called from the server thread.
WrenchSource = Callable[[], SourceResult]


def _constantly(value: tuple[float, ...]) -> Callable[[], tuple[float, ...]]:
    return lambda: value


def _as6(name: str, values: Sequence[float]) -> Wrench6:
    if len(values) != 6:
        raise InputError(f"{name} needs 6 values (Fx Fy Fz Tx Ty Tz), got {len(values)}")
    out = tuple(float(v) for v in values)
    if not all(math.isfinite(v) for v in out):
        raise InputError(f"{name} must be finite, got {out}")
    return out  # type: ignore[return-value]


@dataclass(frozen=True, slots=True)
class AtiSensorParams:
    """Parameters of the twin sensor (per axis Fx, Fy, Fz in N; Tx, Ty, Tz in N m).

    * ``noise_sigma``: standard deviation of white Gaussian noise per sample. Defaults are of the
      order of the Delta SI-660-60 resolution (1/8 N, 1/4 N on z, 7.5 mN m); fit them to a
      recording of the real sensor.
    * ``bias``: constant offset (the unloaded reading before a software bias).
    * ``drift_rate``: intensity of the drift random walk, in units/sqrt(s): after T seconds
      the drift has a standard deviation of about ``drift_rate * sqrt(T)``.
    * ``drift_limit``: bound of the drift (it is clipped to +-limit), so a long run stays
      within what a temperature-drifting strain-gage sensor shows.
    * ``ranges``: measuring range; a larger reading is clipped and flagged (overload).
    """

    noise_sigma: Wrench6 = (0.125, 0.125, 0.25, 0.0075, 0.0075, 0.0075)
    bias: Wrench6 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    drift_rate: Wrench6 = (0.02, 0.02, 0.04, 0.001, 0.001, 0.001)
    drift_limit: Wrench6 = (2.0, 2.0, 4.0, 0.1, 0.1, 0.1)
    ranges: Wrench6 = DELTA_SI_660_60_RANGES

    def __post_init__(self) -> None:
        for name in ("noise_sigma", "bias", "drift_rate", "drift_limit", "ranges"):
            object.__setattr__(self, name, _as6(name, getattr(self, name)))
        for name in ("noise_sigma", "drift_rate", "drift_limit"):
            if any(v < 0.0 for v in getattr(self, name)):
                raise InputError(f"{name} must be >= 0, got {getattr(self, name)}")
        if any(v <= 0.0 for v in self.ranges):
            raise InputError(f"ranges must be > 0, got {self.ranges}")


@dataclass(slots=True)
class _FaultWindow:
    name: str
    t_start: float
    t_end: float | None


@dataclass(slots=True)
class _State:
    """Mutable state, kept apart from parameters so a run can be reset and replayed."""

    rng: np.random.Generator
    drift: list | np.ndarray = field(default_factory=lambda: [0.0] * 6)
    # Standard normals drawn in blocks (one row of 12 per sample: 6 drift, 6 noise); per-sample
    # numpy calls on 6-vectors cost ~10 µs, a block draw amortises to well under 1 µs.
    # The bookkeeping (the next row of ``block``, the last sample's time and counter, a
    # sample committed without its object) lives in the model's packed array (``_A_ROW``,
    # ``_A_T_LAST``, ``_A_SEQ``, ``_A_STATUS``): the twin's compiled period advances it there.
    block: list | np.ndarray = field(default_factory=list)
    last: AtiSample | None = None


#: Offsets of the compiled model's parameter array (6 values each, Fx..Tz).
_P_RATE, _P_LIMIT, _P_BIAS, _P_SIGMA, _P_RANGE = 0, 6, 12, 18, 24
#: The packed array of the model (``rt.twin.kernels`` ``ATI_*`` name the same offsets):
#: parameters, drift, the last compiled sample, then the bookkeeping both paths read and
#: write (issue 16: the last twin state a compiled pre-flight driver needs in arrays).
#: The sample is its wrench, ``_A_SEQ`` its ft_sequence (an exact float, < 2**32) and
#: ``_A_STATUS`` its status word, contiguous (``_A_OUT:_A_SAMPLE_END`` is what a compiled
#: reader takes: ``TwinForceTorque.compiled_sample``). ``_A_PENDING`` is 1.0 while the twin's
#: period committed the sample without building its ``AtiSample`` (built on demand:
#: :meth:`TwinAtiSensorModel.last_sample`), ``_A_ROW`` the next row of the random block,
#: ``_A_T_LAST`` the last sample's time (s; NaN before the first).
(_A_PARAMS, _A_DRIFT, _A_OUT, _A_SEQ, _A_STATUS, _A_PENDING, _A_ROW, _A_T_LAST,
 _A_SIZE) = (0, 30, 36, 42, 43, 44, 45, 46, 47)
#: The wrench's end and the compiled sample's end in the packed array.
_A_OUT_END = _A_OUT + 6
_A_SAMPLE_END = _A_STATUS + 1


@njit(cache=True)
def _measure_kernel(true_wrench, block, row, params, drift, out, dt, overload_bits):
    """``TwinAtiSensorModel.measure``'s arithmetic, compiled: drift from ``block[row, :6]``,
    noise from ``block[row, 6:]``, the same operations in the same order as the interpreted
    loop. Writes the measured wrench to ``out``; returns the overload status bits."""
    if dt > 0.0:
        root_dt = math.sqrt(dt)
        for i in range(6):
            d = drift[i] + params[_P_RATE + i] * root_dt * block[row, i]
            lim = params[_P_LIMIT + i]
            drift[i] = lim if d > lim else (max(d, -lim))
    status = 0
    for i in range(6):
        v = (true_wrench[i] + params[_P_BIAS + i] + drift[i]
             + params[_P_SIGMA + i] * block[row, 6 + i])
        r = params[_P_RANGE + i]
        if v > r or v < -r:
            v = r if v > r else -r
            status |= overload_bits
        out[i] = v
    return status


class TwinAtiSensorModel:
    """The twin's ATI sensor.

    Ports (see ``measure``):
      * input ``true_wrench``: the wrench acting on the sensor, (Fx, Fy, Fz, Tx, Ty, Tz) in N and
        N m, sensor frame S;
      * input ``t``: simulation time (s), non-decreasing;
      * output: ``AtiSample`` (measured wrench, status word, ft_sequence), or ``None`` while the
        ``dropout`` fault is on.

    measured = clip(true + bias + drift(t) + noise, +-ranges). Overload on any axis sets
    ``STATUS_ANY_ERROR | STATUS_FT_OUT_OF_RANGE``; the ``saturate`` fault sets
    ``STATUS_ANY_ERROR | STATUS_GAGE_OUT_OF_RANGE``. ``ft_sequence`` counts new samples.
    Everything random comes from one ``numpy.random.Generator`` seeded by ``seed``, so the same
    seed, inputs and fault schedule give the same samples.

    ``compiled`` (default False) computes each sample with a numba kernel (the twin's
    pre-flight speed, issue 16); the interpreted loop is the reference, and both give the same
    samples from the same seed and inputs (``tests/test_twin_compiled.py``).
    """

    def __init__(self, params: AtiSensorParams | None = None, seed: int = 0,
                 compiled: bool = False) -> None:
        self.params = params if params is not None else AtiSensorParams()
        self.seed = int(seed)
        self.compiled = compiled
        self._manual: dict[str, bool] = {name: False for name in FAULTS}
        # Skips the fault lookups in the per-sample path while no fault was ever switched on.
        self._faults_possible = False
        self._schedule: list[_FaultWindow] = []
        p = self.params
        # Parameters as arrays once, so the per-sample path only does in-place arithmetic.
        self._sigma = tuple(p.noise_sigma)
        self._bias = tuple(p.bias)
        self._drift_rate = tuple(p.drift_rate)
        self._drift_limit = tuple(p.drift_limit)
        self._ranges = tuple(p.ranges)
        # The compiled model's parameters, drift and last sample in one array (views below),
        # so the twin's compiled period takes them as one argument (``rt.twin.kernels.period``).
        self._packed = np.zeros(_A_SIZE)
        self._kparams = self._packed[_A_PARAMS:_A_DRIFT]
        self._kparams[:] = (p.drift_rate + p.drift_limit + p.bias + p.noise_sigma + p.ranges)
        self._out = self._packed[_A_OUT:_A_OUT_END]
        # The sample as a compiled reader takes it (wrench, counter, status).
        self._sample_view = self._packed[_A_OUT:_A_SAMPLE_END]
        self._state = self._new_state()

    def _new_state(self) -> _State:
        st = _State(rng=np.random.default_rng(self.seed))
        pk = self._packed
        pk[_A_SEQ] = pk[_A_STATUS] = pk[_A_PENDING] = pk[_A_ROW] = 0.0
        pk[_A_T_LAST] = math.nan
        if self.compiled:
            st.drift = self._packed[_A_DRIFT:_A_OUT]
            st.drift[:] = 0.0
            st.block = np.empty((0, 12))
        return st

    # ---------------------------------------------------------------- state
    def reset(self, seed: int | None = None) -> None:
        """Back to the initial state (drift 0, ft_sequence 0); faults and schedule are kept."""
        if seed is not None:
            self.seed = int(seed)
        self._state = self._new_state()

    @property
    def ft_sequence(self) -> int:
        """The last sample's counter (0 before the first)."""
        return int(self._packed[_A_SEQ])

    @property
    def t_last(self) -> float | None:
        """The last sample's time (s; None before the first)."""
        t = float(self._packed[_A_T_LAST])
        return None if math.isnan(t) else t

    @property
    def drift(self) -> Wrench6:
        """Current drift (N, N m), for tests and plots."""
        return tuple(float(v) for v in self._state.drift)  # type: ignore[return-value]

    # ---------------------------------------------------------------- faults
    def set_fault(self, name: str, active: bool = True) -> None:
        """Switch fault ``name`` on or off now (independent of the schedule)."""
        self._check_fault(name)
        self._manual[name] = bool(active)
        self._faults_possible = any(self._manual.values()) or bool(self._schedule)

    def schedule_fault(self, name: str, t_start: float, t_end: float | None = None) -> None:
        """Make fault ``name`` active for ``t_start <= t < t_end`` (s); ``t_end=None``: forever."""
        self._check_fault(name)
        if t_end is not None and t_end <= t_start:
            raise InputError(f"fault {name!r}: t_end {t_end} must be after t_start {t_start}")
        self._schedule.append(_FaultWindow(name, float(t_start), t_end))
        self._faults_possible = True

    def clear_faults(self) -> None:
        """Switch every fault off and forget the schedule."""
        for name in FAULTS:
            self._manual[name] = False
        self._schedule.clear()
        self._faults_possible = False

    def fault_active(self, name: str, t: float) -> bool:
        """Whether fault ``name`` is on at time ``t`` (s)."""
        if self._manual.get(name, False):
            return True
        for w in self._schedule:
            if w.name == name and w.t_start <= t and (w.t_end is None or t < w.t_end):
                return True
        return False

    @staticmethod
    def _check_fault(name: str) -> None:
        if name not in FAULTS:
            raise InputError(f"unknown ATI sensor fault {name!r}; known: {', '.join(FAULTS)}")

    # ---------------------------------------------------------------- physics
    def measure(self, true_wrench: Sequence[float] | np.ndarray, t: float) -> AtiSample | None:
        """The sample the sensor reports at time ``t`` (s) under ``true_wrench`` (N, N m)."""
        if len(true_wrench) != 6:
            raise InputError(f"true_wrench needs 6 values (N, N m), got {len(true_wrench)}")
        st = self._state
        pk = self._packed
        if pk[_A_PENDING] != 0.0:
            self.last_sample()                  # ``stale`` repeats it
        faults = self._faults_possible
        if faults and self.fault_active("dropout", t):
            return None
        if faults and st.last is not None and self.fault_active("stale", t):
            return st.last

        t_last = float(pk[_A_T_LAST])
        dt = 0.0 if math.isnan(t_last) else t - t_last
        if self.compiled:
            return self._measure_compiled(true_wrench, t, dt)
        row = int(pk[_A_ROW])
        if row >= len(st.block):
            st.block = st.rng.standard_normal((_BLOCK, 12)).tolist()
            row = 0
        z = st.block[row]
        pk[_A_ROW] = row + 1
        drift = st.drift
        if dt > 0.0:
            # Bounded random walk: increments ~ N(0, rate^2 dt), clipped to +-limit.
            root_dt = math.sqrt(dt)
            for i in range(6):
                d = drift[i] + self._drift_rate[i] * root_dt * z[i]
                lim = self._drift_limit[i]
                drift[i] = lim if d > lim else (max(d, -lim))
        if math.isnan(t_last) or t > t_last:
            pk[_A_T_LAST] = t

        status = 0
        m = [0.0] * 6
        for i in range(6):
            v = float(true_wrench[i]) + self._bias[i] + drift[i] + self._sigma[i] * z[6 + i]
            r = self._ranges[i]
            if v > r or v < -r:
                v = r if v > r else -r
                status |= STATUS_ANY_ERROR | STATUS_FT_OUT_OF_RANGE
            m[i] = v
        if faults and self.fault_active("saturate", t):
            status |= STATUS_ANY_ERROR | STATUS_GAGE_OUT_OF_RANGE

        seq = (int(pk[_A_SEQ]) + 1) & 0xFFFF_FFFF
        pk[_A_SEQ] = seq
        sample = AtiSample((m[0], m[1], m[2], m[3], m[4], m[5]), status, seq)
        st.last = sample
        return sample

    def _measure_compiled(self, true_wrench: Sequence[float] | np.ndarray, t: float,
                          dt: float) -> AtiSample:
        block, row = self._next_block_row()
        w = true_wrench if type(true_wrench) is np.ndarray else np.asarray(true_wrench,
                                                                            dtype=np.float64)
        status = int(_measure_kernel(w, block, row, self._kparams, self._state.drift,
                                     self._out, dt, STATUS_ANY_ERROR | STATUS_FT_OUT_OF_RANGE))
        return self._commit_compiled(status, t)

    # The compiled sample in two halves around the kernel; the twin's fault-free period
    # does both halves in its own compiled call (``rt.twin.kernels.period_ati``: the row, the
    # drift's step and the bookkeeping in ``_packed``), the random block refilled here.
    def _next_block_row(self) -> tuple[np.ndarray, int]:
        """The random block and row the next compiled sample draws from (refilled when used
        up: the same draws, in the same order, as the interpreted path)."""
        st = self._state
        pk = self._packed
        row = int(pk[_A_ROW])
        if row >= len(st.block):
            st.block = st.rng.standard_normal((_BLOCK, 12))
            row = 0
            pk[_A_ROW] = 0.0
        block = st.block
        assert isinstance(block, np.ndarray)        # the compiled state holds an array
        return block, row

    def _commit_compiled(self, status: int, t: float) -> AtiSample:
        """The sample the kernel wrote into ``_out`` with overload bits ``status``, at ``t``:
        the bookkeeping ``period_ati`` does in the twin's period, plus the ``saturate``
        fault's bits and the sample's object."""
        st = self._state
        pk = self._packed
        pk[_A_ROW] += 1.0
        t_last = pk[_A_T_LAST]
        if math.isnan(t_last) or t > t_last:
            pk[_A_T_LAST] = t
        if self._faults_possible and self.fault_active("saturate", t):
            status |= STATUS_ANY_ERROR | STATUS_GAGE_OUT_OF_RANGE
        seq = (int(pk[_A_SEQ]) + 1) & 0xFFFF_FFFF
        pk[_A_SEQ] = seq
        pk[_A_STATUS] = status
        pk[_A_PENDING] = 0.0
        v = self._out.tolist()
        sample = AtiSample((v[0], v[1], v[2], v[3], v[4], v[5]), status, seq)
        st.last = sample
        return sample

    def last_sample(self) -> AtiSample | None:
        """The last sample reported (None before the first): built now if the twin's period
        committed it without an object."""
        st = self._state
        pk = self._packed
        if pk[_A_PENDING] != 0.0:
            v = self._out.tolist()
            st.last = AtiSample((v[0], v[1], v[2], v[3], v[4], v[5]), int(pk[_A_STATUS]),
                                int(pk[_A_SEQ]))
            pk[_A_PENDING] = 0.0
        return st.last

    def make_source(self, true_wrench: Sequence[float] | Callable[[], Sequence[float]],
                    clock: Callable[[], float] = time.monotonic) -> WrenchSource:
        """A ``WrenchSource`` for the RDT server / CAN responder.

        ``true_wrench`` is a constant 6-vector or a zero-argument callable giving it (N, N m);
        time is ``clock()`` (s) relative to the first call, so schedule faults on that time base.
        """
        get = (true_wrench if callable(true_wrench)
               else _constantly(_as6("true_wrench", true_wrench)))
        t0: list[float] = []

        def source() -> AtiSample | None:
            now = clock()
            if not t0:
                t0.append(now)
            return self.measure(get(), now - t0[0])

        return source


class SourceReader:
    """Device-side plumbing shared by the twin's RDT server and CAN responder.

    ``poll()`` pulls one sample from ``source``; afterwards ``value`` holds the reported wrench
    (raw minus software bias, N and N m), ``status`` and ``ft_sequence``. ``set_bias()`` makes
    the current raw reading the new zero, as the Net F/T's software bias does (manual: "set
    software bias" / CAN "bias": zeros the readings at the current load). Not thread-safe: the
    owning server thread is its only caller.
    """

    def __init__(self, source: WrenchSource) -> None:
        if not callable(source):
            raise InputError("source must be a callable returning (wrench6, status[, ft_seq])")
        self._source = source
        self.raw: list[float] = [0.0] * 6
        self.value: list[float] = [0.0] * 6
        self.bias: list[float] = [0.0] * 6
        self.status = 0
        self.ft_sequence = 0
        self.has_sample = False
        self._own_sequence = 0

    def poll(self) -> bool:
        """Fetch a sample; False (state unchanged) when the source has none (dropout)."""
        result = self._source()
        if result is None:
            return False
        wrench = result[0]
        if len(wrench) != 6:
            raise InputError(f"source returned {len(wrench)} wrench values, expected 6")
        self.status = int(result[1]) & 0xFFFF_FFFF
        if len(result) > 2:
            self.ft_sequence = int(result[2]) & 0xFFFF_FFFF
        else:
            self._own_sequence = (self._own_sequence + 1) & 0xFFFF_FFFF
            self.ft_sequence = self._own_sequence
        raw, value, bias = self.raw, self.value, self.bias
        for i in range(6):
            raw[i] = float(wrench[i])
            value[i] = raw[i] - bias[i]
        self.has_sample = True
        return True

    def set_bias(self, samples: int = BIAS_SAMPLES,
                 wait: Callable[[], None] | None = None) -> bool:
        """Zero at the mean of ``samples`` fresh raw readings; False when none is available.

        Fresh samples are pulled so the bias is the load *now*, even when not streaming. One
        sample would put its noise (σ per axis) into every later reading as a constant
        offset; the mean of n has σ/√n. A source that has no new sample yet (same
        ``ft_sequence``) is waited for with ``wait()`` (the server's sample period); after
        ``3·samples`` polls (a dropout) the samples collected so far are used, or else the
        last reading, as the device can only use what it has.
        """
        if samples < 1:
            raise InputError(f"bias needs at least 1 sample, got {samples}")
        total = [0.0] * 6
        n = 0
        seen = None
        for _ in range(3 * samples):
            if n == samples:
                break
            if self.poll() and self.ft_sequence != seen:
                seen = self.ft_sequence
                n += 1
                for i in range(6):
                    total[i] += self.raw[i]
            elif wait is not None:
                wait()
        if n == 0:
            if not self.has_sample:
                return False
            total, n = list(self.raw), 1
        for i in range(6):
            self.bias[i] = total[i] / n
            self.value[i] = self.raw[i] - self.bias[i]
        return True

    def clear_bias(self) -> None:
        """Forget the software bias."""
        for i in range(6):
            self.bias[i] = 0.0
            self.value[i] = self.raw[i]
