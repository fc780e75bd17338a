"""A regressor linear in the robot's base dynamic parameters:  τ = Y(q, q̇, q̈) θ_base.

Standard parameters (79): for each massive body (slider0..2, rod0..2, platform — the platform
including the ATI sensor and any payload) the ten inertial parameters of Pinocchio's ordering
``[m, m·cx, m·cy, m·cz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`` expressed in the body's joint frame
(inertia about the joint-frame origin, kg m²); then per axis the reflected motor inertia
``Jr_i`` (kg), the viscous ``fv_i`` (N s/m) and Coulomb ``fc_i`` (N) friction coefficients.

Not all 79 are identifiable from actuator forces. The *base* parameters are found numerically
(Gautier's QR method): the standard regressor is stacked over random states in the workspace, a
column-pivoted QR picks a maximal independent set of standard parameters, and every other
parameter is folded into them with the coefficients K:  θ_base = θ_b + K θ_d.
``BaseParameters.describe()`` lists each base parameter as its linear combination, which is the
documented set (also printed by ``talus model describe``).
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
import scipy.linalg

from rt.errors import KinematicsError
from rt.model.dynamics import PLATFORM_JOINT, ROD_JOINTS, SLIDER_JOINTS, Dynamics, State

INERTIAL_NAMES = ("m", "mcx", "mcy", "mcz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")
BODIES = (("slider0", SLIDER_JOINTS[0]), ("slider1", SLIDER_JOINTS[1]),
          ("slider2", SLIDER_JOINTS[2]), ("rod0", ROD_JOINTS[0]), ("rod1", ROD_JOINTS[1]),
          ("rod2", ROD_JOINTS[2]), ("platform", PLATFORM_JOINT))
DRIVE_NAMES = tuple(f"{p}{i}" for p in ("Jr", "fv", "fc") for i in range(3))
STANDARD_NAMES = tuple(f"{b}.{p}" for b, _ in BODIES for p in INERTIAL_NAMES) + DRIVE_NAMES
N_RIGID = 10 * len(BODIES)

# Relative threshold on |R_ii| for the numerical rank: columns 1e-8 below the largest are
# combinations of others up to round-off (the regressor entries span ~1e-3..1e3).
_RANK_TOL = 1e-8


@dataclass(frozen=True)
class BaseParameters:
    """Which standard parameters are base, and how the others fold into them."""

    base_index: np.ndarray        # indices into STANDARD_NAMES, one per base parameter
    dependent_index: np.ndarray
    combination: np.ndarray       # K, shape (n_base, n_dependent)

    @property
    def names(self) -> list[str]:
        return [STANDARD_NAMES[i] for i in self.base_index]

    def from_standard(self, theta_std: np.ndarray) -> np.ndarray:
        """θ_base = θ_b + K θ_d."""
        return theta_std[self.base_index] + self.combination @ theta_std[self.dependent_index]

    def describe(self) -> list[dict]:
        """Each base parameter as {"name", "combination": {standard name: coefficient}}."""
        out = []
        for row, idx in enumerate(self.base_index):
            combo = {STANDARD_NAMES[idx]: 1.0}
            for col, dep in enumerate(self.dependent_index):
                coef = float(self.combination[row, col])
                if abs(coef) > 1e-9:
                    combo[STANDARD_NAMES[dep]] = round(coef, 12)
            out.append({"name": STANDARD_NAMES[idx], "combination": combo})
        return out


class Regressor:
    """Standard and base regressors of a ``Dynamics`` model, in actuator space."""

    def __init__(self, dynamics: Dynamics, samples: int = 40, seed: int = 20121):
        self.dyn = dynamics
        cols: list[int] = []
        for _, joint in BODIES:
            cols.extend(range(10 * (joint - 1), 10 * joint))
        self._tree_cols = np.array(cols)
        self._full = np.zeros((3, len(STANDARD_NAMES)))
        self._zero_tree = np.zeros(dynamics.model.nv)
        self._state = State()
        self.base = self._find_base(samples, seed)
        # For ``mixed``: where each base parameter lives (tree regressor column or drive term).
        nv = dynamics.model.nv
        self._y_tree = np.zeros((nv, 10 * (nv)))
        self._y_tmp = np.zeros_like(self._y_tree)
        rigid_pos, rigid_tree, drive_pos, drive = [], [], [], []
        for pos, std in enumerate(self.base.base_index):
            if std < N_RIGID:
                rigid_pos.append(pos)
                rigid_tree.append(int(self._tree_cols[std]))
            else:
                k = std - N_RIGID
                drive_pos.append(pos)
                drive.append((k // 3, k % 3))       # (0 Jr, 1 fv, 2 fc; axis)
        self._base_rigid_pos = np.array(rigid_pos)
        self._base_rigid_tree = np.array(rigid_tree)
        self._base_drive_pos = drive_pos
        self._base_drive = drive
        self._mixed_out = np.zeros((3, len(self.base.base_index)))
        self._acc = np.zeros(nv)
        self._v_plus = np.zeros(nv)
        self._v_minus = np.zeros(nv)
        self._u = np.zeros(3)

    def theta_standard(self) -> np.ndarray:
        """The model's current standard parameters (payload included)."""
        theta = np.empty(len(STANDARD_NAMES))
        for k, (_, joint) in enumerate(BODIES):
            theta[10 * k:10 * k + 10] = self.dyn.model.inertias[joint].toDynamicParameters()
        d = self.dyn
        theta[N_RIGID:N_RIGID + 3] = d.reflected_inertia
        theta[N_RIGID + 3:N_RIGID + 6] = d.viscous
        theta[N_RIGID + 6:N_RIGID + 9] = d.coulomb
        return theta

    def theta_base(self) -> np.ndarray:
        return self.base.from_standard(self.theta_standard())

    def standard(self, st: State, qdd) -> np.ndarray:
        """Y_std (3 × 79) at the state's q, q̇ and slider acceleration ``qdd`` (m/s²)."""
        d = self.dyn
        qdd = np.asarray(qdd, dtype=float)
        qdd_tree = st.S @ qdd + st.Sd @ st.qd
        y_tree = pin.computeJointTorqueRegressor(d.model, d.data, st.Q, st.Qd, qdd_tree)
        full = self._full
        full[:, :N_RIGID] = st.S.T @ y_tree[:, self._tree_cols]
        full[:, N_RIGID:] = 0.0
        for i in range(3):
            full[i, N_RIGID + i] = qdd[i]
            full[i, N_RIGID + 3 + i] = st.qd[i]
            full[i, N_RIGID + 6 + i] = math.tanh(st.qd[i] / d.coulomb_v)
        return full

    def __call__(self, st: State, qdd) -> np.ndarray:
        """Y_base (3 × n_base): τ = Y_base θ_base."""
        return self.standard(st, qdd)[:, self.base.base_index]

    def mixed(self, st: State, qd_r, qdd_r) -> np.ndarray:
        """Slotine-Li regressor (3 × n_base): Y θ = M q̈_r + C(q, q̇) q̇_r + G + F(q̇_r).

        C here is the Christoffel form of M (Ṁ − 2C skew), C(q, q̇) q̇_r = Γ(q̇, q̇_r) with Γ the
        symmetric bilinear form of the velocity terms. On the tree, with V± = S (q̇ ± q̇_r):
        Sᵀ [Y_t(Q, 0, S q̈_r + Ṡ(q̇) q̇_r) + (Y_t(Q, V+, 0) − Y_t(Q, V−, 0)) / 4] — the first
        term is M_t (S q̈_r + H(q̇, q̇_r)) + g_t, the difference 4 Γ_t(S q̇, S q̇_r) (gravity
        cancels). Friction and rotor inertia act on q̇_r, q̈_r. The state must carry q̇.
        """
        d = self.dyn
        model, data = d.model, d.data
        qd_r = np.asarray(qd_r, dtype=float)
        qdd_r = np.asarray(qdd_r, dtype=float)
        S = st.S
        zero = self._zero_tree
        # Pinocchio returns a view of its internal buffer: copy the first, combine the others
        # into it at the full-tree level, then project and pick the base columns once.
        y = self._y_tree
        acc, v_plus, v_minus, u = self._acc, self._v_plus, self._v_minus, self._u
        np.dot(S, qdd_r, out=acc)
        acc += np.dot(st.Sd, qd_r, out=v_minus)
        np.add(st.qd, qd_r, out=u)
        np.dot(S, u, out=v_plus)
        np.subtract(st.qd, qd_r, out=u)
        np.dot(S, u, out=v_minus)
        np.copyto(y, pin.computeJointTorqueRegressor(model, data, st.Q, zero, acc))
        # ¼ (Y(V+) − Y(V−)) = Γ: the difference first, one scaling.
        tmp = self._y_tmp
        np.copyto(tmp, pin.computeJointTorqueRegressor(model, data, st.Q, v_plus, zero))
        tmp -= pin.computeJointTorqueRegressor(model, data, st.Q, v_minus, zero)
        tmp *= 0.25
        y += tmp
        out = self._mixed_out
        out[:, self._base_rigid_pos] = S.T @ y[:, self._base_rigid_tree]
        for col, (kind, axis) in zip(self._base_drive_pos, self._base_drive):
            value = (qdd_r[axis] if kind == 0 else qd_r[axis] if kind == 1
                     else math.tanh(qd_r[axis] / d.coulomb_v))
            out[:, col] = 0.0
            out[axis, col] = value
        return out

    def _find_base(self, samples: int, seed: int) -> BaseParameters:
        w = workspace_rows(self.dyn, self.standard, samples, seed, self._state)
        # Scale columns so the rank decision does not depend on units.
        scale = np.linalg.norm(w, axis=0)
        scale[scale == 0.0] = 1.0
        _, r, perm = scipy.linalg.qr(w / scale, mode="economic", pivoting=True)
        diag = np.abs(np.diag(r))
        rank = int(np.sum(diag > _RANK_TOL * diag[0]))
        base_idx = perm[:rank]
        dep_idx = perm[rank:]
        # Back to unscaled parameters: W_d = W_b K with K = diag(1/s_b) R11⁻¹ R12 diag(s_d).
        k_scaled = scipy.linalg.solve_triangular(r[:rank, :rank], r[:rank, rank:])
        k = k_scaled * scale[dep_idx][None, :] / scale[base_idx][:, None]
        k[np.abs(k) < 1e-10] = 0.0
        order = np.argsort(base_idx)
        return BaseParameters(base_idx[order], dep_idx, k[order])


