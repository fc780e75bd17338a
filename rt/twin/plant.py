"""The twin's mechanical plant: state, parameters and the fixed-step integration.

``TwinPlant.advance(dt, volts)`` holds the amplifier commands for ``dt`` seconds and integrates
the robot's forward dynamics  M q̈ = τ(V) − C q̇ − G − F(q̇) + J_Sᵀ w_env  at the physics rate
(default 5 kHz) with the compiled kernels of ``rt.twin.physics``. With the rig's
imperfections (``rt.twin.realism.RigImperfections``; ``RigImperfections.none()`` is the ideal
rigid plant) the motors are separate bodies behind a compliant, backlashed screw, the motor
currents lag the commands, friction depends on temperature and position, the brakes hold when
the drives are off and the ATI cable pulls on the platform.

``compiled=True`` (the default) runs each held command as one call of
``rt.twin.kernels.advance`` (the period's bookkeeping, brakes, thermal model and the sensor
stage compiled too); ``compiled=False`` is the interpreted reference around the same substep
kernels. Both read and write the same arrays: every state and parameter array here is a view
into the packed ``P``/``S`` arrays of ``rt.twin.kernels``.
"""
from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from rt.errors import ConfigurationError, KinematicsError
from rt.model.description import RobotDescription
from rt.model.dynamics import Payload
from rt.model.kinematics import Kinematics
from rt.twin import kernels, physics
from rt.twin.environment import FreeMotion
from rt.twin.realism import RigImperfections, screw_damping_n_s_per_m

END_STOP_MARGIN_M = 0.005
END_STOP_STIFFNESS_N_PER_M = 5.0e6
END_STOP_DAMPING_N_S_PER_M = 2.0e4

#: How often the temperatures and friction scales are updated (s).
_HEAT_PERIOD_S = 0.1

INTEGRATORS = {"symplectic_euler": physics.INTEGRATOR_SYMPLECTIC_EULER,
               "rk4": physics.INTEGRATOR_RK4}


def _inertia(body) -> pin.Inertia:
    return pin.Inertia(body.mass_kg, np.array(body.com_m, float), np.array(body.inertia_kg_m2, float))


