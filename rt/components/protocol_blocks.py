"""The protocol-driven blocks: a protocol generator as the loop's reference, and the hybrid
position/force controller it drives."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rt.control.base import Controller, Reference
from rt.control.force import ExplicitForce, ForceReference
from rt.engine import Array, Component, Struct
from rt.model.dynamics import State
from rt.references.approach import Approach, ApproachStatus
from rt.safety.supervisor import Supervisor

#: First-order smoothing of F̈_d per cycle (≈ 35 Hz at 1 kHz).
F_DDOT_SMOOTHING = 0.2
PHASE_APPROACH, PHASE_PLAY, PHASE_RETURN, PHASE_STOPPED, PHASE_DONE = 0, 1, 2, 3, 4


@dataclass
class _State:
    phase: int = PHASE_APPROACH
    mode: float = 0.0
    started: bool = False


class ProtocolReference(Component):
    """Ports: in ``q_meas``: float64[3] m; in ``mode``: float64[1] (supervisor, one cycle late);
    in ``wrench``: float64[6] (sensor frame: the patient's torques for interactive protocols).
    Out ``q_ref``, ``qd_ref``, ``qdd_ref``: float64[3] (m, m/s, m/s²); ``force``: float64[3]
    (F_d N, Ḟ_d N/s, F̈_d N/s²); ``pose``: float64[3] (z m, roll, pitch rad); ``ctrl_mode``:
    float64[1] (0 position, 1 force); ``phase``: float64[1] (0 approach, 1 play, 2 return to
    rest, 3 stopped by the supervisor, 4 done); ``progress``: float64[1] (0..1).

    A ruckig approach brings the robot from where it is to the protocol's first state; the
    generator plays (allocate-once ``update``); a jerk-limited stop returns it to rest. A soft
    stop brakes the position reference and ramps the force reference down to zero over
    ``force_ramp_s``; a hard stop makes the reference follow the measured position.
    """

    def __init__(self, name: str, generator, stroke: tuple[float, float], dt: float,
                 force_ramp_s: float = 0.3):
        super().__init__(name)
        self.gen = generator
        self.out = generator.new_output()
        self.approach = Approach(dt=dt, stroke=stroke)
        self.force_ramp_s = force_ramp_s
        self.q_meas = self.declare_input("q_meas", Array(3))
        self.mode = self.declare_input("mode", Array(1))
        self.wrench = self.declare_input("wrench", Array(6))
        self.q_ref = self.declare_output("q_ref", Array(3))
        self.qd_ref = self.declare_output("qd_ref", Array(3))
        self.qdd_ref = self.declare_output("qdd_ref", Array(3))
        self.force = self.declare_output("force", Array(3))
        self.pose = self.declare_output("pose", Array(3))
        self.ctrl_mode = self.declare_output("ctrl_mode", Array(1))
        self.phase = self.declare_output("phase", Array(1))
        self.progress = self.declare_output("progress", Array(1))
        self._n = max(1, int(round(generator.duration_s / dt)))
        from protocols.output import GeneratorInput

        # Interactive protocols (active assist) read the patient's torques each cycle.
        self._inp = GeneratorInput()
        self._k = 0

    def make_state(self):
        return _State()

    def _begin(self) -> bool:
        first = self.gen.new_output()
        self.gen.reset()
        self.gen.update(first)
        self.gen.reset()
        self.approach.reset(self.q_meas.data)
        status = self.approach.set_target(first.q_ref, first.qd_ref, first.qdd_ref)
        self.state.started = True
        return status == ApproachStatus.WORKING

    def update(self, t: float, dt: float) -> int:
        st = self.state
        if not st.started and not self._begin():
            return 20
        mode = self.mode.data[0]
        if mode != st.mode:
            if 2.0 <= mode < 3.0 and st.phase in (PHASE_APPROACH, PHASE_PLAY):
                self.approach.reset(self.q_ref.data, self.qd_ref.data, self.qdd_ref.data)
                self.approach.soft_stop()
                st.phase = PHASE_STOPPED
            elif mode >= 3.0:
                st.phase = PHASE_STOPPED
            st.mode = mode
        f = self.force.data
        if mode >= 3.0:
            self.q_ref.data[:] = self.q_meas.data
            self.qd_ref.data[:] = 0.0
            self.qdd_ref.data[:] = 0.0
            f[:] = 0.0
            self.ctrl_mode.data[0] = 0.0
        elif st.phase == PHASE_STOPPED:
            self.approach.update(self.q_ref.data, self.qd_ref.data, self.qdd_ref.data)
            # Force ramps down linearly; the position law holds once it reaches zero.
            if self.ctrl_mode.data[0] > 0.5:
                f[0] = max(0.0, f[0] - (abs(f[0]) + 1.0) * dt / self.force_ramp_s) \
                    if f[0] > 1.0 else 0.0
                f[1] = f[2] = 0.0
                if f[0] == 0.0:
                    self.ctrl_mode.data[0] = 0.0
        elif st.phase == PHASE_APPROACH:
            if self.approach.update(self.q_ref.data, self.qd_ref.data,
                                    self.qdd_ref.data) == ApproachStatus.FINISHED:
                st.phase = PHASE_PLAY
        elif st.phase == PHASE_PLAY:
            o = self.out
            w = self.wrench.data
            inp = self._inp
            # The patient's torques on the platform about roll (x) and pitch (y), N·m.
            inp.tau_roll_nm = 0.0 if math.isnan(w[3]) else float(w[3])
            inp.tau_pitch_nm = 0.0 if math.isnan(w[4]) else float(w[4])
            status = self.gen.update(o, inp)
            if status < 0:
                return 21
            self._k += 1
            self.q_ref.data[:] = o.q_ref
            self.qd_ref.data[:] = o.qd_ref
            self.qdd_ref.data[:] = o.qdd_ref
            self.pose.data[:] = o.pose_ref
            force_mode = o.mode == 1
            self.ctrl_mode.data[0] = 1.0 if force_mode else 0.0
            fz = o.fz_ref
            if force_mode and not math.isnan(fz):
                f_dot = o.fz_ref_dot
                # F̈_d by a low-passed first difference of Ḟ_d (only the small inertia
                # feedforward uses it; recorded gait forces are not smooth to second order).
                raw = (f_dot - f[1]) / dt if self._k > 1 else 0.0
                f[2] += F_DDOT_SMOOTHING * (raw - f[2])
                f[0], f[1] = fz, f_dot
            else:
                f[:] = 0.0
            if o.done:
                if force_mode:
                    # Leaving force control: the position law takes over where the robot is.
                    self.q_ref.data[:] = self.q_meas.data
                    self.qd_ref.data[:] = 0.0
                    self.qdd_ref.data[:] = 0.0
                self.approach.reset(self.q_ref.data, self.qd_ref.data, self.qdd_ref.data)
                self.approach.soft_stop()
                self.ctrl_mode.data[0] = 0.0
                f[:] = 0.0
                st.phase = PHASE_RETURN
        elif st.phase == PHASE_RETURN:
            if self.approach.update(self.q_ref.data, self.qd_ref.data,
                                    self.qdd_ref.data) == ApproachStatus.FINISHED:
                st.phase = PHASE_DONE
        else:
            self.approach.update(self.q_ref.data, self.qd_ref.data, self.qdd_ref.data)
        self.phase.data[0] = st.phase
        self.progress.data[0] = min(1.0, self._k / self._n)
        return 0


class HybridController(Component):
    """Ports: in ``state``: model ``State``; ``q_ref``, ``qd_ref``, ``qdd_ref``: float64[3];
    ``force``: float64[3]; ``pose``: float64[3]; ``ctrl_mode``: float64[1]; ``wrench``:
    float64[6] (sensor frame); ``mode``: float64[1] (supervisor, one cycle late). Out ``tau``:
    float64[3] N.

    Position mode: the position law tracks the slider references. Force mode: hybrid explicit
    force in z (F = −w_S.fz, the platform's push) with roll and pitch held. Switching between
    them resets the force law's integral so the force starts from its feedforward. The
    supervisor is told when the loop depends on the force sensor. The force reference handed
    to the law is never below the law's preload (``preload_n``, N): the platform only pushes
    on a foot (``rt.control.force``).
    """

    def __init__(self, name: str, position: Controller, force: ExplicitForce,
                 supervisor: Supervisor):
        super().__init__(name)
        self.position = position
        self.force_law = force
        self.supervisor = supervisor
        self.state_in = self.declare_input("state", Struct(State))
        self.q_ref = self.declare_input("q_ref", Array(3))
        self.qd_ref = self.declare_input("qd_ref", Array(3))
        self.qdd_ref = self.declare_input("qdd_ref", Array(3))
        self.force = self.declare_input("force", Array(3))
        self.pose = self.declare_input("pose", Array(3))
        self.ctrl_mode = self.declare_input("ctrl_mode", Array(1))
        self.wrench = self.declare_input("wrench", Array(6))
        self.mode = self.declare_input("mode", Array(1))
        self.tau = self.declare_output("tau", Array(3))
        self._ref = Reference()
        self._fref = ForceReference()
        self._in_force = False
        self._sup_mode = 0.0
        self._offset = 0.0
        self.entry_time_s = 0.3
        self._decay_per_s = math.exp(-1.0 / self.entry_time_s)
        #: Deceleration the platform can give when the force falls to the preload (m/s²).
        self.unload_decel_m_s2 = 0.5
        self._f_gov = math.nan

    def _govern(self, fr: ForceReference, dt: float) -> None:
        """The force reference as the law gets it: never below the preload, and falling to it
        no faster than the platform can brake. Unloading at rate Ḟ moves the platform down at
        Ḟ/k through a contact of stiffness k; stopping that motion within the force left above
        the preload, (F − F_min)/k of travel, needs Ḟ² ≤ 2 a k (F − F_min). A toe off that
        unloads faster (≈ 8 kN/s in real records) would carry the platform past the preload
        into pulling on the foot; the reference is slowed there instead (rising is followed
        as it is)."""
        floor = self.preload_n
        target = fr.f if fr.f > floor else floor
        g = self._f_gov
        if math.isnan(g) or target >= g:
            self._f_gov = target
            if target == floor:
                fr.f_dot = fr.f_ddot = 0.0
            fr.f = target
            return
        k = self.force_law.k_est
        max_rate = math.sqrt(2.0 * self.unload_decel_m_s2 * k * (g - floor))
        step = min(g - target, max_rate * dt)
        self._f_gov = g - step
        fr.f, fr.f_dot, fr.f_ddot = self._f_gov, -step / dt, 0.0

    @property
    def preload_n(self) -> float:
        """The force reference's floor (N): the force law's preload."""
        return float(self.force_law.gains.preload_n)

    def update(self, t: float, dt: float) -> int:
        mode = self.mode.data[0]
        if mode != self._sup_mode:
            if self._sup_mode >= 3.0 and mode < 3.0:
                self.position.reset()
                self.force_law.reset()
            self._sup_mode = mode
        force_mode = self.ctrl_mode.data[0] > 0.5
        measured = -self.wrench.data[2]
        if force_mode != self._in_force:
            self.force_law.reset()
            self._in_force = force_mode
            self.supervisor.force_control = force_mode
            # Bumpless entry: the reference starts from the force the contact already carries
            # and converges to the protocol's with time constant ``entry_time_s``.
            self._offset = 0.0 if math.isnan(measured) else measured - self.force.data[0]
            self._f_gov = math.nan
        st = self.state_in.data
        if force_mode:
            fr = self._fref
            f = self.force.data
            off = self._offset
            self._offset = off * self._decay_per_s ** dt
            fr.f = f[0] + off
            fr.f_dot = f[1] - off / self.entry_time_s
            fr.f_ddot = f[2] + off / self.entry_time_s ** 2
            self._govern(fr, dt)
            fr.roll, fr.pitch = self.pose.data[1], self.pose.data[2]
            fr.roll_rate = fr.pitch_rate = 0.0
            return self.force_law.update(st, measured, fr, dt, self.tau.data)
        r = self._ref
        r.q, r.qd, r.qdd = self.q_ref.data, self.qd_ref.data, self.qdd_ref.data
        return self.position.update(st, r, dt, self.tau.data)
