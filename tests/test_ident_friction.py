"""Viscous friction is identified without bias: the forces and the regressor go through the same
(parallel) filter. A 1 kHz recording of the truth's exact forces (Coulomb switching within
1 mm/s at each reversal, encoder-quantized positions, force noise) is identified with the
module's filtering; filtering the states and the forces at 8 Hz instead (the first method)
reads part of each filtered Coulomb reversal as viscous friction."""
from __future__ import annotations

import numpy as np
import pytest

import rt.identification.estimate as E
from rt.identification.estimate import estimate_base, prepare
from rt.identification.excitation import optimize_excitation
from rt.model import RobotModel
from rt.model.regressor import Regressor
from rt.twin.realism import default_truth

RATE_HZ = 1000.0
SECONDS = 30.0
#: Encoder quantum of the robot (m): the recorded positions are counts.
COUNT_M = 2.0e-5
#: Force noise (N RMS): the DAC's 4.9 mV LSB × 339 N/V ≈ 1.7 N, rounded up.
NOISE_N = 2.0


@pytest.fixture(scope="module")
def recording():
    """(q counts, τ noisy) at 1 kHz along an optimised excitation, the truth's dynamics."""
    model = RobotModel.load()
    exc = optimize_excitation(model, evaluations=60)
    t = np.arange(round(SECONDS * RATE_HZ)) / RATE_HZ
    q, qd, qdd = exc.evaluate(t)
    truth = RobotModel.from_description(default_truth())
    tau = np.empty_like(q)
    st = None
    for j in range(len(t)):
        st = truth.dyn.state(q[j], qd[j], out=st)
        tau[j] = truth.dyn.inverse_dynamics(st, qdd[j])
    rng = np.random.default_rng(7)
    q_counts = np.round(q / COUNT_M) * COUNT_M
    return q_counts, tau + rng.normal(0.0, NOISE_N, tau.shape)


def _fv(recording, filtering, monkeypatch):
    # The truth here has the model's own friction (no Stribeck region): every sample counts.
    monkeypatch.setattr(E, "MIN_SPEED_M_S", 0.0)
    reg = Regressor(RobotModel.load().dyn)
    # The forces are sampled at the positions' instants, not commands held by a DAC.
    est = estimate_base(reg, prepare(*recording, RATE_HZ, filtering=filtering, held=False))
    truth = est.truth(Regressor(RobotModel.from_description(default_truth()).dyn).theta_base(),
                      None)                                 # no amplifier offset here
    idx = [est.names.index(f"fv{i}") for i in range(3)]
    return est.theta[idx], est.sigma[idx], truth[idx]


def test_viscous_friction_recovered_within_its_reported_uncertainty(recording, monkeypatch):
    fv, sigma, truth = _fv(recording, "parallel", monkeypatch)
    # Within 3 σ of the truth, and σ itself meaningful (< 2 % of the value).
    assert np.all(np.abs(fv - truth) <= 3.0 * sigma), (fv, sigma, truth)
    assert np.all(sigma < 0.02 * truth)


def test_filtering_the_states_biases_viscous_friction_upwards(recording, monkeypatch):
    """The bias the parallel filter removes: each filtered Coulomb reversal read as viscous
    friction, so fv comes out high on every axis, further off than the parallel estimate."""
    fv, _sigma, truth = _fv(recording, "states", monkeypatch)
    fv_par, _, _ = _fv(recording, "parallel", monkeypatch)
    assert np.all(fv > truth), (fv, truth)
    assert np.abs(fv - truth).sum() > np.abs(fv_par - truth).sum(), (fv, fv_par, truth)
