"""A clinical session's protocol side: check the protocol, run it on the twin first
(pre-flight), compute the session's figures; the RT process runs the real session
(``protocols.rt_session`` is what it is given to prepare one).

Pre-flight refuses a protocol — with the reason — when its own validation reports a violation,
when its references break the patient's or the robot's limits, or when running it on the twin
as fast as possible makes the safety supervisor stop the robot. Its report gives the predicted
peaks: actuator force, slider speed, platform angles and platform force.

The figures (:class:`SessionFigures`) are computed from the session tap's rows
(``rt.sessions.SESSION_SIGNALS``) as they stream, so an hour at 1 kHz is never held at once;
pre-flight, the in-process twin run (benchmarks) and the RT process all use them.
"""
from __future__ import annotations

import math
import sys
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from protocols.generators import make_generator
from protocols.library import load_protocol
from protocols.schema import ProtocolModel
from protocols.torque_hold import TorqueHoldFigures
from rt.components.blocks import SignalTap
from rt.components.tare import TareState, refusal_message
from rt.engine import Array, Component
from rt.errors import InputError, ProtocolValidationError
from rt.model import RobotModel
from rt.model.ankle import AnkleMonitor, AnkleSetup, sensor_to_ankle_S
from rt.position_loop import PositionLoop, build_protocol_loop, sim_devices
from rt.references.sequencer import Phase
from rt.safety.events import Reaction, SafetyEvent
from rt.safety.limits import PatientLimits, ProtocolLimits, RobotLimits
from rt.sessions import (
    COL_CTRL_MODE,
    COL_FREF,
    COL_FZ,
    COL_PHASE,
    COL_PROGRESS,
    COL_TARE,
    COLUMNS,
    SESSION_SIGNALS,
    SESSION_SOURCES,
    record_rows,
)
from rt.twin.environment import CompliantAnkle, parse_environment, patient_foot
from rt.twin.twin import SimClock, Twin

RATE_HZ = 1000.0
#: ROM figures use every n-th sample's forward kinematics (at 1 kHz: 100 Hz, ample for angles).
ROM_DECIMATION = 10
#: Sensor noise allowed below the preload before pre-flight calls it unloading (N).
PRELOAD_TOLERANCE_N = 2.0


@dataclass
class SessionSetup:
    """What a session needs: the protocol (a file, or a validated model whose relative data
    files resolve in ``base_dir``), the patient, the limits, the twin's environment."""

    protocol_path: Path | None = None
    patient_weight_kg: float | None = None
    patient_limits: PatientLimits = field(default_factory=PatientLimits)
    robot_limits: RobotLimits = field(default_factory=RobotLimits)
    environment: str | None = None
    seed: int = 0
    protocol: ProtocolModel | None = None
    base_dir: Path | None = None
    #: The patient's ankle centre (ankle exercises turn the foot about it; the twin's foot
    #: turns about it).
    ankle: AnkleSetup | None = None

    def load(self) -> ProtocolModel:
        if self.protocol is not None:
            return self.protocol
        if self.protocol_path is None:
            raise ProtocolValidationError("a session needs a protocol (file or document)")
        return load_protocol(self.protocol_path)

    @property
    def source(self) -> str:
        return str(self.protocol_path) if self.protocol_path is not None else \
            f"protocol {self.protocol.name!r}" if self.protocol is not None else "<none>"


def protocol_limits_of(protocol) -> ProtocolLimits | None:
    lim = getattr(protocol, "limits", None)
    if lim is None:
        return None
    return ProtocolLimits(**{k: v for k, v in lim.model_dump().items()
                             if k in ProtocolLimits.model_fields})


def _environment(setup: SessionSetup, model: RobotModel, z: float, roll: float, pitch: float):
    if setup.environment:
        return parse_environment(setup.environment)
    # The patient's strapped foot, unloaded where the protocol starts (the clinician sets the
    # platform under the foot before the session), turning about its ankle centre.
    return patient_foot(model.kin, z, roll, pitch, setup.ankle)


