"""A clinical session's protocol side: check the protocol, run it on the twin first
(pre-flight), compute the session's figures; the RT process runs the real session
(``protocols.rt_session`` is what it is given to prepare one).

Pre-flight refuses a protocol — with the reason — when its own validation reports a violation,
when its references break the patient's or the robot's limits, or when running it on the twin
as fast as possible makes the safety supervisor stop the robot. Its report gives the predicted
peaks: actuator force, slider speed, platform angles and platform force.

The figures (:class:`protocols.session_figures.SessionFigures`, the one definition the session
report uses too) are computed from the session tap's rows (``rt.sessions.SESSION_SIGNALS``) as
they stream, so an hour at 1 kHz is never held at once; pre-flight, the in-process twin run
(benchmarks) and the RT process all use them.
"""
from __future__ import annotations

import math
import os
import sys
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from protocols.generators import make_generator
from protocols.library import load_protocol
from protocols.schema import ProtocolModel
from protocols.session_figures import SessionFigures
from rt.components.blocks import SignalTap
from rt.engine import Array, Component
from rt.errors import InputError, ProtocolValidationError
from rt.model import RobotModel
from rt.model.ankle import AnkleMonitor, AnkleSetup
from rt.position_loop import PositionLoop, build_protocol_loop, sim_devices
from rt.references.sequencer import Phase
from rt.safety.events import Reaction
from rt.safety.limits import PatientLimits, ProtocolLimits, RobotLimits
from rt.sessions import (
    COL_PHASE,
    COL_PROGRESS,
    SESSION_SIGNALS,
    SESSION_SOURCES,
    record_rows,
)
from rt.twin.environment import CompliantAnkle, parse_environment, patient_foot
from rt.twin.twin import SimClock, Twin

RATE_HZ = 1000.0


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
         progress: Callable[[float], None] | None, driver: Any = None) -> None:
    """Run the in-process twin as fast as possible until the protocol is done and back at
    rest, or the supervisor stopped it (then 0.6 s more, to come to rest). A real session runs
    in the RT process, never here. ``driver`` (``rt.preflight.driver.PreflightDriver``) runs
    the same cycles, the steady ones compiled."""
    end = duration_s + 10.0
    run = (driver.run if driver is not None
           else (lambda seconds: pl.loop.run(seconds=seconds)))

    def finished() -> bool:
        row = tap.ring[(tap.written - 1) % tap.capacity]
        if progress is not None and tap.written:
            progress(float(row[COL_PROGRESS]))
        return bool(tap.written) and (row[COL_PHASE] >= Phase.REST
                                      or pl.supervisor.reaction >= Reaction.SOFT_STOP)

    t = 0.0
    while t < end:
        run(0.1)
        t += 0.1
        if finished():
            run(0.6)
            break


def preload_of(pl: PositionLoop) -> float:
    """The force law's preload (N) of a protocol loop's hybrid controller."""
    controller = pl.graph.component("controller")
    return float(getattr(controller, "preload_n", 0.0))


def figures_of(pl: PositionLoop, tap: SignalTap, protocol, model: RobotModel,
               robot_limits: RobotLimits | None = None,
               ankle: AnkleSetup | None = None) -> SessionFigures:
    """The figures of an in-process run whose tap holds the whole session."""
    program = pl.reference.program
    figures = SessionFigures.for_protocol(protocol, model, preload_of(pl), robot_limits,
                                          getattr(program, "info", None), ankle, RATE_HZ)
    rows, _ = tap.drain(0)
    truth = truth_tap(pl)
    figures.add(rows, None if truth is None else truth.drain(0)[0][:, 1:])
    return figures


def summarize(pl: PositionLoop, tap: SignalTap, protocol, model: RobotModel,
              ankle: AnkleSetup | None = None) -> dict:
    """The summary of an in-process run whose tap holds the whole session."""
    return figures_of(pl, tap, protocol, model, ankle=ankle).result(pl.events.snapshot())


