"""The twin's mechanical plant: state, parameters and the fixed-step integration.

``TwinPlant.advance(dt, volts)`` holds the amplifier commands for ``dt`` seconds and integrates
the robot's forward dynamics  M q̈ = τ(V) − C q̇ − G − F(q̇) + J_Sᵀ w_env  at the physics rate
(default 5 kHz) with the compiled kernels of ``rt.twin.physics``.
"""
from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from rt.errors import ConfigurationError, KinematicsError
from rt.model.description import RobotDescription
from rt.model.dynamics import Payload
from rt.model.kinematics import Kinematics
from rt.twin import physics
from rt.twin.environment import FreeMotion

END_STOP_MARGIN_M = 0.005
END_STOP_STIFFNESS_N_PER_M = 5.0e6
END_STOP_DAMPING_N_S_PER_M = 2.0e4

INTEGRATORS = {"symplectic_euler": physics.INTEGRATOR_SYMPLECTIC_EULER,
               "rk4": physics.INTEGRATOR_RK4}


def _inertia(body) -> pin.Inertia:
    return pin.Inertia(body.mass_kg, np.array(body.com_m, float), np.array(body.inertia_kg_m2, float))


class TwinPlant:
    """Mechanics of the twin: sliders, rods, platform (+ sensor, payload) and environment."""

    def __init__(self, description: RobotDescription, environment=None,
                 physics_rate_hz: float = 5000.0, integrator: str = "symplectic_euler",
                 frictionless: bool = False):
        if not 5000.0 <= physics_rate_hz <= 100_000.0:
            raise ConfigurationError(f"physics_rate_hz must be in [5000, 100000] Hz, got "
                                     f"{physics_rate_hz}")
        if integrator not in INTEGRATORS:
            raise ConfigurationError(f"integrator must be one of {sorted(INTEGRATORS)}, got "
                                     f"{integrator!r}")
        self.description = description
        self.kin = Kinematics(description)
        self.geom = self.kin.geom
        self.physics_rate_hz = float(physics_rate_hz)
        self.integrator = INTEGRATORS[integrator]
        self.bodies = np.zeros(physics.N_BODY_PARAMS)
        self.friction = np.zeros(5)
        fr = description.friction
        if not frictionless:
            self.friction[:] = (fr.viscous_n_s_per_m, fr.coulomb_n, fr.static_n,
                                fr.stribeck_velocity_m_s, fr.stiction_smoothing_m_s)
        else:
            self.friction[3:] = (fr.stribeck_velocity_m_s, fr.stiction_smoothing_m_s)
        self.payload: Payload | None = None
        self._pack_bodies()
        self.environment = environment or FreeMotion()
        self.env = self.environment.pack()
        self.env_state = np.zeros(4)
        self.q = np.zeros(3)
        self.qd = np.zeros(3)
        self.qdd = np.zeros(3)
        self.phi = np.full(3, self.kin.phi_nominal)
        self.wrench_s = np.zeros(6)
        self.t = 0.0
        self._volts = np.zeros(3)
        home = self.kin.ik(0.5 * sum(self.kin.stroke) + self._rise(), 0.0, 0.0)
        self.set_state(home.q)

    def _rise(self) -> float:
        g = self.description.geometry
        return math.sqrt(g.rod_length_m ** 2 - (g.base_radius_m - g.platform_radius_m) ** 2)

    # ------------------------------------------------------------------ parameters
    def _pack_bodies(self) -> None:
        d = self.description
        b = self.bodies
        b[physics.B_M_SLIDER] = d.bodies.slider.mass_kg
        rod = d.bodies.rod
        b[physics.B_M_ROD] = rod.mass_kg
        b[physics.B_C_ROD:physics.B_C_ROD + 3] = rod.com_m
        b[physics.B_I_ROD:physics.B_I_ROD + 9] = np.array(rod.inertia_kg_m2).ravel()
        plat = _inertia(d.bodies.platform) + _inertia(d.bodies.sensor)
        if self.payload is not None:
            plat = plat + self.payload.inertia()
        b[physics.B_M_PLAT] = plat.mass
        b[physics.B_C_PLAT:physics.B_C_PLAT + 3] = plat.lever
        b[physics.B_I_PLAT:physics.B_I_PLAT + 9] = plat.inertia.ravel()
        b[physics.B_SENSOR:physics.B_SENSOR + 3] = d.sensor.offset_m
        b[physics.B_G] = d.gravity_m_s2
        b[physics.B_J_REFL] = d.drive.reflected_inertia_kg
        b[physics.B_F_PER_A] = d.drive.force_per_amp_n
        b[physics.B_I_LIMIT] = d.drive.current_limit_a
        b[physics.B_AMP_GAIN] = d.drive.amplifier_gain_a_per_v
        # Mechanical end stops 5 mm beyond the usable stroke (the software limits sit inside).
        b[physics.B_STOP_LO] = d.limits.stroke_m[0] - END_STOP_MARGIN_M
        b[physics.B_STOP_HI] = d.limits.stroke_m[1] + END_STOP_MARGIN_M
        b[physics.B_STOP_K] = END_STOP_STIFFNESS_N_PER_M
        b[physics.B_STOP_C] = END_STOP_DAMPING_N_S_PER_M

    def set_payload(self, payload: Payload | None) -> None:
        """Put a payload on the platform (``None`` removes it); effective from the next substep."""
        self.payload = payload
        self._pack_bodies()

    def set_environment(self, environment) -> None:
        self.environment = environment
        self.env = environment.pack()

    # ------------------------------------------------------------------ state
    def set_state(self, q, qd=(0.0, 0.0, 0.0)) -> None:
        """Place the robot at slider positions ``q`` (m) with velocities ``qd`` (m/s)."""
        cfg = self.kin.fk(q, check=False)
        self.q[:] = q
        self.qd[:] = qd
        self.qdd[:] = 0.0
        self.phi[:] = cfg.phi

    def advance(self, dt: float, volts) -> None:
        """Hold amplifier commands ``volts`` (V, after the DAC) for ``dt`` s and integrate."""
        n = max(1, int(round(dt * self.physics_rate_hz)))
        self._volts[:] = volts
        status = physics.integrate(self.geom, self.bodies, self.friction, self.env, self.q,
                                   self.qd, self.phi, self._volts, n, dt / n, self.integrator,
                                   self.env_state, self.qdd, self.wrench_s)
        if status != physics.STATUS_OK:
            raise KinematicsError(f"twin: forward kinematics failed at q = {self.q.tolist()} m "
                                  f"(t = {self.t:.4f} s); the mechanism left its assembly range")
        self.t += dt

    @property
    def in_contact(self) -> bool:
        """True while the plate environment's contact is closed."""
        return bool(self.env_state[0] > 0.0)
