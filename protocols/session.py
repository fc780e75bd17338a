"""A clinical session without the GUI: check the protocol, run it on the twin first (pre-flight),
then for real, record everything, summarize (``talus session run``).

Pre-flight refuses a protocol — with the reason — when its own validation reports a violation,
when its references break the patient's or the robot's limits, or when running it on the twin
as fast as possible makes the safety supervisor stop the robot. Its report gives the predicted
peaks: actuator force, slider speed, platform angles and platform force.
"""
from __future__ import annotations

import math
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from protocols.generators import make_generator
from protocols.library import load_protocol
from rt.components.blocks import SignalTap
from rt.errors import ProtocolValidationError
from rt.model import RobotModel
from rt.position_loop import PositionLoop, build_protocol_loop, sim_devices
from rt.safety.events import Reaction
from rt.safety.limits import PatientLimits, ProtocolLimits, RobotLimits
from rt.twin.environment import CompliantAnkle, parse_environment
from rt.twin.twin import SimClock, Twin

RATE_HZ = 1000.0
#: Columns of the session tap (after t): wrench 6, flags 2, force ref 3, ctrl mode, phase,
#: progress.
SIGNALS = [("wrench", 6), ("flags", 2), ("force", 3), ("ctrl_mode", 1), ("phase", 1),
           ("progress", 1)]
W, FLAGS, FREF, CMODE, PHASE, PROG = 1, 7, 9, 12, 13, 14


@dataclass
class SessionSetup:
    protocol_path: Path
    patient_weight_kg: float | None = None
    patient_limits: PatientLimits = field(default_factory=PatientLimits)
    robot_limits: RobotLimits = field(default_factory=RobotLimits)
    environment: str | None = None
    seed: int = 0


def _protocol_limits(protocol) -> ProtocolLimits | None:
    lim = getattr(protocol, "limits", None)
    if lim is None:
        return None
    return ProtocolLimits(**{k: v for k, v in lim.model_dump().items()
                             if k in ProtocolLimits.model_fields})


def _environment(setup: SessionSetup, sensor_z: float, roll: float, pitch: float):
    if setup.environment:
        return parse_environment(setup.environment)
    # The patient's strapped foot, unloaded where the protocol starts (the clinician sets the
    # platform under the foot before the session).
    return CompliantAnkle(neutral_z_m=sensor_z, neutral_roll_rad=roll, neutral_pitch_rad=pitch,
                          limb_weight_n=0.0)


def _build(setup: SessionSetup, model: RobotModel, mode: str):
    protocol = load_protocol(setup.protocol_path)
    gen = make_generator(protocol, dt=1.0 / RATE_HZ, kinematics=model.kin,
                         patient_weight_kg=setup.patient_weight_kg)
    report = gen.validate()
    if not report.ok:
        raise ProtocolValidationError(f"{setup.protocol_path}: " + "; ".join(report.violations))
    clock = SimClock()
    start = gen.new_output()
    gen.update(start)
    gen.reset()
    z0, roll0, pitch0 = (float(x) for x in start.pose_ref)
    env = _environment(setup, z0 + model.description.sensor.offset_m[2], roll0, pitch0)
    twin = Twin(model.description, env, seed=setup.seed, clock=clock)
    twin.place(model.kin.ik(z0, roll0, pitch0).q)
    n = int((report.duration_s + 15.0) * RATE_HZ)
    tap = SignalTap("session", SIGNALS, capacity=n)
    pl = build_protocol_loop(sim_devices(twin, clock), gen, model, RATE_HZ, mode,
                             robot_limits=setup.robot_limits,
                             patient_limits=setup.patient_limits,
                             protocol_limits=_protocol_limits(protocol), extra_blocks=[tap],
                             extra_connections=[
                                 ("force.wrench", "session.wrench"),
                                 ("force.flags", "session.flags"),
                                 ("reference.force", "session.force"),
                                 ("reference.ctrl_mode", "session.ctrl_mode"),
                                 ("reference.phase", "session.phase"),
                                 ("reference.progress", "session.progress")])
    return protocol, gen, report, pl, tap


