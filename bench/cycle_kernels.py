"""The cycle's compiled blocks against their interpreted references, one call at a time
(this machine; issue 16): every position law, the explicit-force law, the model block, the
velocity estimator, the supervisor block, the benchmark trajectory's sampler, the sequencer
playing a table program and the device blocks' driver work (encoder read and decode, DAC
write, force reader with its tare). Prints
median / p99 (µs) per implementation.

    .venv/bin/python bench/cycle_kernels.py [--calls 3000]

Each figure times ``update`` alone on a state at a tilted pose with the slider moving (warm
caches: a lower bound of what the block costs inside the loop, where ``talus bench loop``
measures it among the others).
"""
from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np

import rt.control.adaptive
import rt.control.laws  # noqa: F401  (registers the laws)
from rt.components.blocks import ModelState
from rt.components.safety_blocks import ForceReader, SupervisorBlock
from rt.control.base import CONTROLLERS, Reference, create
from rt.control.experiment import benchmark_reference, benchmark_reference_interpreted
from rt.control.force import ExplicitForce, ForceReference
from rt.devices.sampled_ft import SampledForceTorque
from rt.drivers.fake_comedi import FakeComedi
from rt.drivers.fake_pcl833 import FakePcl833Port
from rt.drivers.pci1720 import Pci1720Outputs
from rt.drivers.pcl833 import Pcl833Encoders
from rt.estimation.compiled import CompiledKalmanEstimator
from rt.estimation.velocity import KalmanVelocityEstimator
from rt.model import RobotModel
from rt.model.dynamics import State
from rt.references.program import TrajectoryProgram
from rt.references.sequencer import Phase, ProgramReference
from rt.safety.events import EventLog
from rt.safety.limits import PatientLimits, RobotLimits, effective
from rt.safety.supervisor import InterpretedSupervisor, Supervisor, supervisor_physics


def _supervisor_block(model: RobotModel, st: State, q: np.ndarray, compiled: bool
                      ) -> SupervisorBlock:
    """A supervisor block on read-only input views (as a graph binds them), healthy inputs."""
    d = model.description
    lim = effective(d.limits.stroke, RobotLimits(), PatientLimits())
    cls = Supervisor if compiled else InterpretedSupervisor
    blk = SupervisorBlock("supervisor", cls(lim, 1e-3, EventLog(), **supervisor_physics(d)),
                          d.drive.force_per_volt_n)
    values = {"q": q, "est_status": np.zeros(1), "qd": np.array([0.01, 0.02, -0.01]),
              "qdd": np.zeros(3), "fk_ok": np.ones(1), "q_ref": q + 1e-4,
              "qd_ref": np.array([0.001, 0.0, 0.002]), "tau": np.array([120.0, -40.0, 300.0]),
              "wrench": np.array([1.0, -2.0, -30.0, 0.1, 0.2, 0.0]), "wrench_flags": np.zeros(2),
              "stops": np.zeros(2), "drive_failed": np.zeros(1)}
    for name, value in values.items():
        view = np.array(value, dtype=float)
        view.flags.writeable = False
        getattr(blk, name).data = view
    blk.state_in.data = st
    blk.volts.data, blk.enable.data, blk.mode.data = np.zeros(3), np.ones(1), np.zeros(1)
    return blk


def _time(fn: Callable[[], object], calls: int, warm: int = 50) -> tuple[float, float]:
    """Median and p99 (µs) of ``calls`` calls of ``fn`` after ``warm`` unmeasured ones."""
    for _ in range(warm):
        fn()
    ts = np.empty(calls)
    pc = time.perf_counter_ns
    for i in range(calls):
        t0 = pc()
        fn()
        ts[i] = pc() - t0
    return float(np.median(ts)) / 1e3, float(np.percentile(ts, 99)) / 1e3


class _PolledSensor(SampledForceTorque):
    """A polled force sensor whose sample advances every read (the twin's form: a tuple)."""

    def __init__(self) -> None:
        super().__init__()
        self.seq = 0

    def _sample(self):
        self.seq += 1
        return (1.0, -2.0, -30.0, 0.1, 0.2, 0.0), self.seq, 0, self.seq * 1e-3


