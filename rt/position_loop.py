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

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from rt.components.blocks import (
    ControllerBlock,
    EncoderReader,
    ModelState,
    RecorderTap,
    VelocityEstimation,
)
from rt.components.fused import attach as attach_fused_cycle
from rt.components.safety_blocks import ForceReader, RedundantDrive, StopInputs, SupervisorBlock
from rt.components.twin_step import TwinStep
from rt.control.base import Controller, create
from rt.control.experiment import RefFn, benchmark_reference
from rt.devices.interfaces import ActuatorOutputs, DigitalInputs, EncoderBank, ForceTorqueSensor
from rt.engine import Component, Graph, GraphBuilder, Loop
from rt.errors import ConfigurationError, HardwareError
from rt.model import RobotModel
from rt.model.description import RobotDescription
from rt.references.program import Program, TrajectoryProgram
from rt.references.sequencer import YIELD_LEAD_TRACKING, ProgramReference
from rt.safety.events import EventLog
from rt.safety.limits import PatientLimits, ProtocolLimits, RobotLimits, effective
from rt.safety.supervisor import Supervisor, supervisor_physics
from rt.twin.backends import TwinActuators, TwinDigitalInputs, TwinEncoders, TwinForceTorque
from rt.twin.environment import FreeMotion
from rt.twin.realism import RigImperfections
from rt.twin.twin import SimClock, Twin


@dataclass
class PositionLoop:
    loop: Loop
    graph: Graph
    model: RobotModel
    twin: Twin | None
    recorder: RecorderTap
    reference: ProgramReference
    supervisor: Supervisor
    events: EventLog
    devices: Devices | None = None

    @property
    def controller(self) -> Controller:
        """The position law in the ``controller`` slot (the one the RT process reports and
        tunes), whichever block hosts it."""
        law = getattr(self.graph.component("controller"), "controller", None)
        if not isinstance(law, Controller):
            raise ConfigurationError("the controller slot hosts no position control law")
        return law


@dataclass
class Devices:
    """What the loop talks to: the twin in-process ("sim"), the rig process over shared memory
    ("twin_shm") or, on the rig, the real cards. ``monitor`` reads the amplifier inputs back
    (the rig's current monitors; None when no reading newer than the last command is available
    yet); ``feed_watchdog`` is called at the end of every cycle;
    ``first`` is a block run before everything else (the in-process twin's physics)."""

    encoders: EncoderBank
    cards: Sequence[ActuatorOutputs]
    force: ForceTorqueSensor
    stops: DigitalInputs
    monitor: Callable[[], Sequence[float] | np.ndarray | None] | None = None
    feed_watchdog: Callable[[], None] | None = None
    watchdog_tripped: Callable[[], bool] | None = None
    rearm_watchdog: Callable[[], None] | None = None
    first: Component | None = None
    twin: Twin | None = None
    close: Callable[[], None] | None = None


def sim_devices(twin: Twin, clock: SimClock) -> Devices:
    """The in-process twin, advanced by the loop in lockstep."""
    return Devices(TwinEncoders(twin), [TwinActuators(twin, 0), TwinActuators(twin, 1)],
                   TwinForceTorque(twin), TwinDigitalInputs(twin),
                   monitor=lambda: twin.amp_volts, first=TwinStep("twin", twin, clock),
                   twin=twin)


def shm_devices(shm_name: str) -> Devices:
    """The rig process (``talus twin rig --shm NAME``) over shared memory; the loop feeds its
    amplifier watchdog every cycle, so a dead or stalled loop drops the drives."""
    from rt.twin.shm_backends import (
        ShmActuators,
        ShmDigitalInputs,
        ShmEncoders,
        ShmForceTorque,
        ShmRig,
    )

    rig = ShmRig(shm_name)
    cards = [ShmActuators(rig, 0), ShmActuators(rig, 1)]
    return Devices(ShmEncoders(rig), cards, ShmForceTorque(rig), ShmDigitalInputs(rig),
                   monitor=rig.applied_volts, feed_watchdog=rig.feed_watchdog,
                   watchdog_tripped=rig.watchdog_tripped, rearm_watchdog=rig.rearm,
                   close=rig.close)