def build_twin_session(setup: SessionSetup, model: RobotModel, mode: str):
    """The protocol, its validated generator and report, and the position loop on an
    in-process twin with the session tap, ready to run (pre-flight, benchmarks, tests)."""
    protocol = setup.load()
    gen = make_generator(protocol, dt=1.0 / RATE_HZ, kinematics=model.kin,
                         patient_weight_kg=setup.patient_weight_kg, base_dir=setup.base_dir,
                         ankle=setup.ankle)
    report = gen.validate()
    if not report.ok:
        raise ProtocolValidationError(f"{setup.source}: " + "; ".join(report.violations))
    clock = SimClock()
    z0, roll0, pitch0 = start_pose(gen)
    env = _environment(setup, model, z0, roll0, pitch0)
    # The twin is "the real rig" (its own perturbed truth and imperfections), not the model.
    twin = Twin(None, env, seed=setup.seed, clock=clock)
    twin.place(model.kin.ik(z0, roll0, pitch0).q)
    n = int((report.duration_s + 15.0) * RATE_HZ)
    tap = SignalTap("session", SESSION_SIGNALS, capacity=n)
    blocks: list[Any] = [tap]
    connections = [(src, f"session.{name}") for name, src in SESSION_SOURCES.items()]
    if isinstance(env, CompliantAnkle) and setup.ankle is not None:
        # The twin ankle's true joint torque beside the session's rows (same cycles), so the
        # figures can compare the torque the product reports with it.
        blocks += [TwinAnkleTruth(TRUTH_BLOCK, twin), SignalTap(TRUTH_TAP, [("torque", 3)],
                                                               capacity=n)]
        connections.append((f"{TRUTH_BLOCK}.torque", f"{TRUTH_TAP}.torque"))
    pl = build_protocol_loop(sim_devices(twin, clock), gen, model, RATE_HZ, mode,
                             robot_limits=setup.robot_limits,
                             patient_limits=setup.patient_limits,
                             protocol_limits=protocol_limits_of(protocol), extra_blocks=blocks,
                             extra_connections=connections)
    return protocol, gen, report, pl, tap


def truth_tap(pl: PositionLoop) -> SignalTap | None:
    """The tap of the twin ankle's true torque (:class:`TwinAnkleTruth`) in a loop built by
    :func:`build_twin_session`, None when it has none."""
    try:
        comp = pl.graph.component(TRUTH_TAP)
    except InputError:
        return None
    return comp if isinstance(comp, SignalTap) else None


#: The name other branches know it by (renamed public for bench/ankle.py).
_build = build_twin_session


#: Slots of the twin ankle's truth in a pre-flight loop.
TRUTH_BLOCK, TRUTH_TAP = "ankle_truth", "ankle_truth_tap"


class TwinAnkleTruth(Component):
    """Ports: out ``torque``: float64[3] — the twin ankle joint's moment on the foot (N·m) in
    the foot's (platform's) axes: roll, pitch, yaw; what the product's reported ankle torque
    (the sensor's wrench moved to the ankle centre) should equal. Reads the in-process twin's
    environment state (``rt.twin.physics``: the joint's moment in the base frame), so it only
    exists where a twin does (pre-flight, benchmarks, tests)."""

    def __init__(self, name: str, twin: Twin) -> None:
        super().__init__(name)
        self.twin = twin
        self.torque = self.declare_output("torque", Array(3))

    def update(self, t: float, dt: float) -> int:
        p = self.twin.plant
        r, m = p.rot, p.env_state
        out = self.torque.data
        for a in range(3):        # Rᵀ m, on floats
            out[a] = r[0, a] * m[1] + r[1, a] * m[2] + r[2, a] * m[3]
        return 0


def start_pose(gen) -> tuple[float, float, float]:
    """The platform pose (z m, roll rad, pitch rad) of a generator's first sample."""
    first = gen.new_output()
    gen.reset()
    gen.update(first)
    gen.reset()
    z, roll, pitch = (float(x) for x in first.pose_ref)
    return z, roll, pitch


def _run(pl: PositionLoop, tap: SignalTap, duration_s: float,
         progress: Callable[[float], None] | None) -> None:
    """Run the in-process twin as fast as possible until the protocol is done and back at
    rest, or the supervisor stopped it (then 0.6 s more, to come to rest). A real session runs
    in the RT process, never here."""
    end = duration_s + 10.0

    def finished() -> bool:
        row = tap.ring[(tap.written - 1) % tap.capacity]
        if progress is not None and tap.written:
            progress(float(row[COL_PROGRESS]))
        return bool(tap.written) and (row[COL_PHASE] >= Phase.REST
                                      or pl.supervisor.reaction >= Reaction.SOFT_STOP)

    t = 0.0
    while t < end:
        pl.loop.run(seconds=0.1)
        t += 0.1
        if finished():
            pl.loop.run(seconds=0.6)
            break


