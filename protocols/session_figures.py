"""A session's figures computed in one pass over blocks of loop samples.

One class, one set of definitions for every consumer: the session summary the RT process
publishes and pre-flight judges (fed the session tap's rows, ``rt.sessions.SESSION_SIGNALS``,
as they are drained: :meth:`SessionFigures.for_protocol`), and the session report (fed blocks of
a recording's samples, a few thousand at a time, so an hour at 1 kHz never sits in memory).
Feed :meth:`SessionFigures.add` blocks (or tap rows) in time order, then read
:meth:`SessionFigures.result`. What a recording lacks (drive commands, the sensor's full wrench,
the tare) leaves the figures that need it out.

Definitions (units SI unless the key says so):

* measured force: the force the platform applies, ``-fz`` of the sensor (N, + pushing up);
* force-tracking error: reference − measured over the samples in force control during the
  *play* phase, NaN samples left out. ``rms_error_pct`` is its RMS in % of the protocol's
  amplitude (``sine_fz``) or of the peak force reference (other force kinds); position kinds
  have none (``None``);
* ``peak_force_n``: the largest measured force over the whole session (every phase);
* ROM reached (``rom_deg``): min and max of roll and pitch (degrees) from forward kinematics of
  every ``rom_stride``-th play sample (10: 100 Hz, well above the motion's bandwidth);
* ``phase_time_s``: samples in each phase × the loop period;
* ``stops``: safety faults whose reaction is a soft or a hard stop (failovers are listed apart:
  the robot kept running on the backup card);
* ``completed``: the session came back to rest after playing, with no stop;
* in contact (``min_force_n``): force-controlled play from the moment the contact first carries
  the preload (each stretch of force control counts anew); before it the platform is still
  bringing the unloaded foot up to the preload and the sensor reads its noise around 0 N. Below
  0 N the platform would pull on the foot;
* at the robot's limit (:meth:`SessionFigures.saturation`): the longest stretch with the
  actuator force or the drive command at the robot's limit;
* with the patient's ankle setup: the ankle angles reached from the protocol's neutral pose and
  the peak torques about the ankle centre (``rt.model.ankle``), in clinical directions;
* ``ati_tare``: the force sensor's tare at the session's start (state, zero, or why refused).
"""
from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from protocols.torque_hold import TorqueHoldFigures
from rt.components.tare import TareState, refusal_message
from rt.model.ankle import AnkleSetup, sensor_to_ankle_S
from rt.references.sequencer import Phase
from rt.safety.events import SafetyEvent
from rt.safety.limits import RobotLimits
from rt.sessions import COL_CTRL_MODE, COL_FREF, COL_FZ, COL_PHASE, COL_TARE, COLUMNS

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
#: Sensor noise allowed below the preload before pre-flight calls it unloading (N).
PRELOAD_TOLERANCE_N = 2.0
#: Width of the tare columns of a session-tap row (``rt.components.tare``).
TARE_WIDTH = 10


