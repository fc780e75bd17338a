"""Least-squares identification of the robot's dynamics from a recorded excitation.

Data: slider positions from the encoders and the actuator forces the drives were commanded
(current-mode amplifiers: force = command V × force per volt), recorded at the loop rate. Each
command is held by the DAC for one period after its row's positions were read, and the
amplifier's current loop delivers it late and filtered, so the forces are first aligned to the
positions' instants (:func:`held_to_positions`: half a period; :func:`amplifier_to_positions`:
that and the amplifier's response, from the description's ``drive`` datasheet figures).

Filtering (Gautier's *parallel filtering*): the model is linear in the parameters, τ = W θ, but
W is a nonlinear function of the states — the Coulomb column is sign(q̇) smoothed over
1 mm/s. A low-pass filter F commutes with the linear map θ ↦ Wθ, not with that nonlinearity:
filtering the forces at 8 Hz but computing W from positions filtered at the same 8 Hz (what this
module did first) turns each Coulomb reversal, a step in τ, into a ~60 ms ramp in the filtered
force, which is proportional to q̇ near the reversal, while W's Coulomb column still switches
sharply: least squares reads the ramp as *viscous* friction (fv over-estimated by tens of N s/m,
fc under-estimated, the bias of issue 15). Now:

1. positions pass a zero-phase Butterworth at ``STATE_FILTER_HZ`` (10 Hz: 25× the
   excitation's highest harmonic, so the states are not distorted, while the 20 µm encoder
   quantum's noise in q̇ stays ≪ the Coulomb term's 1 mm/s smoothing — at 40 Hz it biased fv
   by −1…−6 % through the tanh) — only to compute W's arguments;
2. W is evaluated at every sample from those states, then **the same** zero-phase low-pass
   (``FILTER_HZ``, 8 Hz) is applied to every column of W and to τ, and both are decimated to
   ``DECIMATE_TO_HZ``: F(W) θ = F(τ) holds exactly for the true θ whatever F is, so the filter
   removes noise without biasing any parameter. Decimated to 20 Hz (2.5× the filter), the
   residual is close to white, so Gautier's σ is not optimistic;
3. equations of an axis sliding slower than ``MIN_SPEED_M_S`` are left out: below it the
   twin's (and a rig's) friction is stiction and the Stribeck dip from the static to the
   Coulomb level, which f_v q̇ + f_c tanh(q̇/v_s) does not describe. With the first
   optimised excitation's speeds (mostly < 50 mm/s) those samples were a large share, and
   least squares bent the friction line through them: fv −31…−44 % (20 σ) on the twin with
   its effects off; without them −0.5…+0.5 % (≤ 1.7 σ). The excitation is now played at the
   limits (``excitation.to_limits``: ≈ 130 mm/s), which also moves the friction's ripple with
   position (5 mm period) above this filter's band (``bench/identification.py``);
4. the ball screw's friction is not the same all around a revolution (the nut's preload
   follows the screw's straightness, the balls recirculate once per turn): a force
   ∝ sign(q̇) sin(2π q / lead + φ) per axis, periodic in *position* with the screw's lead,
   which the description knows; its amplitude and phase are not. Played at the limits it is
   ≈ 26 Hz, but every slower stretch of the path (20-60 mm/s around each reversal) puts it
   inside the 8 Hz band, where least squares read it as friction: on the realistic twin
   fv0 −1.1 %, fc0 +1.7 %, and it was the largest force left in the residual (1.7 N of the
   fit's 1.7 N RMS). Two nuisance columns per axis, tanh(q̇/v_s)·sin(2π q/lead) and ·cos,
   model it (``ripple=True``, the default): estimated with the rest, not written to the
   description (which has no place for it), reported as an amplitude per axis. With them
   the residual fell to 0.3 N and the identified amplitudes match the twin's ±8 % of f_c.

5. each amplifier adds a constant input offset to its commands while the drives are on (the
   DAC's zero-scale error and the amplifier's residual offset: millivolts, i.e. a few N at
   the slider; the twin's ±15 mV are up to ±5 N): the commands fall short of the dynamics by
   a constant force per axis. Without a column for it least squares reads it as weight, i.e.
   as the leg masses (+3.5…+8.3 %, 100-290 σ, on the realistic twin). With one constant
   column per axis (``offsets=True``, the default) the base reduction changes: a leg's mass
   base parameter M_i (slider, rod and the platform's share; ``slider0.m``, ``rod1.m``,
   ``slider2.m`` in ``rt.model.regressor``'s set) has the column M_i (q̈_i + g) on its axis
   alone — the rotor inertia's column q̈_i plus g times the offset's — so *no* motion
   separates it from J_r,i and o_i (:func:`offset_reduction` finds this numerically). What is
   identified is J_r,i + M_i and o_i − g M_i per axis; the offsets alone follow from the leg
   masses the lab believes (weighed parts, CAD: the description), each wrong kilogram
   putting 9.81 N on its offset. The configuration-dependent terms (rods' first moments and
   inertias, the platform's) are unaffected. In the description's parameters
   (:func:`estimate_physical`) the offsets are free unknowns and the masses' direction the
   data leave open follows the weak prior toward the believed description, inside the
   feasibility bounds (positive masses, physical inertias): the identified slider and rod
   masses stay the believed ones, the rotor inertias take the rest. Every loop built from
   the written description compensates its offsets (the supervisor writes τ·k − offset:
   ``rt.safety.supervisor_kernel.outputs``); the forces here are the volts written to the
   DAC × force per volt, so an identification run on a compensating loop measures the whole
   offset again, not what the compensation left.

Two estimates from the same data:

* **base parameters** (``rt.model.regressor``): ordinary least squares W θ = τ, with standard
  deviations σ_θ = sqrt(diag(σ² (WᵀW)⁻¹)), σ² = |r|²/(n − p) (Gautier's method) — the
  statistically identifiable quantities, reported per parameter;
* **a robot description** a lab loads with ``--robot``: the description's own physical
  parameters (slider mass; rod and platform mass, first moments and inertia; per-axis reflected
  rotor inertia, viscous and Coulomb friction) by bounded least squares (masses, inertias and
  friction positive) with a weak prior toward the nominal values for directions the data do
  not determine. The result must be a physical body set (positive masses, inertia tensors
  about the COMs positive semi-definite and meeting the triangle inequality): otherwise it is
  refused with ``IdentificationError``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
import scipy.optimize
import scipy.signal

from rt.errors import ConfigurationError, TalusError
from rt.model import RobotModel
from rt.model.description import Drive, RobotDescription, description_from_dict
from rt.model.regressor import (
    INERTIAL_NAMES,
    N_RIGID,
    STANDARD_NAMES,
    Regressor,
    workspace_rows,
)

#: Parallel filter (regressor columns and forces alike), Hz.
FILTER_HZ = 8.0
#: Filter of the positions W is computed from (Hz): the states undistorted, the quantum's noise
#: out of the Coulomb column.
STATE_FILTER_HZ = 10.0
DECIMATE_TO_HZ = 20.0
EDGE_S = 1.0
#: Equations of an axis slower than this (m/s) are left out of the fit: 5 × the Stribeck
#: velocity (4 mm/s), below which the real friction (stiction, the Stribeck dip from static to
#: Coulomb level) is not the model's f_v q̇ + f_c tanh(q̇/v_s).
MIN_SPEED_M_S = 0.02
#: Weight of the prior toward the nominal description, relative to the data (dimensionless).
PRIOR_WEIGHT = 1e-3
#: Nuisance columns per axis for the ball screw's friction ripple (module docstring, 4.).
RIPPLE_COLUMNS = 2
#: Relative threshold of the offset reduction's rank test (as the base reduction's).
_OFFSET_RANK_TOL = 1e-8

PHYSICAL_NAMES = (["slider.m"] + [f"rod.{n}" for n in INERTIAL_NAMES]
                  + [f"platform.{n}" for n in INERTIAL_NAMES]
                  + [f"Jr{i}" for i in range(3)] + [f"fv{i}" for i in range(3)]
                  + [f"fc{i}" for i in range(3)])


class IdentificationError(TalusError):
    """The data or the identified parameters cannot make a robot description."""


@dataclass
class IdentificationData:
    """Samples q, q̇, q̈ (m, m/s, m/s²) and τ (N), each (n, 3).

    ``rate_hz`` = 0: the samples are used as they are (exact or already filtered data).
    ``rate_hz`` > 0 (from :func:`prepare`): samples at that rate, to which the parallel filter
    is still to be applied — to W's columns and τ alike — before decimation (module docstring).
    """

    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    tau: np.ndarray
    rate_hz: float = 0.0


#: How :func:`prepare` filters: ``parallel`` (the default, unbiased) or ``states`` (positions
#: and forces both filtered at 8 Hz and W computed from the filtered positions: the first
#: method, kept to measure the bias it caused).
FILTERING = ("parallel", "states")


def held_to_positions(tau: np.ndarray) -> np.ndarray:
    """Commands a sampled loop held for one period, at the instants its positions were read.

    Row j's positions are read at t_j and its command, computed from them, is then held by the
    DAC over [t_j, t_j + T]: the force applied is the command sequence through a zero-order
    hold, i.e. the samples delayed by T/2 (at the excitation's frequencies). Its value at t_j
    is the mean of the commands held on either side, (τ_{j−1} + τ_j)/2. Left as is, the half
    period is a time shift between τ and W: with ω the excitation's harmonics, the rotor
    inertia's force J_r q̈ shifted by δ reads as J_r δ ω² of *negative* viscous friction
    (fv −0.2…−1.3 % on the realistic twin at the limits, ``bench/identification.py``)."""
    out = np.array(tau, float)
    out[1:] = 0.5 * (out[1:] + out[:-1])
    return out


def amplifier_to_positions(tau: np.ndarray, rate_hz: float, bandwidth_hz: float,
                           delay_s: float) -> np.ndarray:
    """The force current-mode amplifiers deliver for held commands, at the positions' instants.

    Row j's command is held over [t_j, t_j + T] (:func:`held_to_positions`), reaches the
    current loop ``delay_s`` later (DAC settling, one PWM period) and is followed by it as a
    first-order lag of ``bandwidth_hz`` (time constant τ_c = 1/(2π bandwidth)). At the
    excitation's frequencies the hold and the delay are a pure delay of T/2 + delay, applied
    here as a fractional delay (linear interpolation between rows: the half period alone gives
    exactly :func:`held_to_positions`' mean); the lag is applied as its bilinear (Tustin)
    discretization, whose phase and gain match the continuous lag's below a tenth of the rate
    (its low-frequency delay is τ_c). Left out, the lag and the delay are a shift between τ and
    W beyond the half period (0.26 ms at the nominal 1 kHz / 100 µs), which least squares reads
    as J_r δ ω² of negative viscous friction: on a realistic twin that realises the documented
    amplifier (the twin since 2026-11-26b; 40 s, one recording, ``bench/identification_bias.py``)
    fv −0.29 / −0.83 / −1.02 % with the half period alone, −0.06 / −0.36 / −0.91 % aligned;
    a 100 Hz amplifier (2.1 ms) left out reads fv1 −3.8 % (``tests/test_ident_amplifier.py``)."""
    out = np.array(tau, float)
    if rate_hz <= 0.0 or bandwidth_hz < 0.0 or delay_s < 0.0:
        raise IdentificationError(f"amplifier alignment needs a positive rate and a non-negative "
                                  f"bandwidth and delay (got {rate_hz}, {bandwidth_hz}, "
                                  f"{delay_s})")
    period = 1.0 / rate_hz
    whole, frac = divmod((0.5 * period + delay_s) / period, 1.0)
    k = int(whole)
    if k or frac:
        # out[j] = (1 − f) τ[j − k] + f τ[j − k − 1]; the first rows repeat the first command
        # (the edges are left out of the fit, EDGE_S).
        padded = np.concatenate((np.repeat(out[:1], k + 1, axis=0), out))
        n = len(out)
        out = ((1.0 - frac) * padded[1:n + 1] + frac * padded[:n])
    if bandwidth_hz > 0.0:
        wc = 2.0 * math.pi * bandwidth_hz
        b, a = scipy.signal.bilinear([1.0], [1.0 / wc, 1.0], fs=rate_hz)
        zi = scipy.signal.lfilter_zi(b, a)
        out = np.column_stack([scipy.signal.lfilter(b, a, out[:, i], zi=zi * out[0, i])[0]
                               for i in range(out.shape[1])])
    return out


def prepare(q: np.ndarray, tau: np.ndarray, rate_hz: float,
            filtering: str = "parallel", held: bool = True,
            amplifier: Drive | None = None) -> IdentificationData:
    """Filter and differentiate a recording (see module docstring). ``held``: ``tau`` are the
    commands of a sampled loop, each held for one period after its row's positions were read
    (:func:`held_to_positions` aligns them; with ``amplifier``, the description's drive, also
    by the amplifier's delay and current loop: :func:`amplifier_to_positions`); ``False``:
    forces sampled at the positions' instants (synthetic data)."""
    q = np.asarray(q, float)
    tau = np.asarray(tau, float)
    if filtering not in FILTERING:
        raise IdentificationError(f"filtering must be one of {FILTERING}, got {filtering!r}")
    if q.shape != tau.shape or q.ndim != 2 or q.shape[1] != 3:
        raise IdentificationError(f"q and tau must both be (n, 3); got {q.shape}, {tau.shape}")
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(tau))):
        raise IdentificationError("the recording holds non-finite samples")
    edge = int(EDGE_S * rate_hz)
    if len(q) < 4 * edge + 100:
        raise IdentificationError(f"recording too short: {len(q) / rate_hz:.1f} s")
    dt = 1.0 / rate_hz
    if filtering == "states":
        sos = scipy.signal.butter(4, FILTER_HZ, fs=rate_hz, output="sos")
        qf = scipy.signal.sosfiltfilt(sos, q, axis=0)
        tf = scipy.signal.sosfiltfilt(sos, tau, axis=0)
        qd = np.gradient(qf, dt, axis=0)
        qdd = np.gradient(qd, dt, axis=0)
        step = max(1, round(rate_hz / DECIMATE_TO_HZ))
        sl = slice(edge, len(q) - edge, step)
        return IdentificationData(qf[sl], qd[sl], qdd[sl], tf[sl])
    sos = scipy.signal.butter(4, min(STATE_FILTER_HZ, 0.4 * rate_hz), fs=rate_hz, output="sos")
    qf = scipy.signal.sosfiltfilt(sos, q, axis=0)
    qd = np.gradient(qf, dt, axis=0)
    qdd = np.gradient(qd, dt, axis=0)
    if not held:
        applied = tau
    elif amplifier is None:
        applied = held_to_positions(tau)
    else:
        applied = amplifier_to_positions(tau, rate_hz, amplifier.current_loop_bandwidth_hz,
                                         amplifier.amplifier_delay_s)
    return IdentificationData(qf, qd, qdd, applied, float(rate_hz))


def _parallel(data: IdentificationData, per_sample: np.ndarray) -> np.ndarray:
    """The parallel filter and decimation of ``per_sample`` (n, 3, …) (module docstring);
    nothing for data without a rate."""
    if data.rate_hz <= 0.0:
        return per_sample
    rate = data.rate_hz
    sos = scipy.signal.butter(4, FILTER_HZ, fs=rate, output="sos")
    filtered = scipy.signal.sosfiltfilt(sos, per_sample, axis=0)
    edge = int(EDGE_S * rate)
    step = max(1, round(rate / DECIMATE_TO_HZ))
    return filtered[edge:len(filtered) - edge:step]


def _standard_rows(reg: Regressor, data: IdentificationData) -> np.ndarray:
    rows = np.empty((len(data.q), 3, len(STANDARD_NAMES)))
    st = None
    for j in range(len(data.q)):
        st = reg.dyn.state(data.q[j], data.qd[j], out=st)
        rows[j] = reg.standard(st, data.qdd[j])
    return _parallel(data, rows).reshape(-1, len(STANDARD_NAMES))


def _forces(data: IdentificationData) -> np.ndarray:
    """τ through the same filter as W's columns, flattened like the rows."""
    return _parallel(data, data.tau).reshape(-1)


def _sliding(data: IdentificationData) -> np.ndarray:
    """Which equations (one per axis and kept sample, flattened like the rows) are fitted: the
    axis slides at least ``MIN_SPEED_M_S`` (module docstring: the Stribeck region). Data
    without a rate (exact samples, used as they are) keep every equation."""
    if data.rate_hz <= 0.0:
        return np.ones(3 * len(data.q), dtype=bool)
    return (np.abs(_parallel(data, data.qd)) >= MIN_SPEED_M_S).reshape(-1)


def _ripple_rows(reg: Regressor, data: IdentificationData) -> np.ndarray:
    """The screw's friction-ripple columns (module docstring, 4.): per axis i,
    tanh(q̇_i/v_s) sin(2π q_i/lead) and … cos(…) on axis i's equations, through the same
    filter as W; flattened like the rows, (3n, 3 × RIPPLE_COLUMNS)."""
    lead = reg.dyn.description.drive.screw_lead_m
    smooth = reg.dyn.description.friction.coulomb_smoothing_m_s
    ang = 2.0 * math.pi * data.q / lead
    sgn = np.tanh(data.qd / smooth)
    rows = np.zeros((len(data.q), 3, 3 * RIPPLE_COLUMNS))
    for i in range(3):
        rows[:, i, RIPPLE_COLUMNS * i] = sgn[:, i] * np.sin(ang[:, i])
        rows[:, i, RIPPLE_COLUMNS * i + 1] = sgn[:, i] * np.cos(ang[:, i])
    return _parallel(data, rows).reshape(-1, 3 * RIPPLE_COLUMNS)


def _offset_rows(n_samples: int) -> np.ndarray:
    """The amplifiers' input-offset columns (module docstring, 5.): −1 on axis i's equations
    (the offset o_i adds to the delivered force, so the commands fall short of the dynamics
    by it: τ_cmd = W θ − o), flattened like the rows, (3n, 3). Constant, so the parallel
    filter leaves them as they are."""
    rows = np.zeros((n_samples, 3, 3))
    for i in range(3):
        rows[:, i, i] = -1.0
    return rows.reshape(-1, 3)


def _system(reg: Regressor, data: IdentificationData, ripple: bool = True,
            offsets: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(W standard, nuisance columns, τ) of the sliding equations, all through the parallel
    filter. The nuisance columns are the screw's ripple (``ripple``, 3 × RIPPLE_COLUMNS) then
    the amplifiers' offsets (``offsets``, 3); 0 wide without either."""
    keep = _sliding(data)
    if keep.sum() < 2 * len(STANDARD_NAMES):
        raise IdentificationError(f"only {int(keep.sum())} samples slide faster than "
                                  f"{MIN_SPEED_M_S * 1e3:.0f} mm/s: the excitation is too slow")
    y = _forces(data)
    parts = [np.zeros((int(keep.sum()), 0))]
    if ripple:
        parts.append(_ripple_rows(reg, data)[keep])
    if offsets:
        parts.append(_offset_rows(len(y) // 3)[keep])
    return _standard_rows(reg, data)[keep], np.hstack(parts), y[keep]


@dataclass(frozen=True)
class OffsetReduction:
    """The base parameters once the amplifiers' offsets are unknowns too (module docstring,
    5.): which base parameters stay (``keep``, positions in ``Regressor.base``), which become
    combinations of the others (``dropped``), and how they fold in: the column of a dropped
    parameter is ``[W_keep, offset columns] @ combination[:, j]``, so the identified values
    are θ_keep + K_keep θ_dropped and o + K_offset θ_dropped."""

    keep: np.ndarray
    dropped: np.ndarray
    combination: np.ndarray          # (len(keep) + 3, len(dropped))
    names: list[str]                 # the identified quantities, kept ones then offsets

    def reduce(self, theta_base: np.ndarray, offsets_n: np.ndarray) -> np.ndarray:
        """The identified quantities' values for base parameters ``theta_base`` and offsets
        ``offsets_n`` (N, per axis): the truth's, on the twin."""
        full = np.concatenate((np.asarray(theta_base, float)[self.keep],
                               np.asarray(offsets_n, float)))
        return full + self.combination @ np.asarray(theta_base, float)[self.dropped]


def offset_reduction(reg: Regressor, samples: int = 40, seed: int = 20121) -> OffsetReduction:
    """Find which base parameters the offsets make unidentifiable, numerically, as the base
    reduction does (``rt.model.regressor``): the base regressor and the offset columns stacked
    over random states in the workspace; columns are taken in the order offsets, drive terms
    (Jr, fv, fc), rigid-body terms, and a column is dropped when it adds no rank (relative
    residual below ``_OFFSET_RANK_TOL``) to those taken before it. On this robot the three
    leg-mass base parameters drop out: each is m (q̈_i + g) on its axis, i.e. the rotor
    inertia's column q̈_i plus g times an offset's."""
    rows = workspace_rows(reg.dyn, reg, samples, seed)
    nb = len(reg.base.base_index)
    w = np.hstack((rows, _offset_rows(samples)))
    scale = np.linalg.norm(w, axis=0)
    scale[scale == 0.0] = 1.0
    ws = w / scale
    names = reg.base.names
    drive = [k for k in range(nb) if names[k] in _DRIVE_SET]
    rigid = [k for k in range(nb) if names[k] not in _DRIVE_SET]
    order = [nb + i for i in range(3)] + drive + rigid
    taken: list[int] = []
    dropped: list[int] = []
    for col in order:
        if taken:
            coef, *_ = np.linalg.lstsq(ws[:, taken], ws[:, col], rcond=None)
            resid = float(np.linalg.norm(ws[:, col] - ws[:, taken] @ coef))
        else:
            resid = float(np.linalg.norm(ws[:, col]))
        (taken if resid > _OFFSET_RANK_TOL * np.linalg.norm(ws[:, col]) else dropped).append(col)
    keep = np.array(sorted(k for k in taken if k < nb), dtype=int)
    cols = np.concatenate((keep, np.arange(nb, nb + 3)))
    drop = np.array(sorted(dropped), dtype=int)
    if len(drop):
        k, *_ = np.linalg.lstsq(w[:, cols], w[:, drop], rcond=None)
        k[np.abs(k) < 1e-9] = 0.0
    else:
        k = np.zeros((len(cols), 0))
    out_names = []
    for row, c in enumerate(cols):
        name = names[c] if c < nb else f"offset{c - nb}"
        for j, d in enumerate(drop):
            if k[row, j] != 0.0:
                coef = float(k[row, j])
                name += (f" {'+' if coef > 0 else '−'} "
                         f"{'' if abs(abs(coef) - 1.0) < 1e-9 else f'{abs(coef):.4g}·'}{names[d]}")
        out_names.append(name)
    return OffsetReduction(keep, drop, k, out_names)


_DRIVE_SET = {f"{p}{i}" for p in ("Jr", "fv", "fc") for i in range(3)}


@dataclass
class BaseEstimate:
    names: list[str]
    theta: np.ndarray
    sigma: np.ndarray
    residual_rms_n: float
    #: The screw's friction-ripple amplitude per axis (N; None without ``ripple``).
    ripple_n: np.ndarray | None = None
    #: With ``offsets``: the reduction (``names`` are then its quantities, the last three the
    #: offsets folded with the leg masses' weight), and the offsets themselves (N, per axis,
    #: with σ) given the believed leg masses (module docstring, 5.).
    reduction: OffsetReduction | None = None
    offset_n: np.ndarray | None = None
    offset_sigma_n: np.ndarray | None = None

    def truth(self, truth_base: np.ndarray, offsets_n: np.ndarray | None) -> np.ndarray:
        """The identified quantities' true values from the truth's base parameters (and, with
        offsets, its amplifiers' offsets in N)."""
        if self.reduction is None:
            return np.asarray(truth_base, float)
        return self.reduction.reduce(truth_base, np.zeros(3) if offsets_n is None
                                     else offsets_n)


def estimate_base(reg: Regressor, data: IdentificationData, ripple: bool = True,
                  offsets: bool = True,
                  believed: RobotDescription | None = None) -> BaseEstimate:
    """OLS on the base parameters with their standard deviations (and, with ``ripple``, the
    screw's friction ripple as nuisance parameters: module docstring, 4.; with ``offsets``, a
    constant force per axis, the amplifiers' input offsets: module docstring, 5. — then the
    leg masses fold into the rotor inertias and the offsets, and the offsets alone are
    reported given the leg masses of ``believed``, default the regressor's description)."""
    red = offset_reduction(reg) if offsets else None
    w_std, nuisance, y = _system(reg, data, ripple, offsets)
    w_base = w_std[:, reg.base.base_index]
    if red is not None:
        w_base = w_base[:, red.keep]
    nb = w_base.shape[1]
    w = np.hstack((w_base, nuisance))
    theta, *_ = np.linalg.lstsq(w, y, rcond=None)
    r = y - w @ theta
    dof = max(1, len(y) - len(theta))
    var = float(r @ r) / dof
    cov = var * np.linalg.pinv(w.T @ w)
    sigma = np.sqrt(np.maximum(np.diag(cov), 0.0))
    amp = (np.hypot(theta[nb:nb + 3 * RIPPLE_COLUMNS:RIPPLE_COLUMNS],
                    theta[nb + 1:nb + 3 * RIPPLE_COLUMNS:RIPPLE_COLUMNS]) if ripple else None)
    if red is None:
        return BaseEstimate(reg.base.names, theta[:nb], sigma[:nb],
                            float(np.sqrt(np.mean(r ** 2))), amp)
    theta_r = np.concatenate((theta[:nb], theta[-3:]))
    sigma_r = np.concatenate((sigma[:nb], sigma[-3:]))
    believed_base = (reg.theta_base() if believed is None
                     else Regressor(RobotModel.from_description(believed).dyn).theta_base())
    # o_i = (o_i + K θ_dropped) − K θ_dropped(believed): σ is the fit's (the believed masses
    # taken as exact; their error enters as g × mass error, module docstring 5.).
    offset = theta[-3:] - red.combination[-3:] @ believed_base[red.dropped]
    return BaseEstimate(red.names, theta_r, sigma_r, float(np.sqrt(np.mean(r ** 2))), amp,
                        red, offset, sigma[-3:])


def _physical_columns(std_rows: np.ndarray) -> np.ndarray:
    """Regressor in the description's parameters: legs share one slider and one rod."""
    idx = {n: k for k, n in enumerate(STANDARD_NAMES)}
    cols = [sum(std_rows[:, idx[f"slider{i}.m"]] for i in range(3))]
    for n in INERTIAL_NAMES:
        cols.append(sum(std_rows[:, idx[f"rod{i}.{n}"]] for i in range(3)))
    for n in INERTIAL_NAMES:
        cols.append(std_rows[:, idx[f"platform.{n}"]])
    for k in range(9):
        cols.append(std_rows[:, N_RIGID + k])
    return np.column_stack(cols)


def _dyn_params(body) -> np.ndarray:
    return pin.Inertia(body.mass_kg, np.array(body.com_m, float),
                       np.array(body.inertia_kg_m2, float)).toDynamicParameters()


def nominal_physical(description: RobotDescription) -> np.ndarray:
    b = description.bodies
    plat = _dyn_params(b.platform) + _dyn_params(b.sensor)
    return np.concatenate(([b.slider.mass_kg], _dyn_params(b.rod), plat,
                           description.drive.reflected_inertia_axes_kg,
                           description.friction.viscous_axes, description.friction.coulomb_axes))


def estimate_physical(reg: Regressor, data: IdentificationData,
                      nominal: RobotDescription, ripple: bool = True,
                      offsets: bool = True) -> np.ndarray:
    """Bounded LS in the description's parameters with a weak prior (module docstring); the
    screw's friction ripple (``ripple``) is estimated alongside, free, and not returned; the
    amplifiers' offsets (``offsets``, module docstring 5.) too, free, and returned after the
    description's parameters (N, per axis: ``len(PHYSICAL_NAMES) + 3`` values)."""
    w_std, nuisance, y = _system(reg, data, ripple, offsets)
    a = _physical_columns(w_std)
    p0 = nominal_physical(nominal)
    scale = np.maximum(np.abs(p0), 1e-3)
    scale[1:4] = max(scale[0], 0.1) * 0.05              # rod first moments: ~ kg × 5 cm
    scale[11:14] = 0.5                                  # platform first moments
    y_scale = max(float(np.sqrt(np.mean(y ** 2))), 1e-9)
    # Prior rows: a relative deviation of 1 from the nominal costs PRIOR_WEIGHT × the data's
    # mean square force, so only directions the data leave open follow the prior.
    prior = math.sqrt(PRIOR_WEIGHT * len(y)) * y_scale * np.diag(1.0 / scale)
    n_extra = nuisance.shape[1]
    lhs = np.vstack((np.hstack((a, nuisance)),
                     np.hstack((prior, np.zeros((len(prior), n_extra))))))
    rhs = np.concatenate((y, prior @ p0))
    lo = np.full(len(p0) + n_extra, -np.inf)
    hi = np.full(len(p0) + n_extra, np.inf)
    for k in (0, 1, 11):                                # masses
        lo[k] = 1e-3
    for base in (1, 11):                                # inertia diagonals about the origin
        for off in (4, 6, 9):
            lo[base + off] = 0.0
    lo[21:30] = 0.0                                     # rotor inertia, friction
    lo[21:24] = 1e-3
    res = scipy.optimize.lsq_linear(lhs, rhs, bounds=(lo, hi), method="trf")
    if offsets:
        return np.concatenate((res.x[:len(p0)], res.x[-3:]))
    return res.x[:len(p0)]


def description_from_physical(p: np.ndarray, nominal: RobotDescription,
                              name: str) -> RobotDescription:
    """Build (and validate) the identified description; physically impossible sets are
    refused with IdentificationError naming the body."""
    p = np.asarray(p, float)
    n = len(PHYSICAL_NAMES)
    if p.shape not in ((n,), (n + 3,)) or not np.all(np.isfinite(p)):
        raise IdentificationError(f"identified parameters must be {n} finite values, or "
                                  f"{n + 3} with the amplifiers' offsets (N)")
    data = nominal.model_dump()
    if len(p) == n + 3:
        # The offsets go to the description in volts, validated there (|v| ≤ 1 V, finite).
        data["drive"]["amplifier_offset_v"] = [float(v / nominal.drive.force_per_volt_n)
                                               for v in p[n:]]
        p = p[:n]
    if p[0] <= 0.0:
        raise IdentificationError(f"identified slider mass {p[0]:.4g} kg is not positive")
    data["bodies"]["slider"]["mass_kg"] = float(p[0])
    sensor = _dyn_params(nominal.bodies.sensor)
    for body, params in (("rod", p[1:11]), ("platform", p[11:21] - sensor)):
        if params[0] <= 0.0:
            raise IdentificationError(f"identified {body} mass {params[0]:.4g} kg is not "
                                      f"positive")
        inertia = pin.Inertia.FromDynamicParameters(np.asarray(params, float))
        about_com = np.asarray(inertia.inertia)
        data["bodies"][body] = {"mass_kg": float(inertia.mass),
                                "com_m": [float(v) for v in inertia.lever],
                                "inertia_kg_m2": [[float(v) for v in row]
                                                  for row in 0.5 * (about_com + about_com.T)]}
    lead = nominal.drive.screw_lead_m
    data["drive"]["rotor_inertia_per_axis_kg_m2"] = [float(j / (2 * math.pi / lead) ** 2)
                                                     for j in p[21:24]]
    fr = data["friction"]
    fr["viscous_per_axis_n_s_per_m"] = [float(v) for v in p[24:27]]
    fr["coulomb_per_axis_n"] = [float(v) for v in p[27:30]]
    ratio = [s / c if c > 0 else 1.0 for s, c in zip(nominal.friction.static_axes,
                                                        nominal.friction.coulomb_axes)]
    fr["static_per_axis_n"] = [float(v) * r for v, r in zip(p[27:30], ratio)]
    data["name"] = name
    try:
        return description_from_dict(data, f"identified set {name!r}")
    except ConfigurationError as exc:
        raise IdentificationError(f"identified parameters are not physically feasible: "
                                  f"{exc}") from None


def force_prediction_error(description: RobotDescription, data: IdentificationData) -> dict:
    """Predicted vs measured actuator forces on a (validation) data set."""
    model = RobotModel.from_description(description)
    pred = np.empty_like(data.tau)
    st = None
    for j in range(len(data.q)):
        st = model.dyn.state(data.q[j], data.qd[j], out=st)
        pred[j] = model.dyn.inverse_dynamics(st, data.qdd[j])
    # The measurement is the commands: the delivered force less the amplifiers' offsets
    # (module docstring, 5.), which the description knows once identified (zero before).
    pred -= np.asarray(description.drive.amplifier_offsets_n)
    # Prediction and measurement through the same (parallel) filter.
    pred = _parallel(data, pred)
    tau = _parallel(data, data.tau)
    err = pred - tau
    peak = float(np.abs(tau).max())
    rms = float(np.sqrt(np.mean(err ** 2)))
    return {"rms_n": rms, "peak_n": peak, "rms_pct_of_peak": 100.0 * rms / peak}
