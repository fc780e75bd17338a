"""The position loop assembled from its blocks (thesis 3.7.3 modular layout with supervisor,
at 1 kHz).

    twin → encoders → estimator ─┬→ model state ─→ controller ─→ supervisor → redundant drive
      force sensor, stop inputs ─┼──────────────────────────────↗     │  (two DAC cards)
                                 └→ reference ←── mode (one cycle late)┘
                                                   recorder tap ← q, q̇, q_ref, τ, V

``build_sim_position_loop`` wires it on the digital twin (the default backend); the same blocks
take the real encoder, DAC and sensor backends on the rig.
"""
from __future__ import annotations

from dataclasses import dataclass

from rt.components.blocks import (ControllerBlock, EncoderReader, ModelState, RecorderTap,
                                  TrajectoryReference, VelocityEstimation)
from rt.components.safety_blocks import ForceReader, RedundantDrive, StopInputs, SupervisorBlock
from rt.components.twin_step import TwinStep
from rt.control.base import create
from rt.control.experiment import RefFn, benchmark_reference
from rt.engine import Graph, GraphBuilder, Loop
from rt.model import RobotModel
from rt.safety.events import EventLog
from rt.safety.limits import PatientLimits, ProtocolLimits, RobotLimits, effective
from rt.safety.supervisor import Supervisor
from rt.twin.backends import TwinActuators, TwinDigitalInputs, TwinEncoders, TwinForceTorque
from rt.twin.environment import FreeMotion
from rt.twin.twin import SimClock, Twin


@dataclass
class PositionLoop:
    loop: Loop
    graph: Graph
    model: RobotModel
    twin: Twin | None
    recorder: RecorderTap
    reference: TrajectoryReference
    supervisor: Supervisor
    events: EventLog

    def close(self) -> None:
        self.graph.stop() if self.loop.running else None


def build_sim_position_loop(controller: str = "paden_panja", gains: dict | None = None,
                            trajectory: RefFn | None = None, duration_s: float = 26.0,
                            environment=None, rate_hz: float = 1000.0, mode: str = "fast",
                            seed: int = 0, start_q: tuple[float, float, float] = (0.2, 0.2, 0.2),
                            model: RobotModel | None = None,
                            robot_limits: RobotLimits | None = None,
                            patient_limits: PatientLimits | None = None,
                            protocol_limits: ProtocolLimits | None = None,
                            twin: Twin | None = None, extra_blocks: list | None = None,
                            start_program: bool = True, **loop_kwargs) -> PositionLoop:
    """A configured, started position loop on the twin (run it with ``.loop.run(...)``).

    With ``start_program`` the trajectory (default: the benchmark) starts at the first cycle;
    without, the robot holds where it is until a program is requested."""
    model = model or RobotModel.load()
    d = model.description
    clock = SimClock()
    if twin is None:
        twin = Twin(d, environment or FreeMotion(), seed=seed, clock=clock)
        twin.place(start_q)
    else:
        twin.clock = clock
    cards = [TwinActuators(twin, 0), TwinActuators(twin, 1)]
    events = EventLog()
    limits = effective(tuple(d.limits.stroke_m), robot_limits or RobotLimits(),
                       patient_limits or PatientLimits(), protocol_limits)
    supervisor = Supervisor(limits, 1.0 / rate_hz, events)
    b = GraphBuilder()
    b.add(TwinStep("twin", twin, clock))
    b.add(EncoderReader("encoders", TwinEncoders(twin)))
    b.add(ForceReader("force", TwinForceTorque(twin)))
    b.add(StopInputs("stops", TwinDigitalInputs(twin)))
    b.add(VelocityEstimation("estimator"))
    b.add(ModelState("model", model))
    program = (trajectory or benchmark_reference()) if start_program else None
    ref = b.add(TrajectoryReference("reference", program, duration_s,
                                    tuple(d.limits.stroke_m), rate_hz))
    b.add(ControllerBlock("controller", create(controller, model, gains)), slot="controller")
    b.add(SupervisorBlock("supervisor", supervisor, d.drive.force_per_volt_n))
    b.add(RedundantDrive("drive", cards, events, monitor=lambda: twin.amp_volts))
    rec = b.add(RecorderTap("recorder"))
    for block in extra_blocks or ():
        b.add(block)                       # port-less observers (e.g. the fault matrix probe)
    for src, dst in (
            ("encoders.q", "estimator.q_meas"), ("encoders.q", "model.q_meas"),
            ("estimator.qd", "model.qd"), ("encoders.q", "reference.q_meas"),
            ("model.state", "controller.state"), ("reference.q_ref", "controller.q_ref"),
            ("reference.qd_ref", "controller.qd_ref"), ("reference.qdd_ref", "controller.qdd_ref"),
            ("encoders.q", "supervisor.q"), ("estimator.status", "supervisor.est_status"),
            ("estimator.qd", "supervisor.qd"), ("estimator.qdd", "supervisor.qdd"),
            ("model.state", "supervisor.state"), ("model.fk_ok", "supervisor.fk_ok"),
            ("reference.q_ref", "supervisor.q_ref"), ("reference.qd_ref", "supervisor.qd_ref"),
            ("controller.tau", "supervisor.tau"), ("force.wrench", "supervisor.wrench"),
            ("force.flags", "supervisor.wrench_flags"), ("stops.inputs", "supervisor.inputs"),
            ("supervisor.volts", "drive.volts"), ("supervisor.enable", "drive.enable"),
            ("encoders.q", "recorder.q"), ("estimator.qd", "recorder.qd"),
            ("reference.q_ref", "recorder.q_ref"), ("controller.tau", "recorder.tau"),
            ("supervisor.volts", "recorder.volts")):
        b.connect(src, dst)
    # The supervisor's verdict reaches the reference and the controller one cycle later, and
    # the drive's failure flag the supervisor: these are the loop's only feedback edges.
    b.connect("supervisor.mode", "reference.mode", delay=1)
    b.connect("supervisor.mode", "controller.mode", delay=1)
    b.connect("drive.failed", "supervisor.drive_failed", delay=1)
    graph = b.build()
    graph.configure()
    loop = Loop(graph, rate_hz=rate_hz, mode=mode, **loop_kwargs)
    graph.start()
    return PositionLoop(loop, graph, model, twin, rec, ref, supervisor, events)


def swap_controller(pl: PositionLoop, controller: str, gains: dict | None = None):
    """Swap the control law at the next cycle boundary, bumplessly; returns the command result."""
    return pl.loop.swap("controller", ControllerBlock(f"controller_{controller}",
                                                      create(controller, pl.model, gains)))