class ForwardKinematics(Protocol):
    """What the figures need of the kinematics (``rt.model.kinematics.Kinematics``): the
    roll and pitch (rad) of rows of slider positions, and which rows solved."""
    def fk_roll_pitch(self, qs: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...


@dataclass
class SampleBlock:
    """Consecutive loop samples, oldest first (n samples; arrays of length n or n × 3).

    ``phase`` holds :class:`Phase` codes (``PHASE_UNKNOWN`` where not recorded);
    ``force_mode`` is True where the loop was in force control; ``force_n`` is the measured
    platform force (N, + up) and ``force_ref_n`` its reference (N); ``q``, ``qd``, ``q_ref``,
    ``tau`` are slider positions (m), velocities (m/s), position references (m) and actuator
    force commands (N). Missing values NaN. Optional (None: not known, the figures needing them
    left out): ``volts`` the drive commands (V, n × 3), ``wrench`` the sensor's wrench (N, N·m,
    sensor frame, n × 6), ``tare`` the tare port (n × :data:`TARE_WIDTH`).
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
    volts: np.ndarray | None = None
    wrench: np.ndarray | None = None
    tare: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.t)

    @classmethod
    def from_tap_rows(cls, rows: np.ndarray) -> SampleBlock:
        """The block of session-tap rows (``rt.sessions.SESSION_SIGNALS``; column 0 the loop
        time): the measured force is ``-fz`` of the sensor; the tap has no position
        reference (NaN)."""
        n = len(rows)
        return cls(t=rows[:, 0], phase=rows[:, COL_PHASE].astype(np.int64),
                   force_mode=rows[:, COL_CTRL_MODE] > 0.5, force_n=-rows[:, COL_FZ],
                   force_ref_n=rows[:, COL_FREF], q=rows[:, COLUMNS["q"]],
                   qd=rows[:, COLUMNS["qd"]], q_ref=np.full((n, 3), math.nan),
                   tau=rows[:, COLUMNS["tau"]], volts=rows[:, COLUMNS["volts"]],
                   wrench=rows[:, COLUMNS["wrench"]],
                   tare=rows[:, COL_TARE:COL_TARE + TARE_WIDTH])


@dataclass
class AngleSamples:
    """The platform angles computed for the ROM in one block: t (s), roll, pitch (rad)."""

    t: np.ndarray
    roll: np.ndarray
    pitch: np.ndarray


def _event_dict(event: SafetyEvent | dict[str, Any]) -> dict[str, Any]:
    return event.as_dict() if isinstance(event, SafetyEvent) else event


def _t(event: dict[str, Any]) -> float:
    """An event's loop time (s), to the millisecond as the summary has it; NaN if absent."""
    t = event.get("t")
    return round(float(t), 3) if isinstance(t, (int, float)) else math.nan


def _alarms(events: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The staff alarms of a session (``pull_in_stop``: a pull that persisted after a stop):
    when raised (``t``, s), the pull then (``fz_n``, N), and when and how it ended
    (``ended_t`` s and ``how``; None: still raised when the session ended)."""
    out: list[dict[str, Any]] = []
    for e in events:
        if e.get("cause") != "pull_in_stop":
            continue
        values = e.get("values") or {}
        if e.get("kind") == "warn":
            out.append({"t": _t(e), "cause": "pull_in_stop", "fz_n": values.get("fz_n"),
                        "message": e.get("message", ""), "ended_t": None, "how": None})
        elif e.get("kind") == "alarm_end" and out and out[-1]["ended_t"] is None:
            out[-1].update(ended_t=_t(e), how=values.get("how"))
    return out


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
        robot_limits: the robot's limits (the stretches at the limit; default the nominal).
        ankle: the patient's ankle setup (ankle figures; None: none).
        neutral_rad: the platform's (roll, pitch) at the ankle's neutral pose (rad).
        header: keys the result starts with (the summary's ``protocol``, ``twin``, ...).
        torque_holds: the program's regulated ankle-torque holds (its ``info``); with an ankle
            setup, the reported torque against the target (and the twin's truth) per hold.
    """

    def __init__(self, kinematics: ForwardKinematics, kind: str,
                 amplitude_n: float | None = None, rate_hz: float = 1000.0,
                 rom_stride: int = 10, preload_n: float = 0.0,
                 robot_limits: RobotLimits | None = None, ankle: AnkleSetup | None = None,
                 neutral_rad: tuple[float, float] = (0.0, 0.0),
                 header: dict[str, Any] | None = None,
                 torque_holds: list[dict[str, Any]] | None = None):
        if rate_hz <= 0 or rom_stride < 1:
            raise ValueError("rate_hz must be > 0 and rom_stride >= 1")
        self.kin = kinematics
        self.kind = kind
        self.amplitude_n = amplitude_n
        self.dt = 1.0 / rate_hz
        self.rom_stride = rom_stride
        self.preload_n = preload_n
        self.robot = robot_limits or RobotLimits()
        self.ankle = ankle
        self.neutral_rad = neutral_rad
        self.header = dict(header or {})
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
        # In contact (module docstring): the last sample's state, and the least force.
        self._on = False
        self._force_mode_last = False
        self._min_contact = (math.inf, math.nan)             # (force N, t s)
        # The session time of the first PLAY sample: where the protocol's own time starts
        # (the approach, a tare, a force ramp come before it).
        self._t_play0 = math.nan
        # Longest run at the limit: [current start t, current length, longest length, its t,
        # its peak] for the actuator force and the drive command (None: never known).
        self._runs: dict[str, list[float]] = {"actuator force": [math.nan, 0, 0, math.nan, 0.0],
                                              "drive command": [math.nan, 0, 0, math.nan, 0.0]}
        self._volts_seen = False
        # Peak ankle torques over the play phase, N·m: [plantar max, plantar min, inversion
        # max, inversion min].
        self._r_ankle = None if ankle is None else sensor_to_ankle_S(ankle)
        self._ankle_tau = [-math.inf, math.inf, -math.inf, math.inf]
        self._tare: np.ndarray | None = None     # the force reader's last tare port
        self._torque = TorqueHoldFigures(torque_holds, ankle) \
            if torque_holds and ankle is not None else None

    @classmethod
    def for_protocol(cls, protocol: Any, model: Any, preload_n: float = 0.0,
                     robot_limits: RobotLimits | None = None,
                     info: dict[str, Any] | None = None,
                     ankle: AnkleSetup | None = None, rate_hz: float = 1000.0
                     ) -> SessionFigures:
        """The accumulator of a session of ``protocol`` (a protocol model) on ``model`` (a
        ``RobotModel``) fed with session-tap rows: its result is the session's summary
        (``protocol``, ``kind``, ``twin``, the replayed file's ``source`` first)."""
        header: dict[str, Any] = {"protocol": protocol.name, "kind": protocol.kind,
                                  "twin": True}
        source = {k: v for k, v in (info or {}).items() if k not in ("torque_holds", "dt")}
        if source:
            header["source"] = source
        pose = getattr(protocol, "pose", None)
        neutral = (math.radians(pose.roll_deg), math.radians(pose.pitch_deg)) \
            if pose is not None else (0.0, 0.0)
        amplitude = getattr(protocol, "amplitude_n", None)
        return cls(model.kin, protocol.kind,
                   float(amplitude) if isinstance(amplitude, (int, float)) else None,
                   rate_hz=rate_hz, preload_n=preload_n, robot_limits=robot_limits,
                   ankle=ankle, neutral_rad=neutral, header=header,
                   torque_holds=(info or {}).get("torque_holds"))

    @property
    def force_kind(self) -> bool:
        return self.kind in FORCE_KINDS

    def add(self, block: SampleBlock | np.ndarray,
            truth: np.ndarray | None = None) -> AngleSamples:
        """Account for one block (or session-tap rows, :meth:`SampleBlock.from_tap_rows`);
        returns the angles computed for the ROM (for plots). ``truth``: the twin ankle's true
        torques (roll, pitch, yaw axes, N·m) of the same samples, where a twin runs in process
        (``protocols.session.TwinAnkleTruth``)."""
        b = block if isinstance(block, SampleBlock) else SampleBlock.from_tap_rows(block)
        n = len(b)
        if n == 0:
            return AngleSamples(np.empty(0), np.empty(0), np.empty(0))
        self.samples += n
        play = b.phase == Phase.PLAY
        if math.isnan(self._t_play0) and play.any():
            self._t_play0 = float(b.t[int(np.argmax(play))])
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
        self._contact(b.t, b.force_n, tracked)
        tau = _row_max_abs(b.tau)
        self._peak_tau = max(self._peak_tau, _nanmax(tau))
        self._at_limit("actuator force", b.t, tau, self.robot.max_actuator_force_n)
        if b.volts is not None:
            self._volts_seen = True
            self._at_limit("drive command", b.t, _row_max_abs(b.volts),
                           self.robot.max_command_v)
        self._peak_qd = max(self._peak_qd, _nanmax(np.abs(b.qd).ravel()))
        if self._r_ankle is not None and b.wrench is not None and play.any():
            self._add_ankle_torques(b.wrench[play])
            if self._torque is not None:
                self._torque.add(b.wrench[play], None if truth is None else truth[play][:, :2])
        if b.tare is not None:
            started = np.flatnonzero(b.tare[:, 0] != TareState.NONE)
            if len(started):
                self._tare = b.tare[started[-1]].copy()
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
        qs = b.q[idx]
        idx = idx[~np.isnan(qs).any(axis=1)]               # a row without positions: skipped
        qs = b.q[idx]
        finite = np.isfinite(qs).all(axis=1)
        # A pose FK cannot solve (or an infinite position) is counted and reported, not
        # fatal to the figures. The rows' FK in one compiled call, in order, with the warm
        # starts and floats of one ``fk`` each (issue 16: ≈ 10 % of a pre-flight's CPU).
        rolls, pitches, ok = self.kin.fk_roll_pitch(qs[finite])
        self._fk_failures += int((~finite).sum()) + int((~ok).sum())
        out = AngleSamples(np.asarray(b.t[idx][finite][ok], dtype=float), rolls[ok], pitches[ok])
        for axis, values in (("roll", out.roll), ("pitch", out.pitch)):
            if len(values):
                r = self._rom[axis]
                r[0] = min(r[0], float(values.min()))
                r[1] = max(r[1], float(values.max()))
        return out

    # ------------------------------------------------------------------ the parts

    def _contact(self, t: np.ndarray, force: np.ndarray, force_mode: np.ndarray) -> None:
        """The least force in contact (module docstring), vectorized over the block: within
        each stretch of force control, in contact from its first sample at the preload on (a
        stretch continuing from the last block keeps its state)."""
        fm = np.asarray(force_mode, dtype=bool)
        if not len(fm):
            return
        starts = fm & ~np.r_[self._force_mode_last, fm[:-1]]
        run = np.cumsum(starts)                 # 0: the stretch continuing from the last block
        hit = fm & (force >= self.preload_n)    # NaN compares False
        reached = np.maximum.accumulate(np.where(hit, run, -1))
        on = fm & ((reached == run) | ((run == 0) & self._on))
        self._on = bool(on[-1])
        self._force_mode_last = bool(fm[-1])
        valid = on & ~np.isnan(force)
        if valid.any():
            k = int(np.flatnonzero(valid)[np.argmin(force[valid])])
            if force[k] < self._min_contact[0]:
                self._min_contact = (float(force[k]), float(t[k]))

    def _at_limit(self, what: str, t: np.ndarray, values: np.ndarray, limit: float) -> None:
        """The longest stretch of consecutive samples at ``limit`` (a stretch may continue
        from the last block). Each stretch is found from the block's edges of ``values >=
        limit``, so samples below the limit always end one (the former per-sample loop only
        visited samples at the limit in a block that began below it, and joined stretches)."""
        run = self._runs[what]
        over = values >= limit - 1e-9           # NaN compares False
        if not over.any():
            run[1] = 0
            return
        edges = np.flatnonzero(np.diff(np.r_[0, over.astype(np.int8), 0]))
        start = length = 0.0
        for s, e in zip(edges[::2], edges[1::2], strict=True):
            if s == 0 and run[1] > 0:           # continues the stretch of the last block
                start, length = run[0], run[1] + (e - s)
            else:
                start, length = float(t[s]), float(e - s)
            if length > run[2]:
                run[2], run[3] = length, start
            run[4] = max(run[4], float(np.max(values[s:e])))
        if over[-1]:
            run[0], run[1] = start, length
        else:
            run[1] = 0

    def _add_ankle_torques(self, w: np.ndarray) -> None:
        """Peaks of the ankle torques (``rt.model.ankle.ankle_torques``, vectorized) of the
        sensor's wrench rows (fx, fy, fz, mx, my, mz)."""
        assert self._r_ankle is not None and self.ankle is not None
        rx, ry, rz = self._r_ankle
        fx, fy, fz, mx, my = w[:, 0], w[:, 1], w[:, 2], w[:, 3], w[:, 4]
        plantar = my - (rz * fx - rx * fz)
        sign = 1.0 if self.ankle.side == "right" else -1.0
        inversion = sign * (mx - (ry * fz - rz * fy))
        ok = ~(np.isnan(plantar) | np.isnan(inversion))
        if not ok.any():
            return
        t = self._ankle_tau
        t[0] = max(t[0], float(plantar[ok].max()))
        t[1] = min(t[1], float(plantar[ok].min()))
        t[2] = max(t[2], float(inversion[ok].max()))
        t[3] = min(t[3], float(inversion[ok].min()))

    # ------------------------------------------------------------------ results

    def tare(self) -> dict[str, Any] | None:
        """The ATI's tare at the session's start (None: none was asked for, e.g. a position
        protocol, or not known): state, the zero subtracted (N, N m) and the force the sensor
        read unloaded, or why it was refused."""
        if self._tare is None:
            return None
        row = self._tare
        state = TareState(int(row[0]))
        out: dict[str, Any] = {"state": state.name.lower(),
                               "mean_force_n": float(row[3]) if math.isfinite(row[3]) else None}
        if state == TareState.DONE:
            out["offset_n"] = [float(x) for x in row[4:7]]
            out["offset_nm"] = [float(x) for x in row[7:10]]
        elif state == TareState.REFUSED:
            out["reason"] = refusal_message(int(row[2]), float(row[3]))
        return out

    def saturation(self, dt: float | None = None) -> list[str]:
        """The stretches at the robot's limit longer than ``RobotLimits.max_saturation_s``
        (``dt``: a sample's duration, default the loop period)."""
        dt = self.dt if dt is None else dt
        out = []
        for what, limit, unit in (("actuator force", self.robot.max_actuator_force_n, "N"),
                                  ("drive command", self.robot.max_command_v, "V")):
            _, _, longest, t0, peak = self._runs[what]
            if longest * dt > self.robot.max_saturation_s:
                out.append(f"{what} {peak:.4g} {unit} at the robot's limit {limit:g} {unit} for "
                           f"{longest * dt * 1e3:.0f} ms from t = {t0:.3f} s (the drives "
                           f"saturate; at most {self.robot.max_saturation_s * 1e3:.0f} ms "
                           "allowed)")
        return out

    def at_limit(self, dt: float | None = None) -> list[dict[str, Any]]:
        """Where the protocol asked more than the robot gives, however briefly (a heel strike
        asks 2.7-3 kN of ≈ 2 kN drives for a few ms): per limit reached, its longest stretch
        (s), when it began (s) and the peak asked, so the clinician sees it even when it is
        short enough to be allowed (:meth:`saturation` refuses the long ones). ``from_s`` is
        the session's time; ``from_play_s`` the protocol's own (its preview's time axis: from
        the first sample it played; None when it never played)."""
        dt = self.dt if dt is None else dt
        out = []
        for what, limit, unit in (("actuator force", self.robot.max_actuator_force_n, "N"),
                                  ("drive command", self.robot.max_command_v, "V")):
            _, _, longest, t0, peak = self._runs[what]
            if longest > 0:
                play0 = self._t_play0
                out.append({"what": what, "limit": limit, "unit": unit,
                            "longest_s": longest * dt, "from_s": t0, "peak": peak,
                            "from_play_s": None if math.isnan(play0) else t0 - play0})
        return out

    def unloading(self) -> list[str]:
        """The force in contact below the preload (less the sensor's noise), if it happened."""
        f, t = self._min_contact
        if f < self.preload_n - PRELOAD_TOLERANCE_N:
            return [(f"the force falls to {f:.1f} N at t = {t:.3f} s, below the "
                    f"{self.preload_n:g} N preload (the platform would unload or pull on the "
                    "foot)")]
        return []

    def _ankle_result(self) -> dict[str, Any]:
        """Ankle angles reached (deg from the neutral pose, each in its own direction) and
        peak torques (N·m, each direction's effort as a positive number)."""
        assert self.ankle is not None
        r0, p0 = self.neutral_rad
        sign = 1.0 if self.ankle.side == "right" else -1.0
        deg = math.degrees
        (r_lo, r_hi), (p_lo, p_hi) = self._rom["roll"], self._rom["pitch"]
        out: dict[str, Any] = {"side": self.ankle.side, "setup": self.ankle.model_dump()}
        if math.isfinite(p_lo) and math.isfinite(r_lo):
            inv = sorted((sign * (r_lo - r0), sign * (r_hi - r0)))
            out["rom_deg"] = {"dorsiflexion": deg(-(p_lo - p0)), "plantarflexion": deg(p_hi - p0),
                              "inversion": deg(inv[1]), "eversion": deg(-inv[0])}
        else:
            out["rom_deg"] = None
        t = self._ankle_tau
        if math.isfinite(t[0]):
            out["peak_torque_nm"] = {"plantarflexion": max(t[0], 0.0),
                                     "dorsiflexion": max(-t[1], 0.0),
                                     "inversion": max(t[2], 0.0), "eversion": max(-t[3], 0.0)}
        else:
            out["peak_torque_nm"] = None
        return out

    def result(self, events: Iterable[SafetyEvent | dict[str, Any]] = ()) -> dict[str, Any]:
        """The figures: the session summary's keys (``protocol``, ``kind``, ``rms_error_pct``,
        ``peak_force_n``, ``min_force_n``, ``rom_deg``, ``stops``, ``completed``, ``phase_s``
        ...) and the report's (``rms_error_n``, ``max_abs_error_n`` (N), ``force_samples``,
        ``phase_time_s`` (every phase, s), ``duration_s``, ``failovers``, ``fk_failures``,
        ``samples``); ``ankle`` with an ankle setup, ``ati_tare`` when a tare was asked.

        ``events``: the safety events (``SafetyEvent`` or as recorded, ``as_dict()``).
        """
        out: dict[str, Any] = {"kind": self.kind, **self.header}
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
        out["min_force_n"] = self._min_contact[0] if math.isfinite(self._min_contact[0]) \
            else None
        deg = math.degrees
        out["rom_deg"] = {axis: ([deg(r[0]), deg(r[1])] if r[0] <= r[1] else None)
                          for axis, r in self._rom.items()}
        if self.ankle is not None:
            out["ankle"] = self._ankle_result()
            if self._torque is not None:
                out["ankle"]["torque_holds"] = self._torque.result()
        ev = [_event_dict(e) for e in events]
        out["stops"] = [{"t": _t(e), "cause": e.get("cause", ""),
                         "reaction": e.get("reaction", ""), "message": e.get("message", "")}
                        for e in ev if e.get("reaction") in STOP_REACTIONS
                        and e.get("kind", "fault") == "fault"]
        out["alarms"] = _alarms(ev)
        out["failovers"] = [{"t": _t(e), "cause": e.get("cause", ""),
                             "message": e.get("message", "")}
                            for e in ev if e.get("reaction") == "failover"]
        out["phase_time_s"] = {p.name.lower(): float(self._phase_counts[p]) * self.dt
                               for p in Phase}
        unknown = int(self._phase_counts[len(Phase)])
        if unknown:
            out["phase_time_s"]["unknown"] = unknown * self.dt
        out["phase_s"] = {k: round(v, 3) for k, v in out["phase_time_s"].items() if v > 0.0}
        out["completed"] = self._last_phase == Phase.REST and not out["stops"] \
            and out["phase_time_s"]["play"] > 0.0
        out["duration_s"] = self.samples * self.dt
        out["peak_actuator_force_n"] = None if self._peak_tau == -math.inf else self._peak_tau
        out["peak_slider_speed_m_s"] = None if self._peak_qd == -math.inf else self._peak_qd
        tare = self.tare()
        if tare is not None:
            out["ati_tare"] = tare
        out["fk_failures"] = self._fk_failures
        out["samples"] = self.samples
        return out


def _row_max_abs(x: np.ndarray) -> np.ndarray:
    """Per sample, the largest magnitude of its components (NaN only when all are NaN)."""
    a = np.abs(x)
    if a.ndim == 1:
        return a
    with np.errstate(invalid="ignore"):
        return np.fmax.reduce(a, axis=1)
