"""The position loop assembled from its blocks (thesis 3.7.2 modular layout, at 1 kHz).

    twin → encoders → estimator ─┬→ model state ─→ controller → drive → (DAC)
                       └─────────┴→ reference ──↗          ↘ recorder tap

``build_sim_position_loop`` wires it on the digital twin (the default backend); the same blocks
take the real encoder and DAC backends on the rig.
"""
from __future__ import annotations

from dataclasses import dataclass

from rt.components.blocks import (ControllerBlock, DriveOutput, EncoderReader, ModelState,
                                  RecorderTap, TrajectoryReference, VelocityEstimation)
from rt.components.twin_step import TwinStep
from rt.control.base import create
from rt.control.experiment import RefFn, benchmark_reference
from rt.engine import Graph, GraphBuilder, Loop
from rt.model import RobotModel
from rt.twin.backends import TwinActuators, TwinEncoders
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

    def close(self) -> None:
        self.graph.stop() if self.loop.running else None


def build_sim_position_loop(controller: str = "paden_panja", gains: dict | None = None,
                            trajectory: RefFn | None = None, duration_s: float = 26.0,
                            environment=None, rate_hz: float = 1000.0, mode: str = "fast",
                            seed: int = 0, start_q: tuple[float, float, float] = (0.2, 0.2, 0.2),
                            model: RobotModel | None = None, **loop_kwargs) -> PositionLoop:
    """A configured, started position loop on the twin (run it with ``.loop.run(...)``)."""
    model = model or RobotModel.load()
    d = model.description
    clock = SimClock()
    twin = Twin(d, environment or FreeMotion(), seed=seed, clock=clock)
    twin.place(start_q)
    card = TwinActuators(twin, 0)
    b = GraphBuilder()
    b.add(TwinStep("twin", twin, clock))
    b.add(EncoderReader("encoders", TwinEncoders(twin)))
    b.add(VelocityEstimation("estimator"))
    b.add(ModelState("model", model))
    ref = b.add(TrajectoryReference("reference", trajectory or benchmark_reference(),
                                    duration_s, tuple(d.limits.stroke_m), rate_hz))
    b.add(ControllerBlock("controller", create(controller, model, gains)), slot="controller")
    b.add(DriveOutput("drive", card, d.drive.force_per_volt_n, d.drive.command_limit_v))
    rec = b.add(RecorderTap("recorder"))
    for src, dst in (("encoders.q", "estimator.q_meas"), ("encoders.q", "model.q_meas"),
                     ("estimator.qd", "model.qd"), ("encoders.q", "reference.q_meas"),
                     ("model.state", "controller.state"), ("reference.q_ref", "controller.q_ref"),
                     ("reference.qd_ref", "controller.qd_ref"),
                     ("reference.qdd_ref", "controller.qdd_ref"), ("controller.tau", "drive.tau"),
                     ("encoders.q", "recorder.q"), ("estimator.qd", "recorder.qd"),
                     ("reference.q_ref", "recorder.q_ref"), ("controller.tau", "recorder.tau"),
                     ("drive.volts", "recorder.volts")):
        b.connect(src, dst)
    graph = b.build()
    graph.configure()
    card.enable()
    loop = Loop(graph, rate_hz=rate_hz, mode=mode, **loop_kwargs)
    graph.start()
    return PositionLoop(loop, graph, model, twin, rec, ref)


def swap_controller(pl: PositionLoop, controller: str, gains: dict | None = None):
    """Swap the control law at the next cycle boundary, bumplessly; returns the command result."""
    return pl.loop.swap("controller", ControllerBlock(f"controller_{controller}",
                                                      create(controller, pl.model, gains)))