def drive_saturation_margin(peak_per_axis_s: list[float], limits: RobotLimits) -> dict:
    """The most saturated time any of the supervisor's sliding windows held, per axis and the
    largest (s), beside what stops the robot: more than ``stops_beyond_s`` at the drives' limit
    within any ``window_s`` (``RobotLimits.max_saturated_fraction`` × ``saturation_window_s``).
    A heel strike's few ms are far from it; a protocol close to it would be stopped by a
    slightly heavier patient or a stiffer contact."""
    peaks = [float(x) for x in peak_per_axis_s]
    return {"peak_s": max(peaks, default=0.0), "per_axis_s": peaks,
            "window_s": limits.saturation_window_s,
            "stops_beyond_s": limits.max_saturated_fraction * limits.saturation_window_s}


#: Whether a pre-flight's graph times its blocks (``Graph.timed``). No verdict reads the
#: times; ``bench/preflight.py --blocks`` turns it on to show where the CPU goes.
PREFLIGHT_TIMED = False
#: ``TALUS_PREFLIGHT_DRIVER=0`` in the environment (read at each pre-flight) runs every
#: cycle of a pre-flight through the loop instead of the compiled driver
#: (``rt.preflight.driver``; issue 16): the reference the driver is held to
#: (``tests/test_preflight_paths.py``).
PREFLIGHT_DRIVER_ENV = "TALUS_PREFLIGHT_DRIVER"


def preflight(setup: SessionSetup, model: RobotModel | None = None) -> dict:
    """Check and simulate the protocol; raises ``ProtocolValidationError`` with the reason.

    Refused: the references against the patient's and the robot's limits
    (``ValidationReport.check_against``); on the twin, a supervisor stop, a protocol that does
    not finish, drives saturated or actuator force beyond the limit for longer than
    ``RobotLimits.max_saturation_s``, or a force below the preload (every reason named with its
    time and value).
    """
    from rt.preflight.driver import PreflightDriver

    model = model or RobotModel.load()
    protocol, _gen, report, pl, tap = build_twin_session(setup, model, "fast")
    # Nobody reads the blocks' times: the same cycle without its clock reads (issue 16).
    pl.graph.timed = PREFLIGHT_TIMED
    # Nobody drains the loop's recorder tap in a pre-flight either (the session tap holds
    # every row the verdict reads), but it stays running: its row is one compiled stage, and
    # the fused segment's fast path (and so the compiled driver) needs the whole segment.
    problems = report.check_against(setup.patient_limits, setup.robot_limits)
    if problems:
        raise ProtocolValidationError(f"{setup.source}: refused by pre-flight: "
                                      + "; ".join(problems))
    # The compiled driver (issue 16) where the loop's shape allows it (``why_not``: the
    # twin ankle's truth block of an ankle setup, a timed graph, no fused segment); it runs
    # the same cycles as the loop, the steady ones in one compiled call.
    driver = (PreflightDriver(pl, tap) if os.environ.get(PREFLIGHT_DRIVER_ENV, "1") != "0"
              else None)
    _run(pl, tap, report.duration_s, None,
         driver if driver is not None and not driver.why_not else None)
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
        # Where the protocol was beyond the robot (the drives at their limit), even briefly.
        "at_robot_limit": figures.at_limit(1.0 / RATE_HZ),
        # How close it came to the sustained-saturation stop (``drive_saturated_<axis>``).
        "drive_saturation": drive_saturation_margin(pl.supervisor.saturated_peak_s,
                                                    setup.robot_limits),
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
    saturated = figures.saturation(1.0 / RATE_HZ)
    if stops:
        # A stop for sustained drive saturation: the stretches at the robot's limit say where
        # the protocol asked more than the drives give.
        why = "; ".join(saturated) if stops[0].cause.startswith("drive_saturated_") else ""
        raise ProtocolValidationError(
            f"{setup.source}: refused by pre-flight: on the twin the supervisor stopped "
            f"the robot at t = {stops[0].t:.3f} s ({stops[0].cause}: {stops[0].message})"
            + (f"; {why}" if why else ""))
    problems = saturated + figures.unloading()
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
        # The pump gives these for every cycle: talus.v4 joins them with the state.
        recorder.expect("/robot/wrench", "/protocol/reference")
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