class SessionFigures:
    """A session's figures, accumulated from session-tap rows as they stream (twin figures on
    the twin): force RMS error (% of the sine's amplitude, else of the peak reference) over the
    samples played in force mode, against the reference the force law tracked (floored at the
    preload); peak platform force; the least force in contact (below 0 the platform would pull
    on the foot); ROM reached per axis; peaks of actuator force and slider speed; the longest
    stretch with the actuator force or the drive command at the robot's limit; phases'
    durations; stops come from the events.

    "In contact" (:meth:`add`): force-controlled play from the moment the contact first carries
    the preload (each stretch of force control counts anew); before it the platform is still
    bringing the unloaded foot up to the preload and the sensor reads its noise around 0 N.
    """

    def __init__(self, protocol: ProtocolModel, model: RobotModel, preload_n: float = 0.0,
                 robot_limits: RobotLimits | None = None, info: dict[str, Any] | None = None,
                 ankle: AnkleSetup | None = None):
        self.protocol = protocol
        # With the patient's ankle setup: ankle angles and torques in clinical terms.
        self.ankle = ankle
        self._r_ankle = None if ankle is None else sensor_to_ankle_S(ankle)
        # Peak ankle torques over the play phase, N·m: [plantar max, plantar min, inversion
        # max, inversion min].
        self._ankle_tau = [-math.inf, math.inf, -math.inf, math.inf]
        windows = (info or {}).get("torque_holds")
        # Per regulated hold: the reported ankle torque against the target (and the truth).
        self._torque = TorqueHoldFigures(windows, ankle) if windows and ankle is not None \
            else None
        self.kin = model.kin
        self.preload_n = preload_n
        self.robot = robot_limits or RobotLimits()
        self.info = info or {}
        self._on = False                  # in contact (see the class docstring)
        self._min_contact = (math.inf, math.nan)             # (force N, t s)
        # Longest run at the limit: [current start t, current length, longest length, its t,
        # its peak] for the actuator force and the drive command.
        self._runs = {"actuator force": [math.nan, 0, 0, math.nan, 0.0],
                      "drive command": [math.nan, 0, 0, math.nan, 0.0]}
        self._se = 0.0                  # Σ e² over force-mode play samples, N²
        self._n_force = 0
        self._peak_ref = -math.inf
        self._peak_force = -math.inf
        self._rom = {"roll": [math.inf, -math.inf], "pitch": [math.inf, -math.inf]}
        self._peak_tau = 0.0
        self._peak_qd = 0.0
        self._phase_time = {p.name.lower(): 0.0 for p in Phase}
        self._last_phase = Phase.APPROACH
        self._play_seen = 0
        self._dt = 1.0 / RATE_HZ
        self._tare: np.ndarray | None = None     # the force reader's last tare port

    def add(self, rows: np.ndarray, truth: np.ndarray | None = None) -> None:
        """Session-tap rows; ``truth``: the twin ankle's true torques (roll, pitch, yaw axes,
        N·m) of the same cycles, where a twin runs in process (:class:`TwinAnkleTruth`)."""
        if not len(rows):
            return
        phase = rows[:, COL_PHASE]
        play = phase == Phase.PLAY
        if self._torque is not None and play.any():
            self._torque.add(rows[play][:, COLUMNS["wrench"]],
                             None if truth is None else truth[play][:, :2])
        force = -rows[:, COL_FZ]
        f_ref = rows[:, COL_FREF]
        force_mode = play & (rows[:, COL_CTRL_MODE] > 0.5)
        if force_mode.any():
            # Against the reference the force law tracked: the protocol's, floored at the
            # preload.
            f_ref = np.maximum(f_ref, self.preload_n)
            e = (f_ref - force)[force_mode]
            e = e[~np.isnan(e)]
            self._se += float(np.sum(e ** 2))
            self._n_force += len(e)
            self._peak_ref = max(self._peak_ref, float(np.nanmax(f_ref[force_mode])))
        valid = ~np.isnan(force)
        if valid.any():
            self._peak_force = max(self._peak_force, float(np.max(force[valid])))
        self._contact(rows[:, 0], force, force_mode)
        tau = np.abs(rows[:, COLUMNS["tau"]]).max(axis=1)
        volts = np.abs(rows[:, COLUMNS["volts"]]).max(axis=1)
        self._at_limit("actuator force", rows[:, 0], tau, self.robot.max_actuator_force_n)
        self._at_limit("drive command", rows[:, 0], volts, self.robot.max_command_v)
        self._peak_tau = max(self._peak_tau, float(tau.max()))
        if self._r_ankle is not None and play.any():
            self._add_ankle_torques(rows[play][:, COLUMNS["wrench"]])
        self._peak_qd = max(self._peak_qd, float(np.abs(rows[:, COLUMNS["qd"]]).max()))
        for p in Phase:
            self._phase_time[p.name.lower()] += float(np.count_nonzero(phase == p)) * self._dt
        # Every ROM_DECIMATION-th play sample, counted from the session's first play sample
        # (continuing across calls; the same samples as protocols.session_figures).
        idx = np.flatnonzero(play)
        counter = self._play_seen + np.arange(len(idx))
        self._play_seen += len(idx)
        for q in rows[idx[counter % ROM_DECIMATION == 0]][:, COLUMNS["q"]]:
            cfg = self.kin.fk(q, check=False)
            for axis, angle in (("roll", cfg.roll), ("pitch", cfg.pitch)):
                lo_hi = self._rom[axis]
                lo_hi[0] = min(lo_hi[0], angle)
                lo_hi[1] = max(lo_hi[1], angle)
        self._last_phase = Phase(int(phase[-1]))
        tare = rows[:, COL_TARE:COL_TARE + 10]
        started = np.flatnonzero(tare[:, 0] != TareState.NONE)
        if len(started):
            self._tare = tare[started[-1]].copy()

    def tare(self) -> dict[str, Any] | None:
        """The ATI's tare at the session's start (None: none was asked for, e.g. a position
        protocol): state, the zero subtracted (N, N m) and the force the sensor read
        unloaded, or why it was refused."""
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

    def _ankle_result(self) -> dict[str, Any]:
        """Ankle angles reached (deg from the neutral pose, each in its own direction) and
        peak torques (N·m, each direction's effort as a positive number)."""
        assert self.ankle is not None
        pose = getattr(self.protocol, "pose", None)
        r0 = math.radians(pose.roll_deg) if pose is not None else 0.0
        p0 = math.radians(pose.pitch_deg) if pose is not None else 0.0
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

    def _contact(self, t: np.ndarray, force: np.ndarray, force_mode: np.ndarray) -> None:
        on = self._on
        lo_f, lo_t = self._min_contact
        for k in range(len(t)):          # a state machine over samples (non-real-time thread)
            f = force[k]
            on = bool(force_mode[k]) and (on or f >= self.preload_n)
            if on and f < lo_f:
                lo_f, lo_t = float(f), float(t[k])
        self._on = on
        self._min_contact = (lo_f, lo_t)

    def _at_limit(self, what: str, t: np.ndarray, values: np.ndarray, limit: float) -> None:
        run = self._runs[what]
        over = values >= limit - 1e-9
        for k in np.flatnonzero(over | (run[1] > 0)):   # only samples that start/continue/end
            if over[k]:
                if run[1] == 0:
                    run[0] = float(t[k])
                run[1] += 1
                if run[1] > run[2]:
                    run[2], run[3] = run[1], run[0]
                run[4] = max(run[4], float(values[k]))
            else:
                run[1] = 0

    def saturation(self, dt: float) -> list[str]:
        """The stretches at the robot's limit longer than ``RobotLimits.max_saturation_s``."""
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

    def unloading(self) -> list[str]:
        """The force in contact below the preload (less the sensor's noise), if it happened."""
        f, t = self._min_contact
        if f < self.preload_n - PRELOAD_TOLERANCE_N:
            return [(f"the force falls to {f:.1f} N at t = {t:.3f} s, below the "
                    f"{self.preload_n:g} N preload (the platform would unload or pull on the "
                    "foot)")]
        return []

    def result(self, events: list[SafetyEvent]) -> dict[str, Any]:
        p = self.protocol
        out: dict[str, Any] = {"protocol": p.name, "kind": p.kind, "twin": True}
        if self._n_force:
            # Sine: % of the protocol's amplitude; gait and others: % of the peak reference.
            span = float(p.amplitude_n) if p.kind == "sine_fz" else self._peak_ref
            out["rms_error_pct"] = math.sqrt(self._se / self._n_force) / span * 100.0 \
                if span > 0 else None
            out["rms_error_basis"] = "amplitude" if p.kind == "sine_fz" else "peak"
        else:
            out["rms_error_pct"] = None
        out["peak_force_n"] = self._peak_force if math.isfinite(self._peak_force) else None
        out["min_force_n"] = self._min_contact[0] if math.isfinite(self._min_contact[0]) \
            else None
        source = {k: v for k, v in self.info.items() if k not in ("torque_holds", "dt")}
        if source:
            out["source"] = source
        deg = math.degrees
        out["rom_deg"] = {axis: [deg(lo), deg(hi)] if math.isfinite(lo) else None
                          for axis, (lo, hi) in self._rom.items()}
        if self.ankle is not None:
            out["ankle"] = self._ankle_result()
            if self._torque is not None:
                out["ankle"]["torque_holds"] = self._torque.result()
        out["peak_actuator_force_n"] = self._peak_tau
        out["peak_slider_speed_m_s"] = self._peak_qd
        out["phase_s"] = {k: round(v, 3) for k, v in self._phase_time.items() if v > 0.0}
        out["stops"] = [{"t": round(e.t, 3), "cause": e.cause,
                         "reaction": e.reaction.name.lower(), "message": e.message}
                        for e in events if e.reaction >= Reaction.SOFT_STOP
                        and e.kind == "fault"]
        tare = self.tare()
        if tare is not None:
            out["ati_tare"] = tare
        out["completed"] = self._last_phase == Phase.REST and not out["stops"] \
            and self._phase_time["play"] > 0.0
        return out