def _check_static_limits(report, setup: SessionSetup) -> list[str]:
    """The references themselves against the patient's and the robot's limits."""
    p, r = setup.patient_limits, setup.robot_limits
    out = []
    rad = math.radians
    lo, hi = report.roll_range_rad
    if not math.isnan(lo) and (lo < rad(p.roll_min_deg) or hi > rad(p.roll_max_deg)):
        out.append(f"roll range [{math.degrees(lo):.1f}, {math.degrees(hi):.1f}] deg exceeds the "
                   f"patient's ROM [{p.roll_min_deg}, {p.roll_max_deg}] deg")
    lo, hi = report.pitch_range_rad
    if not math.isnan(lo) and (lo < rad(p.pitch_min_deg) or hi > rad(p.pitch_max_deg)):
        out.append(f"pitch range [{math.degrees(lo):.1f}, {math.degrees(hi):.1f}] deg exceeds "
                   f"the patient's ROM [{p.pitch_min_deg}, {p.pitch_max_deg}] deg")
    if not math.isnan(report.peak_fz_n) and report.peak_fz_n > min(p.max_force_n,
                                                                   r.max_platform_force_n):
        out.append(f"peak force {report.peak_fz_n:.0f} N exceeds the limit "
                   f"{min(p.max_force_n, r.max_platform_force_n):.0f} N")
    for name, value in (("roll", report.peak_roll_rate_rad_s),
                        ("pitch", report.peak_pitch_rate_rad_s)):
        if not math.isnan(value) and value > rad(p.max_angular_speed_deg_s):
            out.append(f"{name} rate {math.degrees(value):.0f} deg/s exceeds the patient's "
                       f"{p.max_angular_speed_deg_s} deg/s")
    if not math.isnan(report.peak_slider_speed_m_s) and \
            report.peak_slider_speed_m_s > r.max_slider_speed_m_s:
        out.append(f"slider speed {report.peak_slider_speed_m_s:.3f} m/s exceeds the robot's "
                   f"{r.max_slider_speed_m_s} m/s")
    return out


def _run(pl: PositionLoop, tap: SignalTap, duration_s: float,
         progress: Callable[[float], None] | None) -> None:
    """Run until the protocol is done and back at rest, or the supervisor stopped it.

    In real time the loop runs in its own thread for the whole session, watched from here:
    restarting a real-time loop costs a garbage collection and re-phasing, a gap the twin
    would see as the drives holding their last command for that long. In fast mode (simulated
    time) the loop is simply run in slices.
    """
    end = duration_s + 10.0

    def finished() -> bool:
        row = tap.ring[(tap.written - 1) % tap.capacity]
        if progress is not None and tap.written:
            progress(float(row[PROG]))
        return bool(tap.written) and (row[PHASE] >= 4
                                      or pl.supervisor.reaction >= Reaction.SOFT_STOP)

    if pl.loop.mode == "realtime":
        pl.loop.start()
        try:
            t0 = time.monotonic()
            while time.monotonic() - t0 < end and not finished():
                time.sleep(0.1)
            time.sleep(0.6)            # let it come to rest
        finally:
            pl.loop.stop()
        return
    t = 0.0
    while t < end:
        pl.loop.run(seconds=0.1)
        t += 0.1
        if finished():
            pl.loop.run(seconds=0.6)
            break


def summarize(pl: PositionLoop, tap: SignalTap, protocol, model: RobotModel) -> dict:
    """The session's figures (measured on the twin: twin figures)."""
    rows = tap.ring[:tap.written]
    state, _ = pl.recorder.drain(0)
    n = min(len(rows), len(state))
    rows, state = rows[:n], state[:n]
    play = rows[:, PHASE] == 1
    force = -rows[:, W + 2]
    f_ref = rows[:, FREF]
    force_mode = play & (rows[:, CMODE] > 0.5)
    out: dict = {"protocol": protocol.name, "kind": protocol.kind, "twin": True}
    if force_mode.any():
        e = (f_ref - force)[force_mode]
        e = e[~np.isnan(e)]
        ref = f_ref[force_mode]
        # Sine: % of the protocol's amplitude; gait and others: % of the peak reference.
        span = float(protocol.amplitude_n) if protocol.kind == "sine_fz" \
            else float(np.nanmax(ref))
        out["rms_error_pct"] = float(np.sqrt(np.mean(e ** 2)) / span * 100.0) if span > 0 \
            else None
        out["rms_error_basis"] = "amplitude" if protocol.kind == "sine_fz" else "peak"
    else:
        out["rms_error_pct"] = None
    valid = ~np.isnan(force)
    out["peak_force_n"] = float(np.max(force[valid])) if valid.any() else None
    rolls, pitches = [], []
    for q in state[play][::10, 1:4]:
        cfg = model.kin.fk(q, check=False)
        rolls.append(cfg.roll)
        pitches.append(cfg.pitch)
    deg = math.degrees
    out["rom_deg"] = {"roll": [deg(min(rolls)), deg(max(rolls))] if rolls else None,
                      "pitch": [deg(min(pitches)), deg(max(pitches))] if pitches else None}
    out["stops"] = [{"t": round(e.t, 3), "cause": e.cause, "reaction": e.reaction.name.lower(),
                     "message": e.message} for e in pl.events.snapshot()
                    if e.reaction >= Reaction.SOFT_STOP]
    out["completed"] = bool(rows[-1, PHASE] >= 4) and not out["stops"]
    return out


