"""Dynamics of the 3-PRS robot in actuator space, computed with Pinocchio.

    M(q) q̈ + C(q, q̇) q̇ + G(q) + F(q̇) = τ + J_S(q)ᵀ w_S

* The mechanism is modelled as a Pinocchio *tree* of 12 scalar joints — three legs (prismatic
  slider along z, revolute rod about the leg's tangent) and the platform on its own chain
  (PX, PY, PZ, RZ, RY, RX, so the platform coordinates are x, y, z, yaw α, pitch β, roll γ) —
  closed by the three spherical-joint constraints. With S(q) = ∂Q/∂q the tree coordinates'
  sensitivity to the sliders (``rt.model.kernels``), the actuated dynamics are the
  projection  M = Sᵀ M_tree S + J_r I,  C = Sᵀ (M_tree Ṡ + C_tree S),  G = Sᵀ g_tree,  where
  J_r is the motors' reflected inertia. Because M_tree and C_tree satisfy Ṁ − 2C skew and
  Sᵀ M Ṡ − Ṡᵀ M S is skew, the projected C keeps the property Ṁ − 2C skew-symmetric.
* F(q̇) = f_v q̇ + f_c tanh(q̇ / v_s): viscous plus smooth Coulomb friction per axis.
* w_S = (f, m): the wrench applied *to the platform* by what it touches, at the ATI sensor's
  origin and expressed in the sensor frame S (N, N m). J_S maps q̇ to the sensor frame's twist
  (linear, angular) expressed in S.

Units: q in m, τ in N (force along each ball screw), M in kg, C in kg/s, G and F in N.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from rt.errors import InputError
from rt.model import rigid_body as rb
from rt.model.description import Body, RobotDescription
from rt.model.kernels import TREE_DOF, tree_maps
from rt.model.kinematics import Configuration, Kinematics

#: Pinocchio joint ids (1-based; 0 is the universe) of the bodies that carry mass.
SLIDER_JOINTS = (1, 3, 5)
ROD_JOINTS = (2, 4, 6)
PLATFORM_JOINT = 12


def _inertia(body: Body) -> pin.Inertia:
    return pin.Inertia(body.mass_kg, np.array(body.com_m, dtype=float),
                       np.array(body.inertia_kg_m2, dtype=float))


def build_tree_model(description: RobotDescription) -> pin.Model:
    """The open tree (12 scalar joints) of the legs and the platform, gravity along -z."""
    g = description.geometry
    bodies = description.bodies
    model = pin.Model()
    model.name = description.name
    model.gravity.linear = np.array([0.0, 0.0, -description.gravity_m_s2])
    for i, theta_deg in enumerate(g.leg_angles_deg):
        theta = math.radians(theta_deg)
        # Leg frame Li: x radial outward, y tangent, z up, at the bottom of guide i.
        placement = pin.SE3(pin.utils.rotate("z", theta),
                            np.array([g.base_radius_m * math.cos(theta),
                                      g.base_radius_m * math.sin(theta), 0.0]))
        slider = model.addJoint(0, pin.JointModelPZ(), placement, f"slider{i}")
        model.appendBodyToJoint(slider, _inertia(bodies.slider), pin.SE3.Identity())
        rod = model.addJoint(slider, pin.JointModelRY(), pin.SE3.Identity(), f"rod{i}")
        model.appendBodyToJoint(rod, _inertia(bodies.rod), pin.SE3.Identity())
        model.addFrame(pin.Frame(f"sphere{i}", rod, pin.SE3(np.eye(3),
                                 np.array([0.0, 0.0, g.rod_length_m])), pin.FrameType.OP_FRAME))
    parent = 0
    for name, joint in (("platform_x", pin.JointModelPX()), ("platform_y", pin.JointModelPY()),
                        ("platform_z", pin.JointModelPZ()), ("platform_yaw", pin.JointModelRZ()),
                        ("platform_pitch", pin.JointModelRY()),
                        ("platform_roll", pin.JointModelRX())):
        parent = model.addJoint(parent, joint, pin.SE3.Identity(), name)
    assert parent == PLATFORM_JOINT
    platform = _inertia(bodies.platform) + _inertia(bodies.sensor)
    model.appendBodyToJoint(PLATFORM_JOINT, platform, pin.SE3.Identity())
    model.addFrame(pin.Frame("sensor", PLATFORM_JOINT,
                             pin.SE3(np.eye(3), np.array(description.sensor.offset_m, dtype=float)),
                             pin.FrameType.OP_FRAME))
    return model


@dataclass
class Payload:
    """A rigid payload on the platform: mass (kg), COM in P (m), inertia about its COM in P."""

    mass_kg: float
    com_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    inertia_kg_m2: tuple[tuple[float, float, float], ...] = ((0.0, 0.0, 0.0),) * 3

    def __post_init__(self) -> None:
        if not (math.isfinite(self.mass_kg) and self.mass_kg >= 0.0):
            raise InputError(f"payload mass_kg must be a finite number >= 0, got {self.mass_kg}")
        com = np.asarray(self.com_m, dtype=float)
        inertia = np.asarray(self.inertia_kg_m2, dtype=float)
        if com.shape != (3,) or not np.all(np.isfinite(com)):
            raise InputError(f"payload com_m must be 3 finite numbers, got {self.com_m}")
        if inertia.shape != (3, 3) or not np.all(np.isfinite(inertia)):
            raise InputError("payload inertia_kg_m2 must be a 3x3 matrix of finite numbers")
        if not np.allclose(inertia, inertia.T) or np.linalg.eigvalsh(inertia)[0] < -1e-12:
            raise InputError("payload inertia_kg_m2 must be symmetric positive semi-definite")

    def inertia(self) -> pin.Inertia:
        return pin.Inertia(float(self.mass_kg), np.asarray(self.com_m, dtype=float),
                           np.asarray(self.inertia_kg_m2, dtype=float))


class State:
    """Kinematic state of one cycle: the configuration, S, Ṡ and the platform twist map.

    Buffers are allocated once; ``update`` refills them (used in the real-time cycle).
    """

    def __init__(self) -> None:
        self._cfg: Configuration | None = None
        self._filled = False
        # One buffer, the arrays views of it: a compiled kernel takes the state as one argument
        # (layout in ``rt.model.rigid_body``, STATE_*).
        self.buf = np.zeros(rb.STATE_SIZE)
        (self.Q, self.Qd, self.qd, self.S, self.Sd, self.twist, self.rot, self._q,
         self._phi) = rb.unpack_state(self.buf)

    @property
    def cfg(self) -> Configuration | None:
        """The configuration of this cycle, or None before the first fill. The compiled model
        block fills only the buffer; the ``Configuration`` is then built here on first use (the
        cycle's compiled code never asks for it)."""
        if self._cfg is None and self._filled:
            b = self.buf
            q, phi, Q = self._q, self._phi, self.Q
            sph = b[rb.STATE_SPHERES:rb.STATE_SPHERES + 9].tolist()
            self._cfg = Configuration(
                (float(q[0]), float(q[1]), float(q[2])),
                (float(phi[0]), float(phi[1]), float(phi[2])), float(Q[8]), float(Q[11]),
                float(Q[10]), float(Q[6]), float(Q[7]), float(Q[9]),
                tuple(self.rot.ravel().tolist()),
                (tuple(sph[0:3]), tuple(sph[3:6]), tuple(sph[6:9])),
                int(b[rb.STATE_ITERATIONS]))
        return self._cfg

    @cfg.setter
    def cfg(self, value: Configuration | None) -> None:
        self._cfg = value
        self._filled = value is not None

    @property
    def filled(self) -> bool:
        """True once a cycle's state has been computed into this State."""
        return self._filled

    def buffer_filled(self) -> None:
        """The buffer holds a new cycle's state (compiled model block): drop the cached
        ``Configuration``."""
        self._cfg = None
        self._filled = True

    @property
    def forward_det(self) -> float:
        """det(∂f/∂φ) of this cycle's FK constraint Jacobian (0 at a forward singularity)."""
        return float(self.buf[rb.STATE_DET])

    @forward_det.setter
    def forward_det(self, value: float) -> None:
        self.buf[rb.STATE_DET] = value

    @property
    def config(self) -> Configuration:
        """The configuration of this cycle (set by ``Dynamics.state``)."""
        cfg = self.cfg
        if cfg is None:
            raise InputError("this State has no configuration yet: fill it with Dynamics.state")
        return cfg

    def forward_jacobian(self) -> np.ndarray:
        """∂(z, roll, pitch)/∂q (3×3; m/m and rad/m): pose rates from slider velocities."""
        return self.S[[8, 11, 10]]

    def inverse_jacobian(self) -> np.ndarray:
        """∂q/∂(z, roll, pitch) (3×3; m/m and m/rad): slider velocities for pose rates."""
        return np.linalg.inv(self.forward_jacobian())

    def parasitic_jacobian(self) -> np.ndarray:
        """∂(x, y, yaw)/∂q (3×3): the parasitic motions' rates from slider velocities."""
        return self.S[[6, 7, 9]]


class Dynamics:
    """M, C, G, F, the wrench maps, payloads and inverse dynamics, in actuator space."""

    def __init__(self, description: RobotDescription, kinematics: Kinematics | None = None):
        self.description = description
        self.kin = kinematics or Kinematics(description)
        k = self.kin
        self._geom = k.geom
        self.model = build_tree_model(description)
        self.data = self.model.createData()
        self._platform_nominal = self.model.inertias[PLATFORM_JOINT].copy()
        self.payload: Payload | None = None
        # Per axis (kg, N s/m, N): a description may carry identified per-axis values.
        self.reflected_inertia = np.array(description.drive.reflected_inertia_axes_kg)
        fr = description.friction
        self.viscous = np.array(fr.viscous_axes)
        self.coulomb = np.array(fr.coulomb_axes)
        self.coulomb_v = fr.coulomb_smoothing_m_s
        self.sensor_offset = np.array(description.sensor.offset_m, dtype=float)
        self._state = State()
        # crba fills only the upper triangle of the tree's mass matrix; the mask rebuilds the
        # full symmetric matrix without np.triu (which costs ~15 µs per call here).
        self._upper = np.triu(np.ones((TREE_DOF, TREE_DOF)))
        self._upper[np.diag_indices(TREE_DOF)] = 0.5
        self._m_half = np.zeros((TREE_DOF, TREE_DOF))
        self._m_tree = np.zeros((TREE_DOF, TREE_DOF))
        # The same model packed for the compiled kernels (``rt.model.rigid_body``);
        # ``set_payload`` keeps the platform's parameters in step.
        self.tree_i, self.tree_f = rb.pack_tree(self.model, self.reflected_inertia, self.viscous,
                                                self.coulomb, self.coulomb_v)
        self._platform_pi = rb.pi_slice(TREE_DOF, PLATFORM_JOINT - 1)

    def _tree_mass(self, Q: np.ndarray) -> np.ndarray:
        """Full symmetric tree mass matrix (kg, kg m, kg m²) at tree configuration Q."""
        pin.crba(self.model, self.data, Q)
        np.multiply(self.data.M, self._upper, out=self._m_half)
        np.add(self._m_half, self._m_half.T, out=self._m_tree)
        return self._m_tree

    # ------------------------------------------------------------------ state
    def state(self, q, qd=(0.0, 0.0, 0.0), out: State | None = None,
              cfg: Configuration | None = None) -> State:
        """Solve FK (unless ``cfg`` is given) and fill S, Ṡ for slider velocity ``qd`` (m/s)."""
        st = self._state if out is None else out
        cfg = self.kin.fk(q) if cfg is None else cfg
        st.cfg = cfg
        st._q[0], st._q[1], st._q[2] = cfg.q
        st._phi[0], st._phi[1], st._phi[2] = cfg.phi
        st.qd[0], st.qd[1], st.qd[2] = qd[0], qd[1], qd[2]
        r = cfg.rotation
        st.rot[0, 0], st.rot[0, 1], st.rot[0, 2] = r[0], r[1], r[2]
        st.rot[1, 0], st.rot[1, 1], st.rot[1, 2] = r[3], r[4], r[5]
        st.rot[2, 0], st.rot[2, 1], st.rot[2, 2] = r[6], r[7], r[8]
        st.forward_det = tree_maps(self._geom, st._q, st._phi, st.rot, st.qd, st.S, st.Sd,
                                   st.twist)
        Q = st.Q
        Q[0], Q[1], Q[2], Q[3], Q[4], Q[5] = (cfg.q[0], cfg.phi[0], cfg.q[1], cfg.phi[1],
                                              cfg.q[2], cfg.phi[2])
        Q[6], Q[7], Q[8], Q[9], Q[10], Q[11] = cfg.x, cfg.y, cfg.z, cfg.yaw, cfg.pitch, cfg.roll
        np.dot(st.S, st.qd, out=st.Qd)
        return st

    # ------------------------------------------------------------------ terms
    def mass_matrix(self, st: State) -> np.ndarray:
        """M(q) (kg), symmetric positive definite, including the reflected motor inertia."""
        m = st.S.T @ (self._tree_mass(st.Q) @ st.S)
        jr = self.reflected_inertia
        m[0, 0] += jr[0]
        m[1, 1] += jr[1]
        m[2, 2] += jr[2]
        return m

    def mcg(self, st: State) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(M, C, G) for the state's q and q̇: kg, kg/s and N."""
        model, data = self.model, self.data
        m_tree = self._tree_mass(st.Q)
        c_tree = pin.computeCoriolisMatrix(model, data, st.Q, st.Qd)
        g_tree = pin.computeGeneralizedGravity(model, data, st.Q)
        s_t = st.S.T
        ms = m_tree @ st.S
        m = s_t @ ms
        jr = self.reflected_inertia
        m[0, 0] += jr[0]
        m[1, 1] += jr[1]
        m[2, 2] += jr[2]
        c = s_t @ (m_tree @ st.Sd + c_tree @ st.S)
        g = s_t @ g_tree
        return m, c, g

    def gravity(self, st: State) -> np.ndarray:
        """G(q) (N): actuator forces that hold the robot still against gravity."""
        return st.S.T @ pin.computeGeneralizedGravity(self.model, self.data, st.Q)

    def friction(self, qd) -> np.ndarray:
        """F(q̇) = f_v q̇ + f_c tanh(q̇ / v_s) (N)."""
        qd = np.asarray(qd, dtype=float)
        return self.viscous * qd + self.coulomb * np.tanh(qd / self.coulomb_v)

    def inverse_dynamics(self, st: State, qdd) -> np.ndarray:
        """τ = M q̈ + C q̇ + G + F (N) via Pinocchio's RNEA on the tree (no matrices formed)."""
        qdd = np.asarray(qdd, dtype=float)
        qdd_tree = st.S @ qdd + st.Sd @ st.qd
        tau_tree = pin.rnea(self.model, self.data, st.Q, st.Qd, qdd_tree)
        return st.S.T @ tau_tree + self.reflected_inertia * qdd + self.friction(st.qd)

    def forward_dynamics(self, st: State, tau, wrench=None) -> np.ndarray:
        """q̈ (m/s²) for actuator forces τ (N) and an optional sensor wrench w_S."""
        m, c, g = self.mcg(st)
        rhs = np.asarray(tau, dtype=float) - c @ st.qd - g - self.friction(st.qd)
        if wrench is not None:
            rhs = rhs + self.wrench_jacobian(st).T @ np.asarray(wrench, dtype=float)
        return np.linalg.solve(m, rhs)

    # ------------------------------------------------------------------ energy
    def kinetic_energy(self, st: State) -> float:
        """½ q̇ᵀ M q̇ (J), reflected motor inertia included."""
        m = self.mass_matrix(st)
        return 0.5 * float(st.qd @ m @ st.qd)

    def potential_energy(self, st: State) -> float:
        """Gravitational potential energy (J), zero at base height."""
        return float(pin.computePotentialEnergy(self.model, self.data, st.Q))

    # ------------------------------------------------------------------ wrenches
    def wrench_jacobian(self, st: State) -> np.ndarray:
        """J_S (6×3): q̇ → twist of the sensor frame S at its origin, expressed in S."""
        rot = st.rot
        v = st.twist[0:3]
        w = st.twist[3:6]
        s_b = rot @ self.sensor_offset                       # sensor offset in the base frame
        v_s = v + np.cross(w, s_b, axis=0)
        return np.vstack((rot.T @ v_s, rot.T @ w))

    def actuator_forces_for_wrench(self, st: State, wrench) -> np.ndarray:
        """Static actuator forces (N) that balance the wrench w_S applied to the platform."""
        return -(self.wrench_jacobian(st).T @ np.asarray(wrench, dtype=float))

    def wrench_from_actuator_forces(self, st: State, tau, fx: float = 0.0, fy: float = 0.0,
                                    tz: float = 0.0) -> np.ndarray:
        """The wrench w_S (N, N m) that static actuator forces τ balance.

        A 3-DOF mechanism sees only three wrench components; the others (fx, fy, tz in S, carried
        by the joints) are taken as given and the actuated ones (fz, tx, ty) are solved for.
        """
        j = self.wrench_jacobian(st)
        known = np.array([fx, fy, 0.0, 0.0, 0.0, tz])
        rhs = -np.asarray(tau, dtype=float) - j.T @ known
        solved = np.linalg.solve(j[[2, 3, 4]].T, rhs)
        return np.array([fx, fy, solved[0], solved[1], solved[2], tz])

    # ------------------------------------------------------------------ payload
    def set_payload(self, payload: Payload | None) -> None:
        """Put a payload on the platform (or remove it with ``None``); takes effect at once."""
        base = self._platform_nominal
        self.model.inertias[PLATFORM_JOINT] = base if payload is None else base + payload.inertia()
        self.tree_f[self._platform_pi] = self.model.inertias[PLATFORM_JOINT].toDynamicParameters()
        self.payload = payload
