"""A session's figures computed in one pass over blocks of loop samples.

One definition for every consumer: the session summary (from the loop's tap, all samples at
once) and the session report (from a recording, streamed in blocks of a few thousand samples
so an hour at 1 kHz never sits in memory). Feed :meth:`SessionFigures.add` blocks in time
order, then read :meth:`SessionFigures.result`.

Definitions (the same as ``protocols.session.summarize``; units SI unless the key says so):

* measured force: the force the platform applies, ``-fz`` of the sensor (N, + pushing up);
* force-tracking error: reference − measured over the samples in force control during the
  *play* phase, NaN samples left out. ``rms_error_pct`` is its RMS in % of the protocol's
  amplitude (``sine_fz``) or of the peak force reference (other force kinds); position kinds
  have none (``None``);
* ``peak_force_n``: the largest measured force over the whole session (every phase);
* ROM reached (``rom_deg``): min and max of roll and pitch (degrees) from forward kinematics of
  every ``rom_stride``-th play sample (10: 100 Hz, well above the motion's bandwidth);
* ``phase_time_s``: samples in each phase × the loop period;
* ``stops``: safety events whose reaction is a soft or a hard stop (failovers are listed apart:
  the robot kept running on the backup card).
"""
from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from rt.errors import KinematicsError
from rt.references.sequencer import Phase

#: Recorded phase name → :class:`Phase` (``/protocol/reference`` ``phase`` strings; "done" is
#: what recordings made before the one sequencer called the rest after the end).
PHASE_BY_NAME = {**{p.name.lower(): p for p in Phase}, "done": Phase.REST}
#: Code for a sample whose phase was not recorded.
PHASE_UNKNOWN = -1
#: Protocol kinds played in force control (the others are position kinds); a recording whose
#: ``/protocol/reference`` messages carry ``mode`` overrides this per sample.
FORCE_KINDS = frozenset({"sine_fz", "gait_replay"})
#: Safety reactions that stop the session.
STOP_REACTIONS = ("soft_stop", "hard_stop")


class ForwardKinematics(Protocol):
    def fk(self, q: Any, guess: Any = None, check: bool = True) -> Any: ...


@dataclass
class SampleBlock:
    """Consecutive loop samples, oldest first (n samples; arrays of length n or n × 3).

    ``phase`` holds :class:`Phase` codes (``PHASE_UNKNOWN`` where not recorded);
    ``force_mode`` is True where the loop was in force control; ``force_n`` is the measured
    platform force (N, + up) and ``force_ref_n`` its reference (N); ``q``, ``qd``, ``q_ref``,
    ``tau`` are slider positions (m), velocities (m/s), position references (m) and actuator
    force commands (N). Missing values NaN.
    """

    t: np.ndarray
    phase: np.ndarray
    force_mode: np.ndarray
    force_n: np.ndarray
    force_ref_n: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    q_ref: np.ndarray
    tau: np.ndarray

    def __len__(self) -> int:
        return len(self.t)


@dataclass
class AngleSamples:
    """The platform angles computed for the ROM in one block: t (s), roll, pitch (rad)."""

    t: np.ndarray
    roll: np.ndarray
    pitch: np.ndarray


def _t(event: dict[str, Any]) -> float:
    """An event's loop time (s), to the millisecond as the summary has it; NaN if absent."""
    t = event.get("t")
    return round(float(t), 3) if isinstance(t, (int, float)) else math.nan


def _nanmax(x: np.ndarray) -> float:
    x = x[~np.isnan(x)]
    return float(x.max()) if len(x) else -math.inf