def workspace_rows(dyn: Dynamics, row: Callable[[State, np.ndarray], np.ndarray],
                   samples: int, seed: int, out: State | None = None) -> np.ndarray:
    """``samples`` regressor rows ``row(state, q̈)`` stacked, at random states of the
    workspace (heights within the stroke, roll and pitch within 80 % of their limits, random
    velocities and accelerations; draws outside the workspace drawn again): the sample on
    which a numerical rank decides which parameters the data can identify (the base
    reduction here, the offsets' in ``rt.identification.estimate``). Deterministic for a
    ``seed``; ``out`` a state to reuse."""
    rng = np.random.default_rng(seed)
    kin = dyn.kin
    rows: list[np.ndarray] = []
    st = out
    while len(rows) < samples:
        z = rng.uniform(kin.stroke[0] + 0.45, kin.stroke[1] + 0.40)
        roll = rng.uniform(-0.8, 0.8) * kin.roll_max
        pitch = rng.uniform(-0.8, 0.8) * kin.pitch_max
        try:
            cfg = kin.ik(z, roll, pitch)
        except KinematicsError:                           # outside the workspace: draw again
            continue
        st = dyn.state(cfg.q, rng.normal(0.0, 0.1, 3), out=st, cfg=cfg)
        rows.append(row(st, rng.normal(0.0, 1.0, 3)).copy())
    return np.vstack(rows)