def _device_rows(calls: int) -> list[tuple[str, str, float, float]]:
    """The device blocks' driver work (issue 16): the PCL-833 read and decode on the emulated
    card, the PCI-1720 write into the comedilib double, the force reader with its tare."""
    rows: list[tuple[str, str, float, float]] = []
    port = FakePcl833Port()
    enc = Pcl833Encoders(port_io=port)
    q = np.zeros(3)
    for name, read in (("compiled", enc.read_positions_m),
                       ("interpreted", enc.read_positions_m_interpreted)):
        rows.append(("encoder read+decode", name, *_time(lambda r=read: r(q), calls)))
    dac = Pci1720Outputs(lib=FakeComedi(keep_log=False))
    dac.enable()
    volts = np.array([1.2, -0.4, 5.9])
    volts.flags.writeable = False                 # the loop's port view
    for name, write in (("compiled", dac.write_volts), ("interpreted",
                                                        dac.write_volts_interpreted)):
        rows.append(("DAC write", name, *_time(lambda w=write: w(volts), calls)))
    for compiled in (True, False):
        blk = ForceReader("force", _PolledSensor(), compiled=compiled)
        blk.sensor.start()
        request = np.zeros(1)
        request.flags.writeable = False
        blk.tare_request.data = request
        rows.append(("force reader block", "compiled" if compiled else "interpreted",
                     *_time(lambda b=blk: b.update(0.0, 1e-3), calls)))
    return rows


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--calls", type=int, default=3000)
    args = p.parse_args(argv)
    model = RobotModel.load()
    cfg = model.kin.ik(0.63, 0.1, 0.05)
    st = model.dyn.state(np.array(cfg.q), np.array([0.01, 0.02, -0.01]), out=State())
    ref = Reference(np.array(cfg.q), np.array([0.01, 0.0, 0.02]), np.array([0.1, 0.2, 0.3]))
    out = np.zeros(3)
    rows: list[tuple[str, str, float, float]] = []
    for name in sorted(CONTROLLERS):
        for compiled in (True, False):
            law = create(name, model, compiled=compiled)
            n = args.calls if compiled else max(200, args.calls // 10)
            rows.append((name, "compiled" if compiled else "interpreted",
                         *_time(lambda law=law: law.update(st, ref, 1e-3, out), n)))
    fref = ForceReference(f=300.0, f_dot=100.0, roll=0.02)
    for compiled in (True, False):
        force = ExplicitForce(model, compiled=compiled)
        rows.append(("explicit_force", "compiled" if compiled else "interpreted",
                     *_time(lambda f=force: f.update(st, 280.0, fref, 1e-3, out), args.calls)))
    for compiled in (True, False):
        blk = ModelState("model", model, compiled=compiled)
        blk.q_meas.data = np.array(cfg.q)
        blk.qd.data = np.array([0.01, 0.02, -0.01])
        blk.state_out.data = State()
        blk.fk_ok.data = np.zeros(1)
        rows.append(("model block", "compiled" if compiled else "interpreted",
                     *_time(lambda b=blk: b.update(0.0, 1e-3), args.calls)))
    q = np.array(cfg.q)
    for est in (CompiledKalmanEstimator(), KalmanVelocityEstimator()):
        rows.append(("estimator", "compiled" if isinstance(est, CompiledKalmanEstimator)
                     else "interpreted", *_time(lambda e=est: e.update(q, 1e-3), args.calls)))
    for compiled in (True, False):
        blk = _supervisor_block(model, st, q, compiled)
        # Advancing times; the count stands still under a still reference (no trip).
        clock = iter(range(10**9))
        rows.append(("supervisor block", "compiled" if compiled else "interpreted",
                     *_time(lambda b=blk, c=clock: b.update(1.0 + next(c) * 1e-3, 1e-3),
                            args.calls)))
    r = Reference()
    for name, sampler in (("compiled", benchmark_reference()),
                          ("interpreted", benchmark_reference_interpreted())):
        rows.append(("benchmark sampler", name,
                     *_time(lambda s=sampler: s(1.234, r), args.calls)))
    for compiled in (True, False):
        # The sequencer playing a long table program (a benchmark trajectory), steady PLAY.
        seq = ProgramReference("reference", model.description.limits.stroke, 1e-3,
                               TrajectoryProgram(benchmark_reference(), 600.0, 1e-3),
                               compiled=compiled)
        for port, value in ((seq.q_meas, np.full(3, 0.2)), (seq.mode, np.zeros(1)),
                            (seq.wrench, np.zeros(6)), (seq.tare, np.zeros(10))):
            value.flags.writeable = False
            port._bind(value, "bench")
        seq.configure()
        seq.start()
        for k in range(20000):               # through the approach, into PLAY
            seq.update(k * 1e-3, 1e-3)
            if seq.phase.data[0] == float(Phase.PLAY):
                break
        rows.append(("sequencer (PLAY)", "compiled" if compiled else "interpreted",
                     *_time(lambda b=seq: b.update(0.0, 1e-3), args.calls)))
    rows += _device_rows(args.calls)
    print(f"{'block':22s} {'implementation':14s} {'median µs':>10s} {'p99 µs':>10s}")
    for name, impl, med, p99 in rows:
        print(f"{name:22s} {impl:14s} {med:10.1f} {p99:10.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
