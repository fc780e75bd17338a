"""The identification workflow on the twin: excite, record, estimate, write, validate.

The excitation (``rt.identification.excitation``) runs through the product's position loop
(Paden-Panja with the nominal model, 1 kHz, the supervisor active) on the in-process twin; the
RT process can run the same reference as a program. The record is the encoder positions and
the commanded actuator forces after the supervisor (what the amplifiers were told).
"""
from __future__ import annotations

import numpy as np

from rt.identification.estimate import IdentificationData, IdentificationError, prepare
from rt.identification.excitation import FourierExcitation
from rt.model import RobotModel
from rt.model.description import RobotDescription
from rt.position_loop import build_sim_position_loop
from rt.twin.realism import RigImperfections
from rt.twin.twin import Twin

RATE_HZ = 1000.0


def record(excitation: FourierExcitation, seconds: float, model: RobotModel,
           truth: RobotDescription | None = None,
           imperfections: RigImperfections | None = None, seed: int = 0) -> IdentificationData:
    """Run the excitation on the twin for ``seconds`` and return the prepared data."""
    q, tau = record_commands(excitation, seconds, model, truth, imperfections, seed)
    # Aligned by the amplifier the lab believes (its datasheet, in the description).
    return prepare(q, tau, RATE_HZ, amplifier=model.description.drive)


def record_commands(excitation: FourierExcitation, seconds: float, model: RobotModel,
                    truth: RobotDescription | None = None,
                    imperfections: RigImperfections | None = None,
                    seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Run the excitation on the twin for ``seconds``: the encoder positions (m) and the
    commanded actuator forces (N, the supervisor's volts × the model's force per volt), one
    row per loop cycle, before :func:`rt.identification.estimate.prepare`."""
    twin = Twin(truth, seed=seed, imperfections=imperfections)
    twin.place((excitation.q0,) * 3)
    pl = build_sim_position_loop("paden_panja", None, excitation, seconds, rate_hz=RATE_HZ,
                                 model=model, twin=twin)
    cycles = 0
    while pl.reference.phase.data[0] != 1.0:
        pl.loop.run(cycles=1)
        cycles += 1
        if cycles > 30 * RATE_HZ or pl.reference.phase.data[0] == 3.0:
            raise IdentificationError("the excitation did not start (supervisor stop or "
                                      "approach refused)")
    _, start = pl.recorder.drain(0)
    n = round(seconds * RATE_HZ)
    pl.loop.run(cycles=n)
    if pl.reference.phase.data[0] == 3.0:
        events = "; ".join(e.message for e in pl.events.snapshot()[:3])
        raise IdentificationError(f"the supervisor stopped the excitation: {events}")
    rows, _ = pl.recorder.drain(start)
    rows = rows[:n]
    q = rows[:, 1:4].copy()
    volts = rows[:, 13:16]
    return q, volts * model.description.drive.force_per_volt_n


def truth_base(truth: RobotDescription, reg_names: list[str],
               offsets_n: np.ndarray | None = None) -> np.ndarray:
    """The truth's base parameters (for the report on the twin); for an estimate with the
    amplifiers' offsets (its names those of ``estimate.offset_reduction``), the truth of its
    quantities, with the twin's offsets ``offsets_n`` (N, per axis; zero if not given)."""
    from rt.identification.estimate import offset_reduction
    from rt.model.regressor import Regressor

    reg = Regressor(RobotModel.from_description(truth).dyn)
    if reg.base.names == reg_names:
        return reg.theta_base()
    red = offset_reduction(reg)
    assert red.names == reg_names, (red.names, reg_names)
    return red.reduce(reg.theta_base(), np.zeros(3) if offsets_n is None else offsets_n)


def record_benchmark(seconds: float, model: RobotModel, truth: RobotDescription | None = None,
                     imperfections: RigImperfections | None = None,
                     seed: int = 1) -> IdentificationData:
    """The validation record: the tracking benchmark's trajectory (two sines per slider), a
    trajectory unlike the excitation."""
    from rt.control.experiment import benchmark_reference

    class _Ref:
        q0 = 0.20

        def __call__(self, t, out):
            benchmark_reference(self.q0)(t, out)

    return record(_Ref(), seconds, model, truth, imperfections, seed)  # type: ignore[arg-type]