class WatchdogFeed(Component):
    """Ports: none. Feeds the amplifier watchdog at the end of each cycle: only a loop that
    completes its cycles keeps the drives powered.

    With ``tripped`` (the watchdog's latched state) the block faults when the watchdog has
    dropped the drives (the loop stalled longer than its timeout): the supervisor then
    hard-stops naming it, and the operator's reset restarts the block, which re-arms the
    watchdog (``rearm``; honoured by the amplifiers only once feeding has resumed)."""

    def __init__(self, name: str, feed: Callable[[], None],
                 tripped: Callable[[], bool] | None = None,
                 rearm: Callable[[], None] | None = None):
        super().__init__(name)
        self.feed = feed
        self.tripped = tripped
        self.rearm = rearm

    def on_start(self) -> None:
        if self.rearm is not None:
            self.feed()
            self.rearm()

    def update(self, t: float, dt: float) -> int:
        self.feed()
        if self.tripped is not None and self.tripped():
            raise HardwareError("the amplifiers' watchdog dropped the drives (the loop stalled "
                                "longer than its timeout)")
        return 0


def build_sim_position_loop(controller: str = "paden_panja", gains: dict | None = None,
                            trajectory: RefFn | None = None, duration_s: float = 26.0,
                            environment=None, rate_hz: float = 1000.0, mode: str = "fast",
                            seed: int = 0, start_q: tuple[float, float, float] = (0.2, 0.2, 0.2),
                            model: RobotModel | None = None, twin: Twin | None = None,
                            truth: RobotDescription | None = None,
                            imperfections: RigImperfections | None = None,
                            **kwargs) -> PositionLoop:
    """A configured, started position loop on the in-process twin (``.loop.run(...)``).

    The controllers use ``model`` (what the lab believes); the twin is ``twin``, or one built
    from ``truth`` (default: the realistic twin's perturbed truth) and ``imperfections``."""
    model = model or RobotModel.load()
    clock = SimClock()
    if twin is None:
        twin = Twin(truth, environment or FreeMotion(), seed=seed, clock=clock,
                    imperfections=imperfections)
        twin.place(start_q)
    else:
        twin.clock = clock
    return build_position_loop(sim_devices(twin, clock), controller, gains, trajectory,
                               duration_s, rate_hz=rate_hz, mode=mode, model=model, **kwargs)


def build_position_loop(devices: Devices, controller: str = "paden_panja",
                        gains: dict | None = None, trajectory: RefFn | None = None,
                        duration_s: float = 26.0, rate_hz: float = 1000.0, mode: str = "fast",
                        model: RobotModel | None = None,
                        robot_limits: RobotLimits | None = None,
                        patient_limits: PatientLimits | None = None,
                        protocol_limits: ProtocolLimits | None = None,
                        extra_blocks: list | None = None, start_program: bool = True,
                        **loop_kwargs) -> PositionLoop:
    """The position loop over ``devices``, configured and started.

    With ``start_program`` the trajectory (default: the benchmark) starts at the first cycle;
    without, the robot holds where it is until a program is requested."""
    model = model or RobotModel.load()
    program = TrajectoryProgram(trajectory or benchmark_reference(), duration_s,
                                1.0 / rate_hz) if start_program else None
    reference = ProgramReference("reference", model.description.limits.stroke,
                                 1.0 / rate_hz, program)
    return _assemble(devices, model, reference,
                     lambda sup: ControllerBlock("controller", create(controller, model, gains)),
                     [], rate_hz, mode, robot_limits, patient_limits, protocol_limits,
                     extra_blocks, None, loop_kwargs)


def swap_controller(pl: PositionLoop, controller: str, gains: dict | None = None):
    """Swap the control law at the next cycle boundary, bumplessly; returns the command result."""
    return pl.loop.swap("controller", ControllerBlock(f"controller_{controller}",
                                                      create(controller, pl.model, gains)))


def build_protocol_loop(devices: Devices, program: Program | None = None,
                        model: RobotModel | None = None, rate_hz: float = 1000.0,
                        mode: str = "fast", robot_limits: RobotLimits | None = None,
                        patient_limits: PatientLimits | None = None,
                        protocol_limits: ProtocolLimits | None = None,
                        force_gains: dict | None = None, extra_blocks: list | None = None,
                        extra_connections: list[tuple[str, str]] | None = None,
                        controller: str = "paden_panja", gains: dict | None = None,
                        **loop_kwargs) -> PositionLoop:
    """The loop that plays programs in position and in force mode: position samples through
    ``controller`` (Paden-Panja by default), force samples through the hybrid explicit-force
    law; the same supervisor, drive and recorder. ``program`` (e.g. a protocol's generator)
    starts at the first cycle; without one the robot holds until one is requested (the RT
    process). ``extra_blocks`` (e.g. a signal tap) are wired with ``extra_connections``."""
    from rt.components.protocol_blocks import HybridController
    from rt.control.force import ExplicitForce

    model = model or RobotModel.load()
    reference = ProgramReference("reference", model.description.limits.stroke,
                                 1.0 / rate_hz, program)
    force_law = ExplicitForce(model, force_gains)
    # The force law's preview, in the loop's samples: the sequencer reads a program known in
    # advance this far ahead for it.
    reference.preview_steps = round(force_law.gains.preview_s * rate_hz)
    return _assemble(
        devices, model, reference,
        lambda sup: HybridController("controller", create(controller, model, gains),
                                     force_law, sup),
        [("reference.force", "controller.force"),
         ("reference.force_preview", "controller.force_preview"),
         ("reference.pose", "controller.pose"),
         ("reference.ctrl_mode", "controller.ctrl_mode"), ("force.wrench", "controller.wrench")],
        rate_hz, mode, robot_limits, patient_limits, protocol_limits, extra_blocks,
        extra_connections, loop_kwargs)


