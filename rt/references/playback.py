"""Position-trajectory playback from a file (thesis 3.7.4), and the approach/play/return sequence.

File format (CSV, one row per sample, ``#`` comment lines and blank lines ignored):

* header ``t,q0,q1,q2``: time (s) and the three slider positions (m); or
* header ``q0,q1,q2`` (or no header, three numeric columns): positions only, sampled at a rate
  declared by the caller (``sample_rate_hz``).

Validation is strict and every refusal is a :class:`~rt.errors.ProtocolValidationError` naming the
file, the line (1-based, as an editor shows it) and the reason: unreadable or empty file, wrong
header, wrong column count, a value that is not a number or not finite, time not strictly
increasing, non-uniform sampling (unless ``uniform=False``), a position outside the stroke, a
velocity or acceleration implied by finite differences of the samples beyond the limits, and the
same checks on the resampled reference that will actually be played.

Resampling: the samples are interpolated and the interpolant evaluated at the loop's times
``k dt`` from the first sample, so a file at any rate (the thesis's 100 Hz files, 1 kHz files, or
a non-uniform file when allowed) plays at the loop rate. Velocity and acceleration come from the
analytic derivatives of the interpolant, not from differences of noisy samples:

* ``"cubic"`` (default): a not-a-knot cubic spline (scipy ``CubicSpline``), C² — position,
  velocity and acceleration are continuous, and it reproduces the file's samples exactly.
  Not-a-knot rather than natural end conditions, so a file that starts or ends in motion is not
  forced to zero acceleration at its ends.
* ``"linear"``: piecewise linear, for files already at the loop rate that must be reproduced with
  no spline overshoot; velocity is piecewise constant and acceleration zero (its impulses at the
  knots are not representable) — the controller's feedforward is poorer.

The resampled position/velocity/acceleration arrays are computed once by ``validate()`` (72 bytes
per sample: 4.3 MB per minute at 1 kHz), so every sample that will be played has been checked
against the limits, and ``update`` only copies one row. A partial last period (file duration not
a multiple of dt) is not played.

Sources (playback, ``BenchmarkTrajectory``) share one per-cycle API, :class:`CycleSource`;
:class:`SourceProgram` hands one to the loop's sequencer, which adds the ruckig approach from the
robot's state to the source's first sample state and the return to rest.
"""
from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from enum import IntEnum
from pathlib import Path
from typing import Protocol

import numpy as np
from scipy.interpolate import CubicSpline

from rt.errors import ConfigurationError, ProtocolValidationError
from rt.references.approach import (
    DEFAULT_MAX_ACCELERATION_M_S2,
    DEFAULT_MAX_VELOCITY_M_S,
    N_AXES,
    POSITION_SLACK_M,
    STROKE_M,
)
from rt.references.program import Mode, ProgramInput, ProgramStatus, ReferenceOutput

_AXES = ("q0", "q1", "q2")
# Relative tolerance on a file's sample interval against its median: 0.1 % absorbs times written
# with 6 significant digits (e.g. 0.00100000 s ± 1e-9) but refuses a dropped or doubled sample.
UNIFORM_TOLERANCE = 1e-3
# Slack on the velocity/acceleration limit checks: 1e-9 relative, round-off only.
LIMIT_SLACK = 1e-9


class ReferenceStatus(IntEnum):
    """Per-cycle status of a :class:`CycleSource`; negative values are errors."""

    PLAYING = 0  # the output is a sample inside the trajectory
    FINISHED = 1  # the output is the last sample (and stays so on later calls)
    ERROR_NOT_VALIDATED = -1  # validate() was not called (or failed)


class CycleSource(Protocol):
    """Per-cycle reference source: ``validate()`` once, then one ``update`` per cycle.

    ``dt`` (s) is the loop period; samples are at times k·dt, k = 0 … n_samples - 1. ``index`` is
    the sample the next ``update`` emits.
    """

    dt: float
    n_samples: int
    index: int

    def validate(self) -> None: ...

    def reset(self, start_index: int = 0) -> None: ...

    def state_at(self, index: int, pos: np.ndarray, vel: np.ndarray,
                 acc: np.ndarray) -> None: ...

    def update(self, out_pos: np.ndarray, out_vel: np.ndarray,
               out_acc: np.ndarray) -> ReferenceStatus: ...


