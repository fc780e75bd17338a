"""Identification: exact recovery on noiseless data, ≤ 5 % on noisy data for well-excited base
parameters, refusal of malformed or physically impossible sets, excitation inside the limits."""
from __future__ import annotations

import numpy as np
import pytest

from rt.identification.estimate import (
    IdentificationData,
    IdentificationError,
    description_from_physical,
    estimate_base,
    estimate_physical,
    force_prediction_error,
    nominal_physical,
    prepare,
)
from rt.identification.excitation import N_HARMONICS, FourierExcitation
from rt.model import RobotModel
from rt.model.description import load_description
from rt.model.regressor import Regressor
from rt.twin.realism import default_truth


def _synthetic(noise_n: float, seed: int = 3,
               offsets_n: np.ndarray | None = None) -> IdentificationData:
    """Samples of a rich trajectory with the truth's exact inverse-dynamics forces; with
    ``offsets_n`` (N per axis) as *commands*: the amplifiers add the offsets, so the commands
    are the dynamics' forces less them (tests/test_ident_offsets.py)."""
    rng = np.random.default_rng(seed)
    exc = FourierExcitation(rng.uniform(-0.02, 0.02, (3, N_HARMONICS)),
                            rng.uniform(-0.02, 0.02, (3, N_HARMONICS)))
    t = np.linspace(0.0, 10.0, 600, endpoint=False)
    q, qd, qdd = exc.evaluate(t)
    truth = RobotModel.from_description(default_truth())
    tau = np.empty_like(q)
    st = None
    for j in range(len(t)):
        st = truth.dyn.state(q[j], qd[j], out=st)
        tau[j] = truth.dyn.inverse_dynamics(st, qdd[j])
    if offsets_n is not None:
        tau -= offsets_n
    tau += rng.normal(0.0, noise_n, tau.shape) if noise_n else 0.0
    return IdentificationData(q, qd, qdd, tau)


def _truth_base(reg: Regressor) -> np.ndarray:
    return Regressor(RobotModel.from_description(default_truth()).dyn).theta_base()


def test_noiseless_data_recover_the_truth_within_the_reported_uncertainty():
    reg = Regressor(RobotModel.load().dyn)
    est = estimate_base(reg, _synthetic(0.0))
    # The estimator's quantities (with the offsets' columns, the leg masses folded into the
    # rotor inertias and the offsets: test_ident_offsets.py); no offset in these data.
    truth = est.truth(_truth_base(reg), None)
    scale = np.maximum(np.abs(truth), 1.0)
    np.testing.assert_allclose(est.theta, truth, atol=1e-6 * scale.max())
    assert np.all(np.abs(est.theta - truth) <= 3 * est.sigma + 1e-9 * scale)


def test_noisy_data_recover_well_excited_parameters_within_5_percent():
    reg = Regressor(RobotModel.load().dyn)
    est = estimate_base(reg, _synthetic(2.0))             # 2 N noise on ~100-300 N forces
    truth = est.truth(_truth_base(reg), None)
    well = est.sigma < 0.01 * np.abs(est.theta)
    assert well.sum() >= 8                                  # rotor inertias (+ leg masses), friction
    rel = np.abs(est.theta - truth) / np.abs(truth)
    assert np.all(rel[well] < 0.05), dict(zip(np.array(est.names)[well], rel[well]))


def test_identified_description_is_physical_and_predicts_forces():
    nominal = load_description()
    reg = Regressor(RobotModel.from_description(nominal).dyn)
    data = _synthetic(1.0)
    ident = description_from_physical(estimate_physical(reg, data, nominal), nominal, "id")
    err_id = force_prediction_error(ident, data)["rms_pct_of_peak"]
    err_nom = force_prediction_error(nominal, data)["rms_pct_of_peak"]
    assert err_id < 5.0 and err_id < err_nom


def test_physically_impossible_or_malformed_sets_are_refused():
    nominal = load_description()
    p = nominal_physical(nominal)
    bad = p.copy()
    bad[11] = -5.0                                          # negative platform mass
    with pytest.raises(IdentificationError, match="platform mass"):
        description_from_physical(bad, nominal, "bad")
    bad = p.copy()
    bad[1 + 9] = 50.0                                       # rod Izz ≫ Ixx + Iyy
    with pytest.raises(IdentificationError, match="not physically feasible"):
        description_from_physical(bad, nominal, "bad")
    with pytest.raises(IdentificationError, match="finite"):
        description_from_physical(p[:-1], nominal, "bad")
    with pytest.raises(IdentificationError, match="non-finite"):
        prepare(np.full((5000, 3), np.nan), np.zeros((5000, 3)), 1000.0)


def test_excitation_reference_matches_its_derivatives():
    rng = np.random.default_rng(0)
    exc = FourierExcitation(rng.uniform(-0.02, 0.02, (3, N_HARMONICS)),
                            rng.uniform(-0.02, 0.02, (3, N_HARMONICS)))
    t = np.linspace(0.0, 10.0, 100001)
    q, qd, qdd = exc.evaluate(t)
    np.testing.assert_allclose(np.gradient(q, t, axis=0)[1:-1], qd[1:-1], atol=1e-6)
    np.testing.assert_allclose(np.gradient(qd, t, axis=0)[1:-1], qdd[1:-1], atol=1e-5)
    np.testing.assert_allclose(q[0], q[-1], atol=1e-12)      # periodic