def preload_of(pl: PositionLoop) -> float:
    """The force law's preload (N) of a protocol loop's hybrid controller."""
    controller = pl.graph.component("controller")
    return float(getattr(controller, "preload_n", 0.0))


def figures_of(pl: PositionLoop, tap: SignalTap, protocol, model: RobotModel,
               robot_limits: RobotLimits | None = None,
               ankle: AnkleSetup | None = None) -> SessionFigures:
    """The figures of an in-process run whose tap holds the whole session."""
    program = pl.reference.program
    figures = SessionFigures(protocol, model, preload_of(pl), robot_limits,
                             getattr(program, "info", None), ankle)
    rows, _ = tap.drain(0)
    truth = truth_tap(pl)
    figures.add(rows, None if truth is None else truth.drain(0)[0][:, 1:])
    return figures


def summarize(pl: PositionLoop, tap: SignalTap, protocol, model: RobotModel,
              ankle: AnkleSetup | None = None) -> dict:
    """The summary of an in-process run whose tap holds the whole session."""
    return figures_of(pl, tap, protocol, model, ankle=ankle).result(pl.events.snapshot())


def preflight(setup: SessionSetup, model: RobotModel | None = None) -> dict:
    """Check and simulate the protocol; raises ``ProtocolValidationError`` with the reason.

    Refused: the references against the patient's and the robot's limits
    (``ValidationReport.check_against``); on the twin, a supervisor stop, a protocol that does
    not finish, drives saturated or actuator force beyond the limit for longer than
    ``RobotLimits.max_saturation_s``, or a force below the preload (every reason named with its
    time and value).
    """
    model = model or RobotModel.load()
    protocol, _gen, report, pl, tap = build_twin_session(setup, model, "fast")
    problems = report.check_against(setup.patient_limits, setup.robot_limits)
    if problems:
        raise ProtocolValidationError(f"{setup.source}: refused by pre-flight: "
                                      + "; ".join(problems))
    _run(pl, tap, report.duration_s, None)
    rows = tap.ring[:tap.written]
    stops = [e for e in pl.events.snapshot() if e.reaction >= Reaction.SOFT_STOP]
    figures = figures_of(pl, tap, protocol, model, setup.robot_limits, setup.ankle)
    summary = figures.result(pl.events.snapshot())
    predicted = {
        "duration_s": report.duration_s,
        "peak_actuator_force_n": summary["peak_actuator_force_n"],
        "peak_slider_speed_m_s": summary["peak_slider_speed_m_s"],
        "platform_angles_deg": summary["rom_deg"],
        "peak_platform_force_n": summary["peak_force_n"],
        "min_platform_force_n": summary["min_force_n"],
        "rms_error_pct": summary["rms_error_pct"],
    }
    holds = summary.get("ankle", {}).get("torque_holds")
    if holds is not None:
        # Per regulated hold on the twin's passive ankle: the torque reported vs the target
        # and vs the twin ankle's true torque.
        predicted["ankle_torque_holds"] = holds
    if not math.isnan(report.ankle_peak_displacement_m):
        predicted["ankle_displacement_mm"] = {
            "peak": report.ankle_peak_displacement_m * 1e3,
            "rms": report.ankle_rms_displacement_m * 1e3,
            "limit": report.ankle_displacement_limit_m * 1e3}
    if stops:
        raise ProtocolValidationError(
            f"{setup.source}: refused by pre-flight: on the twin the supervisor stopped "
            f"the robot at t = {stops[0].t:.3f} s ({stops[0].cause}: {stops[0].message})")
    problems = figures.saturation(1.0 / RATE_HZ) + figures.unloading()
    if problems:
        raise ProtocolValidationError(f"{setup.source}: refused by pre-flight: on the twin "
                                      + "; ".join(problems))
    if len(rows) and rows[-1, COL_PHASE] < Phase.REST:
        raise ProtocolValidationError(f"{setup.source}: refused by pre-flight: the "
                                      "protocol did not finish on the twin")
    return {"ok": True, "predicted": predicted}