class TwinPlant:
    """Mechanics of the twin: sliders, rods, platform (+ sensor, payload) and environment."""

    def __init__(self, description: RobotDescription, environment=None,
                 physics_rate_hz: float = 5000.0, integrator: str = "symplectic_euler",
                 frictionless: bool = False, imperfections: RigImperfections | None = None,
                 compiled: bool = True):
        if not 5000.0 <= physics_rate_hz <= 100_000.0:
            raise ConfigurationError(f"physics_rate_hz must be in [5000, 100000] Hz, got "
                                     f"{physics_rate_hz}")
        if integrator not in INTEGRATORS:
            raise ConfigurationError(f"integrator must be one of {sorted(INTEGRATORS)}, got "
                                     f"{integrator!r}")
        self.imperfections = imperfections if imperfections is not None else RigImperfections()
        self.realistic = not self.imperfections.ideal
        if self.realistic and integrator != "symplectic_euler":
            raise ConfigurationError("the rig's imperfections are integrated with "
                                     "symplectic_euler only; use RigImperfections.none() for rk4")
        self.description = description
        self.kin = Kinematics(description)
        self.physics_rate_hz = float(physics_rate_hz)
        self.integrator = INTEGRATORS[integrator]
        self.compiled = compiled
        # Packed parameters, state and scratch of the compiled period (rt.twin.kernels), all
        # views of one block ``B`` with the environment, the geometry and the time; the named
        # arrays below are views into them, so both paths share one state.
        self._store, self.B = kernels.new_block()
        self.P, self.S, self.W, self.env, self.geom = kernels.block_views(self.B)
        self.geom[:] = self.kin.geom
        P, S, K = self.P, self.S, kernels
        P[K.P_REALISTIC] = 1.0 if self.realistic else 0.0
        P[K.P_INTEGRATOR] = self.integrator
        self.bodies = P[K.P_BODIES:K.P_BODIES + physics.N_BODY_PARAMS]
        self.friction = P[K.P_FRICTION:K.P_FRICTION + physics.N_FRICTION]
        self.friction_slider = P[K.P_FRICTION_SLIDER:K.P_FRICTION_SLIDER + physics.N_FRICTION]
        self.friction_motor = P[K.P_FRICTION_MOTOR:K.P_FRICTION_MOTOR + physics.N_FRICTION]
        self.real = P[K.P_REAL:K.P_REAL + physics.N_REAL]
        fr = description.friction
        if not frictionless:
            self.friction[0:3] = fr.viscous_axes
            self.friction[3:6] = fr.coulomb_axes
            self.friction[6:9] = fr.static_axes
        self.friction[9:11] = (fr.stribeck_velocity_m_s, fr.stiction_smoothing_m_s)
        self.friction[11:17] = 1.0
        imp = self.imperfections
        self.friction[17:19] = (imp.friction_ripple, imp.friction_ripple_period_m)
        self.temperature_rise_k = S[K.S_TEMP:K.S_TEMP + 3]
        self.temperature_rise_k[:] = imp.initial_temperature_rise_k
        self._heat_energy = S[K.S_HEAT_ENERGY:K.S_HEAT_ENERGY + 3]  # J since the last update
        # With a compliant screw the friction is split (RigImperfections.motor_side_friction):
        # ``friction`` stays the whole (for heat and reports), the kernels get the two shares.
        split = imp.motor_side_friction if imp.screw_stiffness_n_per_m > 0.0 else 0.0
        self._friction_split = split
        self._update_temperature_scales()
        self._pack_extra()
        self.payload: Payload | None = None
        self._pack_bodies()
        self.environment = environment or FreeMotion()
        self.env[:] = self.environment.pack()
        self.env_state = S[K.S_ENV_STATE:K.S_ENV_STATE + physics.ENV_STATE_SIZE]
        self.q = S[K.S_Q:K.S_Q + 3]
        self.qd = S[K.S_QD:K.S_QD + 3]
        self.qdd = S[K.S_QDD:K.S_QDD + 3]
        # Motor side (at the slider, m and m/s), motor currents (A), cable forces (N).
        self.xm = S[K.S_XM:K.S_XM + 3]
        self.vm = S[K.S_VM:K.S_VM + 3]
        self.current = S[K.S_CURRENT:K.S_CURRENT + 3]
        self.cable_tau = S[K.S_CABLE_TAU:K.S_CABLE_TAU + 3]
        self.phi = S[K.S_PHI:K.S_PHI + 3]
        self.phi[:] = self.kin.phi_nominal
        self.wrench_s = S[K.S_WRENCH:K.S_WRENCH + 6]
        self.rot = S[K.S_ROT:K.S_ROT + 9].reshape(3, 3)  # R_BP after the last advance
        self.rot[:] = np.eye(3)
        # The sensor stage (rt.twin.twin.Twin reads them): encoder reading, ATI filter state,
        # its input with the tool's weight, and the filtered wrench the gauges feel.
        self.encoder_q = S[K.S_ENC:K.S_ENC + 3]
        self.wrench_filtered = S[K.S_W_FILTERED:K.S_W_FILTERED + 6]
        self.wrench_sensed = S[K.S_W_SENSED:K.S_W_SENSED + 6]
        self.wrench_measured = S[K.S_W_MEAS:K.S_W_MEAS + 6]
        self.t = 0.0       # in the block (``X_T``): a compiled period advances it
        self._volts = S[K.S_VOLTS:K.S_VOLTS + 3]
        self._volts_prev = S[K.S_VOLTS_PREV:K.S_VOLTS_PREV + 3]
        self._delay_left = 0
        self._drives_on = False
        self._drives_changed_t = -1.0e9     # powered off since forever: brakes on
        # Amplifier input offsets (V), added to the commands while the drives are enabled.
        # (views into P and S: the twin's compiled period applies them in its kernel)
        self.amp_offset_v = self.P[K.P_AMP_OFFSET:K.P_AMP_OFFSET + 3]
        self.amp_offset_v[:] = self.imperfections.amplifier_offsets_v()
        self._with_offset = bool(np.any(self.amp_offset_v != 0.0))
        self.P[K.P_WITH_OFFSET] = 1.0 if self._with_offset else 0.0
        self.P[K.P_CMD_LIMIT] = self.description.drive.command_limit_v
        self._volts_in = S[K.S_VOLTS_IN:K.S_VOLTS_IN + 3]
        self._n_of_dt = (0.0, 1)       # the substeps of the last period length (dt, n)
        home = self.kin.ik(0.5 * sum(self.kin.stroke) + self._rise(), 0.0, 0.0)
        self._pack_real(home.z)
        self.set_state(home.q)

    def _pack_real(self, z_home: float) -> None:
        imp = self.imperfections
        r = self.real
        h = 1.0 / self.physics_rate_hz
        # The amplifier is the truth description's (its datasheet figures, rt.twin.realism).
        drive = self.description.drive
        bw = drive.current_loop_bandwidth_hz if imp.amplifier_dynamics else 0.0
        delay = drive.amplifier_delay_s if imp.amplifier_dynamics else 0.0
        # The exact first-order lag over a substep: what it keeps of the gap to its input at
        # the substep's end (1 − alpha) and on average over it (mean; the drive applies the
        # mean). The delay in whole substeps and the fraction of one beyond (it was rounded
        # to whole substeps: 100 µs at 5 kHz rounded to none).
        h_over_tau = 2.0 * math.pi * bw * h
        r[physics.R_AMP_ALPHA] = 1.0 if bw <= 0.0 else 1.0 - math.exp(-h_over_tau)
        r[physics.R_AMP_MEAN] = 0.0 if bw <= 0.0 else -math.expm1(-h_over_tau) / h_over_tau
        steps, frac = divmod(delay * self.physics_rate_hz, 1.0)
        if frac > 1.0 - 1e-9:                    # round-off of a whole number of substeps
            steps, frac = steps + 1.0, 0.0
        r[physics.R_AMP_DELAY_STEPS] = steps
        r[physics.R_AMP_DELAY_FRAC] = frac
        r[physics.R_SCREW_K] = imp.screw_stiffness_n_per_m
        # Damping ratio referred to the slider's own share of the moving mass (slider + rod).
        d = self.description.bodies
        r[physics.R_SCREW_C] = screw_damping_n_s_per_m(imp, d.slider.mass_kg + d.rod.mass_kg)
        r[physics.R_BACKLASH] = imp.backlash_m
        r[physics.R_BRAKE_HOLD] = imp.brake_holding_force_n
        r[physics.R_BRAKE_ON] = 1.0 if imp.brake_holding_force_n > 0.0 else 0.0
        r[physics.R_CABLE_W] = imp.cable_weight_n
        r[physics.R_CABLE_K] = imp.cable_stiffness_n_per_m
        r[physics.R_CABLE_Z] = z_home
        r[physics.R_JR:physics.R_JR + 3] = self.description.drive.reflected_inertia_axes_kg

    def _update_temperature_scales(self) -> None:
        imp = self.imperfections
        for i in range(3):
            dt_k = self.temperature_rise_k[i]
            self.friction[11 + i] = max(0.2, 1.0 + imp.viscous_per_k * dt_k)
            self.friction[14 + i] = max(0.2, 1.0 + imp.coulomb_per_k * dt_k)
        split = self._friction_split
        self.friction_slider[:] = self.friction
        self.friction_slider[11:17] *= 1.0 - split
        self.friction_motor[:] = self.friction
        self.friction_motor[11:17] *= split

    def _pack_extra(self) -> None:
        """The compiled period's scalar parameters (``rt.twin.kernels.P_*``)."""
        imp = self.imperfections
        P, K = self.P, kernels
        P[K.P_VISCOUS_PER_K] = imp.viscous_per_k
        P[K.P_COULOMB_PER_K] = imp.coulomb_per_k
        P[K.P_HEAT_CAPACITY] = imp.heat_capacity_j_per_k
        P[K.P_THERMAL_RES] = imp.thermal_resistance_k_per_w
        P[K.P_SPLIT] = self._friction_split
        P[K.P_HEAT_PERIOD] = _HEAT_PERIOD_S
        P[K.P_BRAKE_HOLD_N] = imp.brake_holding_force_n
        P[K.P_BRAKE_RELEASE] = imp.brake_release_s
        P[K.P_BRAKE_ENGAGE] = imp.brake_engage_s
        P[K.P_ENC_LATENCY] = imp.encoder_latency_s
        P[K.P_ATI_TAU] = (0.0 if imp.ati_filter_hz <= 0.0
                          else 1.0 / (2.0 * math.pi * imp.ati_filter_hz))
        P[K.P_TOOL_MG] = imp.ati_tool_mass_kg * self.description.gravity_m_s2
        P[K.P_TOOL_COM] = imp.ati_tool_com_m

    @property
    def t(self) -> float:
        """The plant's time (s): held in the block (``kernels.X_T``), where the compiled
        period advances it; read from the block's ``array('d')`` store (a Python float)."""
        return self._store[kernels.B_X + kernels.X_T]

    @t.setter
    def t(self, value: float) -> None:
        self._store[kernels.B_X + kernels.X_T] = value

    # Scalar state kept in ``S`` so the compiled period and the interpreted path share it.
    @property
    def _delay_left(self) -> int:
        return int(self.S[kernels.S_DELAY_LEFT])

    @_delay_left.setter
    def _delay_left(self, value: int) -> None:
        self.S[kernels.S_DELAY_LEFT] = value

    @property
    def _heat_time(self) -> float:
        return float(self.S[kernels.S_HEAT_TIME])

    @_heat_time.setter
    def _heat_time(self, value: float) -> None:
        self.S[kernels.S_HEAT_TIME] = value

    @property
    def _drives_on(self) -> bool:
        return bool(self.S[kernels.S_DRIVES_ON] > 0.5)

    @_drives_on.setter
    def _drives_on(self, value: bool) -> None:
        self.S[kernels.S_DRIVES_ON] = 1.0 if value else 0.0

    @property
    def _drives_changed_t(self) -> float:
        return float(self.S[kernels.S_DRIVES_CHANGED_T])

    @_drives_changed_t.setter
    def _drives_changed_t(self, value: float) -> None:
        self.S[kernels.S_DRIVES_CHANGED_T] = value

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
        jr = d.drive.reflected_inertia_axes_kg
        b[physics.B_J_REFL] = jr[0]
        # With a compliant screw the rotors are separate bodies (``real[R_JR:]``), not in M.
        compliant = self.imperfections.screw_stiffness_n_per_m > 0.0
        b[physics.B_J_REFL_AXES:physics.B_J_REFL_AXES + 3] = (0.0, 0.0, 0.0) if compliant else jr
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
        self.env[:] = environment.pack()
        self.env_state[:] = 0.0       # a new environment: no contact, no stuck point yet

    # ------------------------------------------------------------------ state
    def set_state(self, q, qd=(0.0, 0.0, 0.0)) -> None:
        """Place the robot at slider positions ``q`` (m) with velocities ``qd`` (m/s)."""
        cfg = self.kin.fk(q, check=False)
        self.q[:] = q
        self.qd[:] = qd
        self.qdd[:] = 0.0
        self.phi[:] = cfg.phi
        self.xm[:] = q
        self.vm[:] = qd
        self.cable_tau[:] = 0.0
        self.rot[:] = np.array(cfg.rotation).reshape(3, 3)

    @property
    def motor_position(self) -> np.ndarray:
        """Motor positions at the slider (m): what the motor-mounted encoders count."""
        return self.xm

    def set_drives_enabled(self, enabled: bool) -> None:
        """The amplifiers were enabled or disabled now: the brakes release or engage after
        their delays (``RigImperfections.brake_release_s`` / ``brake_engage_s``)."""
        if enabled != self._drives_on:
            self._drives_on = enabled
            self._drives_changed_t = self.t

    @property
    def brakes_engaged(self) -> bool:
        return bool(self.real[physics.R_BRAKE_ON] > 0.5)

    def _update_brakes(self) -> None:
        """The brakes' state: engaged ``brake_engage_s`` after the drives went off, released
        ``brake_release_s`` after they came back on; a shorter interruption (a DAC failover's
        card switch) changes nothing."""
        imp = self.imperfections
        if imp.brake_holding_force_n <= 0.0:
            return
        since = self.t - self._drives_changed_t
        on = self.real[physics.R_BRAKE_ON] > 0.5
        if self._drives_on and on and since >= imp.brake_release_s:
            on = False
        elif not self._drives_on and not on and since >= imp.brake_engage_s:
            on = True
        self.real[physics.R_BRAKE_ON] = 1.0 if on else 0.0

    def _held_input(self, volts):
        """The amplifier input held over the next period: the commands plus the input offset
        while the drives are on (``RigImperfections.amp_offset_v``)."""
        if self._with_offset and self._drives_on:
            np.add(volts, self.amp_offset_v, out=self._volts_in)
            return self._volts_in
        return volts

    def _fk_failed(self) -> KinematicsError:
        return KinematicsError(f"twin: forward kinematics failed at q = {self.q.tolist()} m "
                               f"(t = {self.t:.4f} s); the mechanism left its assembly range")

    def set_encoder_card(self, sign, m_per_count) -> None:
        """The encoder card's count direction and scale per axis (``FakePcl833Port.sign``,
        ``.m_per_count``), for :meth:`period`."""
        K = kernels
        self.P[K.P_PORT_SIGN:K.P_PORT_SIGN + 3] = sign
        self.P[K.P_PORT_MPC:K.P_PORT_MPC + 3] = m_per_count

    def warm_period(self, port: np.ndarray, ati: np.ndarray) -> None:
        """Load :meth:`period`'s kernel (numba's cache, or compile) now, on copies of the
        state: this plant, the card and the ATI are untouched.

        Why: the first call of a kernel holds the GIL for tens of ms while numba loads it, and
        reads the cache's files with it released. A twin behind a real-time loop in another
        thread (``tests/test_rig.py``) then left its amplifier input stale while the loop
        wrote three cycles of new commands, and the drive's monitor failed the channel over
        (preflight5's note, 2026-11-26b): loaded here, at construction, the period never
        pays that in a loop."""
        if not self.compiled:
            return
        codes = np.full(3, kernels.NO_CODE, dtype=np.int64)
        B = self.B.copy()
        P = B[kernels.B_P:kernels.B_P + kernels.P_SIZE]
        K = kernels
        P[K.P_PORT_SIGN:K.P_PORT_SIGN + 3] = 1.0     # a card's scale (set_encoder_card's,
        P[K.P_PORT_MPC:K.P_PORT_MPC + 3] = 1e-6      # unset until the first period)
        kernels.period_block(B, port.copy(), codes, ati.copy(), np.zeros((1, 12)), 1e-3, 5, 0,
                             0.0)

    def substeps(self, dt: float) -> int:
        """The physics substeps of a period of ``dt`` s (cached for the last ``dt``)."""
        last_dt, n = self._n_of_dt
        if dt != last_dt:
            n = max(1, round(dt * self.physics_rate_hz))
            self._n_of_dt = (dt, n)
        return n

    def period(self, dt: float, port: np.ndarray, codes: np.ndarray, ati: np.ndarray,
               ati_block: np.ndarray, ati_row: int, ati_dt: float) -> int:
        """The twin's fault-free period on the compiled path (``kernels.period_block``): the
        amplifier input from the DAC ``codes``, ``advance(dt, ·)``, the encoder card's
        counters (``port``, the card's int64 state; its scale from
        :meth:`set_encoder_card`) and the ATI sample (``ati``: the model's packed array) in
        one dispatch, the plant's time advanced in the block. Returns the ATI overload bits
        (``kernels.OVERLOAD_BITS`` on an overloaded axis). ``Twin._sync_fused`` makes the
        same call inline."""
        bits = kernels.period_block(self.B, port, codes, ati, ati_block, dt,
                                    self.substeps(dt), ati_row, ati_dt)
        if bits < 0:
            raise self._fk_failed()
        return bits

    def advance(self, dt: float, volts) -> None:
        """Hold amplifier commands ``volts`` (V, after the DAC) for ``dt`` s and integrate."""
        n = max(1, round(dt * self.physics_rate_hz))
        volts = self._held_input(volts)
        if self.compiled:
            if type(volts) is not np.ndarray:
                volts = np.asarray(volts, dtype=np.float64)
            status = kernels.advance(self.geom, self.P, self.env, self.S, self.W, volts, dt, n,
                                     self.t, self.realistic, self.integrator)
        elif not self.realistic:
            self._volts[:] = volts
            status = physics.integrate(self.geom, self.bodies, self.friction, self.env, self.q,
                                       self.qd, self.phi, self._volts, n, dt / n,
                                       self.integrator, self.env_state, self.qdd, self.wrench_s)
            self.xm[:] = self.q
            self.vm[:] = self.qd
        else:
            v = self._volts
            if v[0] != volts[0] or v[1] != volts[1] or v[2] != volts[2]:
                # A new command: the amplifiers keep acting on the old one for the delay.
                self._volts_prev[:] = v
                v[:] = volts
                self._delay_left = int(self.real[physics.R_AMP_DELAY_STEPS])
            self._update_brakes()
            status = physics.integrate_real(
                self.geom, self.bodies, self.friction_slider, self.friction_motor, self.env,
                self.real, self.q, self.qd,
                self.phi, self.xm, self.vm, self.current, self.cable_tau, v, self._volts_prev,
                self._delay_left, n, dt / n, self.env_state, self.qdd, self.wrench_s, self.rot)
            if self._delay_left < n:
                # The delay has ended (its fractional substep included): from now on the
                # amplifiers' previous command is the present one.
                self._volts_prev[:] = v
            self._delay_left = max(0, self._delay_left - n)
            self._heat(dt)
        if status != physics.STATUS_OK:
            raise self._fk_failed()
        self.t += dt

    def _heat(self, dt: float) -> None:
        """First-order thermal model per axis: friction power in, convection out. The friction
        power is sampled every call; the temperature and the friction scales are updated every
        ``_HEAT_PERIOD_S`` (the thermal time constant is minutes: R C = 400 s)."""
        imp = self.imperfections
        if imp.viscous_per_k == 0.0 and imp.coulomb_per_k == 0.0:
            return
        fr = self.friction
        acc = self._heat_energy
        for i in range(3):
            v = float(self.qd[i])
            acc[i] += dt * (fr[11 + i] * fr[i] * v * v + fr[14 + i] * fr[3 + i] * abs(v))
        self._heat_time += dt
        if self._heat_time < _HEAT_PERIOD_S:
            return
        cap = imp.heat_capacity_j_per_k
        res = imp.thermal_resistance_k_per_w
        span = self._heat_time
        for i in range(3):
            self.temperature_rise_k[i] += (acc[i] - span * self.temperature_rise_k[i] / res) / cap
            acc[i] = 0.0
        self._heat_time = 0.0
        self._update_temperature_scales()

    @property
    def in_contact(self) -> bool:
        """True while the plate environment's contact is closed."""
        return bool(self.env_state[0] > 0.0)