def preflight(setup: SessionSetup, model: RobotModel | None = None) -> dict:
    """Check and simulate the protocol; raises ``ProtocolValidationError`` with the reason."""
    model = model or RobotModel.load()
    protocol, gen, report, pl, tap = _build(setup, model, "fast")
    problems = _check_static_limits(report, setup)
    if problems:
        raise ProtocolValidationError(f"{setup.protocol_path}: refused by pre-flight: "
                                      + "; ".join(problems))
    _run(pl, tap, report.duration_s, None)
    rows = tap.ring[:tap.written]
    state, _ = pl.recorder.drain(0)
    stops = [e for e in pl.events.snapshot() if e.reaction >= Reaction.SOFT_STOP]
    summary = summarize(pl, tap, protocol, model)
    predicted = {
        "duration_s": report.duration_s,
        "peak_actuator_force_n": float(np.abs(state[:, 10:13]).max()),
        "peak_slider_speed_m_s": float(np.abs(state[:, 4:7]).max()),
        "platform_angles_deg": summary["rom_deg"],
        "peak_platform_force_n": summary["peak_force_n"],
        "rms_error_pct": summary["rms_error_pct"],
    }
    if stops:
        raise ProtocolValidationError(
            f"{setup.protocol_path}: refused by pre-flight: on the twin the supervisor stopped "
            f"the robot at t = {stops[0].t:.3f} s ({stops[0].cause}: {stops[0].message})")
    if len(rows) and rows[-1, PHASE] < 4:
        raise ProtocolValidationError(f"{setup.protocol_path}: refused by pre-flight: the "
                                      "protocol did not finish on the twin")
    return {"ok": True, "predicted": predicted}


def run_session(setup: SessionSetup, record: Path | None = None, realtime: bool = True,
                progress: Callable[[float], None] | None = None,
                model: RobotModel | None = None) -> dict:
    """Pre-flight, then the real run (on the twin, in real time by default), recorded."""
    from rt.recording.writer import SessionRecorder

    model = model or RobotModel.load()
    pre = preflight(setup, model)
    protocol, gen, report, pl, tap = _build(setup, model, "realtime" if realtime else "fast")
    recorder = None
    pump = None
    stop_pump = threading.Event()
    if record is not None:
        meta = {"protocol_name": protocol.name,
                "protocol_version": int(getattr(protocol, "schema_version", 1)),
                "parameters": protocol.model_dump(mode="json", exclude={"loaded_from"})
                if hasattr(protocol, "model_dump") else {},
                "patient_id": "twin-demo", "robot_description": model.description.name}
        recorder = SessionRecorder(record, meta)
        recorder.attach_state_ring(pl.recorder, start=0)
        pl.events.listener = recorder.event
        pump = threading.Thread(target=_pump, args=(tap, recorder, stop_pump), daemon=True)
        pump.start()
    try:
        _run(pl, tap, report.duration_s, progress)
    finally:
        pl.graph.stop()
        stop_pump.set()
        if pump is not None:
            pump.join()
    summary = summarize(pl, tap, protocol, model)
    summary["preflight"] = pre["predicted"]
    if recorder is not None:
        info = recorder.close()
        summary["recording"] = {"path": str(record), "sha256": info.get("sha256")}
    else:
        summary["recording"] = None
    return summary


def _pump(tap: SignalTap, recorder, stop: threading.Event) -> None:
    """Non-real-time: the tap's wrench and reference rows → the recorder's channels."""
    start = 0
    while True:
        final = stop.wait(0.05)
        rows, start = tap.drain(start)
        for r in rows:
            t = float(r[0])
            recorder.wrench(t, *(float(x) for x in r[W:W + 6]), bool(r[FLAGS] > 0.5),
                            bool(r[FLAGS + 1] > 0.5))
            recorder.publish("/protocol/reference", {
                "t": t, "force": [0.0, 0.0, float(r[FREF])],
                "phase": ("approach", "play", "return", "stopped", "done")[int(r[PHASE])],
                "mode": "force" if r[CMODE] > 0.5 else "position"})
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