def _assemble(devices: Devices, model: RobotModel, reference: ProgramReference,
              make_controller: Callable[[Supervisor], Component],
              own_connections: list[tuple[str, str]], rate_hz: float, mode: str,
              robot_limits: RobotLimits | None, patient_limits: PatientLimits | None,
              protocol_limits: ProtocolLimits | None, extra_blocks: list | None,
              extra_connections: list[tuple[str, str]] | None, loop_kwargs: dict) -> PositionLoop:
    """Sensors → estimator → model → reference → controller → supervisor → redundant drive →
    recorder (→ watchdog feed), the wiring every loop shares; ``own_connections`` add what the
    chosen reference and controller need beyond it."""
    d = model.description
    # A model reused from an earlier loop (pre-flight after pre-flight) starts its FK where a
    # fresh one does: the same protocol then gives the same cycles to the last bit.
    model.kin.reset_warm_start()
    events = EventLog()
    robot = robot_limits or RobotLimits()
    limits = effective(d.limits.stroke, robot, patient_limits or PatientLimits(),
                       protocol_limits)
    # A force-control soft stop's hold yields to a pull, below the stroke's soft-stop margin.
    reference.configure_yield(robot.pull_yield_speed_m_s, robot.pull_yield_max_m,
                              limits.stroke_hi_m - limits.stroke_margin_m,
                              YIELD_LEAD_TRACKING * limits.max_tracking_error_m)
    supervisor = Supervisor(limits, 1.0 / rate_hz, events, **supervisor_physics(d))
    b = GraphBuilder()
    if devices.first is not None:
        b.add(devices.first)
    b.add(EncoderReader("encoders", devices.encoders))
    b.add(ForceReader("force", devices.force))
    b.add(StopInputs("stops", devices.stops))
    b.add(VelocityEstimation("estimator"))
    b.add(ModelState("model", model))
    ref = b.add(reference)
    b.add(make_controller(supervisor), slot="controller")
    b.add(SupervisorBlock("supervisor", supervisor, d.drive.force_per_volt_n))
    b.add(RedundantDrive("drive", devices.cards, events, monitor=devices.monitor))
    rec = b.add(RecorderTap("recorder"))
    if devices.feed_watchdog is not None:
        b.add(WatchdogFeed("watchdog", devices.feed_watchdog, devices.watchdog_tripped,
                           devices.rearm_watchdog))
    for block in extra_blocks or ():
        b.add(block)
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
            ("force.wrench", "reference.wrench"), ("force.flags", "reference.wrench_flags"),
            ("force.tare", "reference.tare"),
            ("supervisor.volts", "recorder.volts"), *own_connections,
            *(extra_connections or ())):
        b.connect(src, dst)
    # The supervisor's verdict reaches the reference and the controller one cycle later, the
    # drive's failure flag the supervisor, and the sequencer's tare request the force reader:
    # these are the loop's only feedback edges.
    b.connect("supervisor.mode", "reference.mode", delay=1)
    b.connect("supervisor.mode", "controller.mode", delay=1)
    b.connect("drive.failed", "supervisor.drive_failed", delay=1)
    # The sequencer asks the force reader for a tare at a force program's start.
    b.connect("reference.tare_request", "force.tare_request", delay=1)
    graph = b.build()
    graph.configure()
    sup_block = graph.component("supervisor")
    assert isinstance(sup_block, SupervisorBlock)
    sup_block.failed_components = graph.failed_components
    # Estimator → supervisor as one compiled call per cycle (rt.components.fused;
    # TALUS_FUSED_CYCLE=0 keeps the per-block cycle).
    attach_fused_cycle(graph)
    loop = Loop(graph, rate_hz=rate_hz, mode=mode, **loop_kwargs)
    graph.start()
    return PositionLoop(loop, graph, model, devices.twin, rec, ref, supervisor, events, devices)