def run_session(setup: SessionSetup, record: Path | None = None,
                progress: Callable[[float], None] | None = None,
                model: RobotModel | None = None, force: bool = False) -> dict:
    """Pre-flight, then the whole session on the in-process twin as fast as possible,
    optionally recorded: the engine of benchmarks and tests (twin figures). A patient's session
    runs in the RT process (``talus session run``).

    ``record`` must not exist (unless ``force``: replaced once the new one is complete) and
    must not be the protocol or a file it reads (``rt.output_files``).
    """
    from protocols.library import protocol_files
    from rt.output_files import check_output
    from rt.recording.writer import SessionRecorder

    inputs = protocol_files(setup.load())
    if record is not None:      # before the pre-flight: a refusal costs nothing
        check_output(record, inputs, force=force, what="recording")

    model = model or RobotModel.load()
    pre = preflight(setup, model)
    protocol, gen, report, pl, tap = build_twin_session(setup, model, "fast")
    recorder = None
    pump = None
    stop_pump = threading.Event()
    if record is not None:
        meta = {"protocol_name": protocol.name,
                "protocol_version": int(getattr(protocol, "schema_version", 1)),
                "parameters": protocol.model_dump(mode="json", exclude={"loaded_from"})
                if hasattr(protocol, "model_dump") else {},
                "patient_id": "twin-demo", "robot_description": model.description.name}
        if getattr(gen, "info", None):
            meta["source"] = gen.info          # traceability of the replayed record
        meta["preload_n"] = preload_of(pl)     # the force law's floor (the error's reference)
        if setup.ankle is not None:
            meta["ankle"] = setup.ankle.model_dump()   # where the ankle centre was
        recorder = SessionRecorder(record, meta, force=force, inputs=inputs)
        recorder.attach_state_ring(pl.recorder, start=0)
        pl.events.listener = recorder.event
        ankle = None if setup.ankle is None else AnkleMonitor(model.kin, setup.ankle,
                                                              start_pose(gen))
        pump = threading.Thread(target=_pump, args=(tap, recorder, stop_pump, ankle),
                                daemon=True)
        pump.start()
    try:
        _run(pl, tap, report.duration_s, progress)
    finally:
        pl.graph.stop()
        stop_pump.set()
        if pump is not None:
            pump.join()
    summary = summarize(pl, tap, protocol, model, setup.ankle)
    summary["preflight"] = pre["predicted"]
    if recorder is not None:
        info = recorder.close()
        summary["recording"] = {"path": str(record), "sha256": info.get("sha256")}
    else:
        summary["recording"] = None
    return summary


def _pump(tap: SignalTap, recorder, stop: threading.Event,
          ankle: AnkleMonitor | None = None) -> None:
    """Non-real-time: the tap's rows → the recorder's channels."""
    start = 0
    while True:
        final = stop.wait(0.05)
        rows, start = tap.drain(start)
        record_rows(recorder, rows, ankle)
        if final:
            return


def progress_bar(stream=sys.stderr) -> Callable[[float], None]:
    def show(fraction: float) -> None:
        n = int(fraction * 40)
        stream.write(f"\r[{'#' * n}{'.' * (40 - n)}] {fraction * 100:5.1f} %")
        stream.flush()
        if fraction >= 1.0:
            stream.write("\n")
    return show