# -- file loading ------------------------------------------------------------------------------
def _refuse(source: str, line: int | None, reason: str) -> ProtocolValidationError:
    where = f"{source}, line {line}" if line is not None else source
    return ProtocolValidationError(f"{where}: {reason}")


def _parse_float(text: str, source: str, line: int, column: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise _refuse(source, line,
                      f"column {column!r}: {text.strip()!r} is not a number") from None
    if not math.isfinite(value):
        raise _refuse(source, line, f"column {column!r}: {text.strip()} is not a finite number")
    return value


def load_csv(path: str | Path, sample_rate_hz: float | None = None
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read a trajectory CSV strictly.

    Args:
        path: the file.
        sample_rate_hz: sample rate (Hz) of a file without a time column; must be None when the
            file has one.

    Returns:
        ``(t, q, lines)``: times (s, starting where the file starts), positions (m, shape (n, 3))
        and each sample's 1-based line number in the file.

    Raises:
        ProtocolValidationError: naming the file, the line and the reason.
    """
    source = str(path)
    try:
        with open(path, newline="", encoding="utf-8") as f:
            rows = list(csv.reader(f))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise _refuse(source, None, f"cannot read the file ({exc})") from None
    numbered = [(i + 1, r) for i, r in enumerate(rows)
                if r and any(c.strip() for c in r) and not r[0].lstrip().startswith("#")]
    if not numbered:
        raise _refuse(source, None, "the file has no header and no samples")
    line, first = numbered[0]
    header = [c.strip().lower() for c in first]
    if header == ["t", *_AXES]:
        has_time, data = True, numbered[1:]
    elif header == list(_AXES):
        has_time, data = False, numbered[1:]
    elif all(_is_number(c) for c in first):
        has_time, data = False, numbered  # headerless positions
        if len(first) != N_AXES:
            raise _refuse(source, line, f"a file without a header must have {N_AXES} position "
                          f"columns (got {len(first)}); write the header 't,q0,q1,q2' for a time "
                          "column")
    else:
        raise _refuse(source, line, "the header must be 't,q0,q1,q2' or 'q0,q1,q2' "
                      f"(got {','.join(c.strip() for c in first)!r})")
    if has_time and sample_rate_hz is not None:
        raise _refuse(source, line, "the file has a time column; do not also declare "
                      "sample_rate_hz")
    if not has_time:
        if sample_rate_hz is None:
            raise _refuse(source, line, "the file has no time column: declare its sample_rate_hz")
        if not (math.isfinite(sample_rate_hz) and sample_rate_hz > 0.0):
            raise _refuse(source, None, f"sample_rate_hz must be > 0 (got {sample_rate_hz!r})")
    columns = ["t", *_AXES] if has_time else list(_AXES)
    if not data:
        raise _refuse(source, None, "the file has a header but no samples")
    t = np.empty(len(data))
    q = np.empty((len(data), N_AXES))
    lines = np.empty(len(data), dtype=int)
    for k, (line, row) in enumerate(data):
        if len(row) != len(columns):
            raise _refuse(source, line, f"expected {len(columns)} columns "
                          f"({','.join(columns)}), got {len(row)}")
        values = [_parse_float(c, source, line, name) for c, name in zip(row, columns)]
        if has_time:
            t[k] = values[0]
            q[k] = values[1:]
            if k > 0 and not t[k] > t[k - 1]:
                raise _refuse(source, line, f"time {float(t[k])!r} s is not after the previous "
                              f"sample's {float(t[k - 1])!r} s (line {lines[k - 1]}): times must "
                              "increase strictly")
        else:
            t[k] = k / sample_rate_hz  # type: ignore[operator]
            q[k] = values
        lines[k] = line
    return t, q, lines


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


# -- playback ----------------------------------------------------------------------------------
class TrajectoryPlayback:
    """Plays a sampled position trajectory at the loop rate (a :class:`CycleSource`).

    Ports (per cycle): ``update(out_pos, out_vel, out_acc)`` writes the reference position (m),
    velocity (m/s), acceleration (m/s²) into the caller's (3,) arrays.

    Args:
        t: sample times (s), strictly increasing (shifted so the first is 0).
        q: positions (m), shape (n, 3).
        dt: loop period (s).
        stroke: (lo, hi) stroke (m).
        max_velocity, max_acceleration: limits (m/s, m/s²) the samples and the played
            reference must respect (one value or one per axis).
        interpolation: ``"cubic"`` or ``"linear"`` (module docstring).
        uniform: require uniform sampling (tolerance ``UNIFORM_TOLERANCE``, relative).
        source: name used in error messages (the file path).
        lines: each sample's line in the file, for error messages (default: sample index + 1).
    """

    def __init__(self, t: Sequence[float] | np.ndarray, q: Sequence[Sequence[float]] | np.ndarray,
                 dt: float = 1.0e-3, stroke: tuple[float, float] = STROKE_M,
                 max_velocity: float | Sequence[float] = DEFAULT_MAX_VELOCITY_M_S,
                 max_acceleration: float | Sequence[float] = DEFAULT_MAX_ACCELERATION_M_S2,
                 interpolation: str = "cubic", uniform: bool = True, source: str = "<array>",
                 lines: Sequence[int] | np.ndarray | None = None) -> None:
        if not (math.isfinite(dt) and dt > 0.0):
            raise ConfigurationError(f"dt must be > 0 s (got {dt!r})")
        if interpolation not in ("cubic", "linear"):
            raise ConfigurationError(f"interpolation must be 'cubic' or 'linear' "
                                     f"(got {interpolation!r})")
        self.dt = dt
        self.stroke = (float(stroke[0]), float(stroke[1]))
        self.max_velocity = np.broadcast_to(np.asarray(max_velocity, float), (N_AXES,)).copy()
        self.max_acceleration = np.broadcast_to(np.asarray(max_acceleration, float),
                                                (N_AXES,)).copy()
        self.interpolation = interpolation
        self.uniform = uniform
        self.source = source
        self._t = np.asarray(t, dtype=float)
        self._q = np.asarray(q, dtype=float)
        self._lines = (np.arange(1, self._t.size + 1) if lines is None
                       else np.asarray(lines, dtype=int))
        self._validated = False
        self.n_samples = 0
        self.index = 0
        self._pos = self._vel = self._acc = np.zeros((0, N_AXES))

    @classmethod
    def from_csv(cls, path: str | Path, dt: float = 1.0e-3, sample_rate_hz: float | None = None,
                 **kwargs: object) -> TrajectoryPlayback:
        """Load a CSV (module docstring) and validate it; raises ProtocolValidationError."""
        t, q, lines = load_csv(path, sample_rate_hz)
        playback = cls(t, q, dt=dt, source=str(path), lines=lines,
                       **kwargs)  # type: ignore[arg-type]
        playback.validate()
        return playback

    @property
    def duration(self) -> float:
        """Played duration (s): (n_samples - 1)·dt."""
        return (self.n_samples - 1) * self.dt

    # -- validation ----------------------------------------------------------------------------
    def validate(self) -> None:
        """Check everything that will be played; build the resampled reference.

        Raises:
            ProtocolValidationError: naming the source, the line and the reason.
        """
        self._validated = False
        src, t, q, lines = self.source, self._t, self._q, self._lines
        if t.ndim != 1 or q.shape != (t.size, N_AXES) or lines.shape != t.shape:
            raise _refuse(src, None, f"expected n times and an (n, {N_AXES}) position array "
                          f"(got {t.shape} and {q.shape})")
        if t.size < 2:
            raise _refuse(src, None, f"at least 2 samples are needed (got {t.size})")
        bad = np.argwhere(~np.isfinite(q))
        if bad.size:
            k, i = bad[0]
            raise _refuse(src, int(lines[k]), f"column {_AXES[i]!r}: {float(q[k, i])} is not "
                          "finite")
        if not np.all(np.isfinite(t)):
            k = int(np.argmax(~np.isfinite(t)))
            raise _refuse(src, int(lines[k]), f"time {float(t[k])} is not finite")
        dts = np.diff(t)
        if np.any(dts <= 0.0):
            k = int(np.argmax(dts <= 0.0)) + 1
            raise _refuse(src, int(lines[k]), f"time {float(t[k])!r} s is not after the previous "
                          f"sample's {float(t[k - 1])!r} s: times must increase strictly")
        if self.uniform:
            h = float(np.median(dts))
            off = np.abs(dts - h) > UNIFORM_TOLERANCE * h
            if np.any(off):
                k = int(np.argmax(off)) + 1
                raise _refuse(src, int(lines[k]), f"sample interval {float(dts[k - 1]):.6g} s "
                              f"differs from the file's {h:.6g} s by more than "
                              f"{UNIFORM_TOLERANCE:.1%}: the file is not uniformly sampled (a "
                              "dropped or repeated sample?); pass uniform=False to resample a "
                              "non-uniform file")
        lo, hi = self.stroke
        out = (q < lo - POSITION_SLACK_M) | (q > hi + POSITION_SLACK_M)
        if np.any(out):
            k, i = np.argwhere(out)[0]
            raise _refuse(src, int(lines[k]), f"column {_AXES[i]!r}: position "
                          f"{float(q[k, i])!r} m is outside the stroke [{lo}, {hi}] m")
        # Velocities and accelerations implied by finite differences of the samples.
        v = np.diff(q, axis=0) / dts[:, None]
        over = np.abs(v) > self.max_velocity * (1.0 + LIMIT_SLACK)
        if np.any(over):
            k, i = np.argwhere(over)[0]
            raise _refuse(src, int(lines[k + 1]),
                          f"column {_AXES[i]!r}: velocity {v[k, i]:.4g} m/s from line "
                          f"{lines[k]} to {lines[k + 1]} exceeds the limit "
                          f"{self.max_velocity[i]:.4g} m/s")
        if t.size >= 3:
            tm = 0.5 * (t[2:] - t[:-2])
            a = np.diff(v, axis=0) / tm[:, None]
            over = np.abs(a) > self.max_acceleration * (1.0 + LIMIT_SLACK)
            if np.any(over):
                k, i = np.argwhere(over)[0]
                raise _refuse(src, int(lines[k + 1]), f"column {_AXES[i]!r}: acceleration "
                              f"{a[k, i]:.4g} m/s² (second difference over lines {lines[k]} to "
                              f"{lines[k + 2]}) exceeds the limit "
                              f"{self.max_acceleration[i]:.4g} m/s²")
        self._resample()
        self._check_played()
        self._validated = True
        self.index = 0

    def _resample(self) -> None:
        t = self._t - self._t[0]
        n = math.floor(t[-1] / self.dt + 1e-9) + 1
        tk = np.arange(n) * self.dt
        tk[-1] = min(tk[-1], t[-1])  # round-off must not evaluate past the last sample
        if self.interpolation == "cubic":
            spline = CubicSpline(t, self._q, axis=0, bc_type="not-a-knot")
            self._pos = spline(tk)
            self._vel = spline(tk, 1)
            self._acc = spline(tk, 2)
        else:
            seg = np.clip(np.searchsorted(t, tk, side="right") - 1, 0, t.size - 2)
            slope = np.diff(self._q, axis=0) / np.diff(t)[:, None]
            self._pos = self._q[seg] + slope[seg] * (tk - t[seg])[:, None]
            self._vel = slope[seg]
            self._acc = np.zeros_like(self._pos)
        self._tk = tk
        self.n_samples = n

    def _check_played(self) -> None:
        """The resampled reference (what the loop will see) within stroke and limits."""
        src, lo, hi = self.source, *self.stroke
        checks = (
            (self._pos < lo - POSITION_SLACK_M) | (self._pos > hi + POSITION_SLACK_M),
            np.abs(self._vel) > self.max_velocity * (1.0 + LIMIT_SLACK),
            np.abs(self._acc) > self.max_acceleration * (1.0 + LIMIT_SLACK),
        )
        what = ("position", "velocity", "acceleration")
        unit = ("m", "m/s", "m/s²")
        arrays = (self._pos, self._vel, self._acc)
        limit_txt = (lambda i: f"is outside the stroke [{lo}, {hi}] m",
                     lambda i: f"exceeds the limit {self.max_velocity[i]:.4g} m/s",
                     lambda i: f"exceeds the limit {self.max_acceleration[i]:.4g} m/s²")
        for bad, name, u, arr, txt in zip(checks, what, unit, arrays, limit_txt):
            if np.any(bad):
                k, i = np.argwhere(bad)[0]
                tk = self._tk[k] + self._t[0]
                j = int(np.clip(np.searchsorted(self._t, tk, side="right") - 1, 0,
                                self._t.size - 2))
                raise _refuse(src, int(self._lines[j + 1]),
                              f"column {_AXES[i]!r}: the {self.interpolation} interpolation "
                              f"between lines {self._lines[j]} and {self._lines[j + 1]} gives "
                              f"{name} {arr[k, i]:.7g} {u} at t = {tk:.4f} s, which {txt(i)} "
                              "(the samples overshoot between them; smooth the file or use "
                              "interpolation='linear')")

    # -- per-cycle -------------------------------------------------------------------------------
    def reset(self, start_index: int = 0) -> None:
        """Make ``start_index`` the next sample emitted."""
        self.index = min(max(int(start_index), 0), max(self.n_samples - 1, 0))

    def states(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every sample's position, velocity and acceleration (n×3 each, m, m/s, m/s²):
        read-only views, for whole-path computations (``state_at`` copies one sample)."""
        views = (self._pos.view(), self._vel.view(), self._acc.view())
        for v in views:
            v.flags.writeable = False
        return views

    def state_at(self, index: int, pos: np.ndarray, vel: np.ndarray, acc: np.ndarray) -> None:
        """Write sample ``index``'s state (m, m/s, m/s²) into the arrays (-1 = the last)."""
        pos[:] = self._pos[index]
        vel[:] = self._vel[index]
        acc[:] = self._acc[index]

    def update(self, out_pos: np.ndarray, out_vel: np.ndarray,
               out_acc: np.ndarray) -> ReferenceStatus:
        """Emit the next sample; ``FINISHED`` on the last one (held afterwards)."""
        if not self._validated:
            return ReferenceStatus.ERROR_NOT_VALIDATED
        k = self.index
        out_pos[:] = self._pos[k]
        out_vel[:] = self._vel[k]
        out_acc[:] = self._acc[k]
        if k >= self.n_samples - 1:
            return ReferenceStatus.FINISHED
        self.index = k + 1
        return ReferenceStatus.PLAYING


# -- as a program ------------------------------------------------------------------------------
class SourceProgram:
    """A validated :class:`CycleSource` (file playback, the benchmark) as a program for the
    loop's sequencer (``rt.references.sequencer.ProgramReference``), which adds the approach
    from the robot's state and the return to rest."""

    def __init__(self, source: CycleSource) -> None:
        self.source = source
        self.duration_s = (source.n_samples - 1) * source.dt

    @staticmethod
    def new_output() -> ReferenceOutput:
        return ReferenceOutput()

    def reset(self) -> None:
        self.source.reset(0)

    def update(self, out: ReferenceOutput, inp: ProgramInput | None = None) -> int:
        index = self.source.index
        status = self.source.update(out.q_ref, out.qd_ref, out.qdd_ref)
        if status < 0:
            return ProgramStatus.ERROR_NOT_VALIDATED
        out.mode = Mode.POSITION
        out.index = index
        out.done = status == ReferenceStatus.FINISHED
        return ProgramStatus.FINISHED if out.done else ProgramStatus.RUNNING