class SessionFigures:
    """One-pass accumulator of a session's figures (module docstring for the definitions).

    Args:
        kinematics: the robot's kinematic model (``fk`` for the platform angles).
        kind: the protocol's kind (``sine_fz``, ``gait_replay``, ...).
        amplitude_n: a sine protocol's amplitude (N), the basis of its RMS error in %.
        rate_hz: the loop rate (Hz): the duration of a sample.
        rom_stride: forward kinematics on every this-many play samples.
        preload_n: the force law's floor (N): the error is taken against the reference the
            law tracked, max(F_d, preload) (the recording's metadata ``preload_n``; 0 for
            recordings made before the floor existed).
    """

    def __init__(self, kinematics: ForwardKinematics, kind: str,
                 amplitude_n: float | None = None, rate_hz: float = 1000.0,
                 rom_stride: int = 10, preload_n: float = 0.0):
        if rate_hz <= 0 or rom_stride < 1:
            raise ValueError("rate_hz must be > 0 and rom_stride >= 1")
        self.kin = kinematics
        self.kind = kind
        self.amplitude_n = amplitude_n
        self.dt = 1.0 / rate_hz
        self.rom_stride = rom_stride
        self.preload_n = preload_n
        self.samples = 0
        self._play_seen = 0
        self._sq_err = 0.0
        self._n_err = 0
        self._max_abs_err = 0.0
        self._peak_ref = -math.inf
        self._force_samples = 0
        self._peak_force = -math.inf
        self._peak_tau = -math.inf
        self._peak_qd = -math.inf
        self._phase_counts = np.zeros(len(Phase) + 1, dtype=np.int64)   # last: unknown
        self._rom = {"roll": [math.inf, -math.inf], "pitch": [math.inf, -math.inf]}
        self._last_phase = PHASE_UNKNOWN
        self._fk_failures = 0

    @property
    def force_kind(self) -> bool:
        return self.kind in FORCE_KINDS

    def add(self, b: SampleBlock) -> AngleSamples:
        """Account for one block; returns the angles computed for the ROM (for plots)."""
        n = len(b)
        if n == 0:
            return AngleSamples(np.empty(0), np.empty(0), np.empty(0))
        self.samples += n
        play = b.phase == Phase.PLAY
        tracked = play & b.force_mode
        if tracked.any():
            e = (np.maximum(b.force_ref_n, self.preload_n) - b.force_n)[tracked]
            e = e[~np.isnan(e)]
            self._sq_err += float(np.dot(e, e))
            self._n_err += len(e)
            if len(e):
                self._max_abs_err = max(self._max_abs_err, float(np.abs(e).max()))
            self._peak_ref = max(self._peak_ref,
                                 _nanmax(np.maximum(b.force_ref_n, self.preload_n)[tracked]))
            self._force_samples += int(tracked.sum())
        self._peak_force = max(self._peak_force, _nanmax(b.force_n))
        self._peak_tau = max(self._peak_tau, _nanmax(np.abs(b.tau).ravel()))
        self._peak_qd = max(self._peak_qd, _nanmax(np.abs(b.qd).ravel()))
        codes = np.where((b.phase >= 0) & (b.phase < len(Phase)), b.phase, len(Phase))
        self._phase_counts += np.bincount(codes.astype(np.int64), minlength=len(Phase) + 1)
        known = b.phase[b.phase != PHASE_UNKNOWN]
        if len(known):
            # The state may run on a few cycles past the last recorded reference (the RT
            # process stops recording when the session is at rest): those rows say nothing.
            self._last_phase = int(known[-1])
        # Every rom_stride-th play sample, counted from the session's first play sample.
        idx = np.flatnonzero(play)
        if not len(idx):
            return AngleSamples(np.empty(0), np.empty(0), np.empty(0))
        counter = self._play_seen + np.arange(len(idx))
        self._play_seen += len(idx)
        idx = idx[counter % self.rom_stride == 0]
        ts, rolls, pitches = [], [], []
        for i in idx:
            q = b.q[i]
            if np.isnan(q).any():
                continue
            try:
                cfg = self.kin.fk(q, check=False)
            except KinematicsError:
                # A pose FK cannot solve is counted and reported, not fatal to the figures.
                self._fk_failures += 1
                continue
            ts.append(float(b.t[i]))
            rolls.append(cfg.roll)
            pitches.append(cfg.pitch)
        out = AngleSamples(np.asarray(ts), np.asarray(rolls), np.asarray(pitches))
        for axis, values in (("roll", out.roll), ("pitch", out.pitch)):
            if len(values):
                r = self._rom[axis]
                r[0] = min(r[0], float(np.degrees(values.min())))
                r[1] = max(r[1], float(np.degrees(values.max())))
        return out

    def result(self, events: Iterable[dict[str, Any]] = ()) -> dict[str, Any]:
        """The figures, keyed as the session summary's (plus the extra figures below).

        ``events``: the safety events as recorded (``SafetyEvent.as_dict()``).
        Extra keys: ``rms_error_n``, ``max_abs_error_n`` (N), ``force_samples``,
        ``phase_time_s`` (phase name → s), ``duration_s``, ``peak_actuator_force_n``,
        ``peak_slider_speed_m_s``, ``failovers``, ``fk_failures``, ``samples``.
        """
        out: dict[str, Any] = {"kind": self.kind}
        if self._n_err:
            rms = math.sqrt(self._sq_err / self._n_err)
            basis = "amplitude" if self.kind == "sine_fz" else "peak"
            span = float(self.amplitude_n) if basis == "amplitude" and self.amplitude_n \
                else self._peak_ref
            out["rms_error_pct"] = rms / span * 100.0 if span > 0 else None
            out["rms_error_basis"] = basis
            out["rms_error_n"] = rms
            out["max_abs_error_n"] = self._max_abs_err
        else:
            out["rms_error_pct"] = None
            out["rms_error_n"] = None
            out["max_abs_error_n"] = None
        out["force_samples"] = self._force_samples
        out["peak_force_n"] = None if self._peak_force == -math.inf else self._peak_force
        out["rom_deg"] = {axis: (list(r) if r[0] <= r[1] else None)
                          for axis, r in self._rom.items()}
        ev = list(events)
        out["stops"] = [{"t": _t(e), "cause": e.get("cause", ""),
                         "reaction": e.get("reaction", ""), "message": e.get("message", "")}
                        for e in ev if e.get("reaction") in STOP_REACTIONS]
        out["failovers"] = [{"t": _t(e), "cause": e.get("cause", ""),
                             "message": e.get("message", "")}
                            for e in ev if e.get("reaction") == "failover"]
        out["completed"] = self._last_phase == Phase.REST and not out["stops"]
        out["phase_time_s"] = {p.name.lower(): float(self._phase_counts[p]) * self.dt
                               for p in Phase}
        unknown = int(self._phase_counts[len(Phase)])
        if unknown:
            out["phase_time_s"]["unknown"] = unknown * self.dt
        out["duration_s"] = self.samples * self.dt
        out["peak_actuator_force_n"] = None if self._peak_tau == -math.inf else self._peak_tau
        out["peak_slider_speed_m_s"] = None if self._peak_qd == -math.inf else self._peak_qd
        out["fk_failures"] = self._fk_failures
        out["samples"] = self.samples
        return out
