"""The thesis's fixed-parameter laws (3.6.1, 3.6.2), all on the nominal model.

Default gains put the closed loop's error dynamics near ω = 40 rad/s, ζ ≈ 1 for the ~210 kg per
axis that the sliders weigh with their reflected rotor inertia: Kp = m ω², Kd = 2 ζ m ω. The
model-based laws use the model's friction F(q̇_d) as feedforward (the thesis's C term of eq. 35
holds the friction); PID and PD use none.

Gain ranges (``gain_ranges``) keep the closed loop where it is known to behave on this robot:
natural frequencies ω from 5 to 150 rad/s (below 5 the platform sags centimetres under its own
weight; above 150 the 1 kHz sampling, the velocity estimator's lag and the 20 µm encoder
quantization make it ring) and damping ratios up to 2, for the ~210 kg per axis. Integral
clamps stay below what the drives can give (6 V × 339 N/V ≈ 2 kN per axis).
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Annotated

import numpy as np
from pydantic import Field

from rt.control import kernels as ck
from rt.control.base import STATUS_OK, Controller, GainRange, Gains, Reference, register
from rt.errors import KinematicsError
from rt.model.dynamics import State
from rt.model.kinematics import FK_MAX_ITERATIONS, FK_STEP_TOL_RAD

Positive = Annotated[float, Field(gt=0.0, allow_inf_nan=False)]
NonNegative = Annotated[float, Field(ge=0.0, allow_inf_nan=False)]


class PdGains(Gains):
    kp_n_per_m: Positive = 3.4e5
    kd_n_s_per_m: Positive = 1.7e4


class PidGains(PdGains):
    ki_n_per_m_s: NonNegative = 2.0e6
    integral_limit_n: Positive = 1500.0


class CtGains(Gains):
    """Computed torque: gains on the linearised error dynamics (1/s², 1/s)."""

    kp_per_s2: Positive = 1600.0
    kd_per_s: Positive = 80.0


#: Kp = m ω², Kd = 2 ζ m ω with m ≈ 210 kg, ω ∈ [5, 150] rad/s, ζ ≤ 2 (module docstring).
PD_RANGES = {"kp_n_per_m": GainRange(5.0e3, 5.0e6, "N/m"),
             "kd_n_s_per_m": GainRange(1.0e3, 1.5e5, "N s/m")}
PID_RANGES = {**PD_RANGES, "ki_n_per_m_s": GainRange(0.0, 2.0e7, "N/(m s)"),
              "integral_limit_n": GainRange(1.0, 2500.0, "N")}
#: Kp = ω², Kd = 2 ζ ω on the linearised error dynamics, same ω and ζ.
CT_RANGES = {"kp_per_s2": GainRange(25.0, 22500.0, "1/s²"),
             "kd_per_s": GainRange(5.0, 600.0, "1/s")}


def _bound(kernel: Callable[..., None], *args: object) -> Callable[[float], int]:
    """``cycle(dt)`` calling a law's kernel on fixed arguments (laws that do not use dt)."""
    def cycle(dt: float) -> int:
        kernel(*args)
        return STATUS_OK
    return cycle


def _pd(g: PdGains, st: State, ref: Reference, out: np.ndarray) -> None:
    q = st.config.q
    e = q[0] - ref.q[0], q[1] - ref.q[1], q[2] - ref.q[2]
    for i in range(3):
        out[i] = -g.kp_n_per_m * e[i] - g.kd_n_s_per_m * (st.qd[i] - ref.qd[i])


@register
class Pid(Controller):
    """τ = −Kp e − Kd ė − Ki ∫e (thesis table 5), integral clamped (anti-windup)."""

    name = "pid"
    gains: PidGains
    gains_type = PidGains
    gain_ranges = PID_RANGES

    def reset(self) -> None:
        super().reset()
        self.integral = np.zeros(3)        # ∫ e dt (m s)

    def _law(self, st, ref, dt, out, dry_run):
        g = self.gains
        _pd(g, st, ref, out)
        limit = g.integral_limit_n / g.ki_n_per_m_s if g.ki_n_per_m_s > 0 else 0.0
        for i in range(3):
            integ = self.integral[i] + (st.cfg.q[i] - ref.q[i]) * dt
            integ = max(-limit, min(limit, integ))
            if not dry_run:
                self.integral[i] = integ
            out[i] -= g.ki_n_per_m_s * integ
        return STATUS_OK

    def _pack_gains(self) -> None:
        g = self.gains
        self._gain_array[:] = (g.kp_n_per_m, g.kd_n_s_per_m, g.ki_n_per_m_s, g.integral_limit_n)

    def _law_compiled(self, st, ref, dt, out, dry_run):
        ck.pid(st.buf, ref.q, ref.qd, self._gain_array, self.integral, dt, dry_run, out)
        return STATUS_OK

    def _bound_kernel(self, st, ref, out):
        kernel, stb, q, qd, g = ck.pid, st.buf, ref.q, ref.qd, self._gain_array

        def cycle(dt: float) -> int:
            kernel(stb, q, qd, g, self.integral, dt, False, out)   # reset() replaces integral
            return STATUS_OK
        return cycle

    def _absorb(self, difference: np.ndarray) -> None:
        # Bumpless: preload the integrator so the first output equals the previous one.
        ki = self.gains.ki_n_per_m_s
        if ki > 0:
            self.integral -= difference / ki
        else:
            super()._absorb(difference)


@register
class PdG(Controller):
    """PD+G: τ = −Kp e − Kd ė + G(q)."""

    name = "pd_g"
    gains: PdGains
    gains_type = PdGains
    gain_ranges = PD_RANGES

    def _law(self, st, ref, dt, out, dry_run):
        _pd(self.gains, st, ref, out)
        out += self.dyn.gravity(st)
        return STATUS_OK

    def _pack_gains(self) -> None:
        self._gain_array[0] = self.gains.kp_n_per_m
        self._gain_array[1] = self.gains.kd_n_s_per_m

    def _law_compiled(self, st, ref, dt, out, dry_run):
        d = self.dyn
        ck.pd_gravity(d.tree_i, d.tree_f, st.buf, ref.q, ref.qd, self._gain_array, self._work,
                      out)
        return STATUS_OK

    def _bound_kernel(self, st, ref, out):
        d = self.dyn
        return _bound(ck.pd_gravity, d.tree_i, d.tree_f, st.buf, ref.q, ref.qd,
                      self._gain_array, self._work, out)


@register
class PdG0(Controller):
    """PD+G0: τ = −Kp e − Kd ė + G(q_d); G at the desired position, cached while q_d holds."""

    name = "pd_g0"
    gains: PdGains
    gains_type = PdGains
    gain_ranges = PD_RANGES

    def reset(self) -> None:
        self._g_at = None
        self._state_d = None
        # The compiled law's cache and scratch (``ck.pd_gravity_desired``): G at q_d, the q_d
        # it was computed at, the FK's tolerances, and one scratch array for the FK at q_d.
        self._g0 = np.zeros(ck.G0_SIZE)
        self._g0[ck.G0_TOL] = FK_STEP_TOL_RAD
        self._g0[ck.G0_MAXIT] = FK_MAX_ITERATIONS
        self._g = self._g0[ck.G0_G:ck.G0_G + 3]     # the interpreted law's cached G, too
        self._g0_scratch = np.zeros(ck.g0_scratch_size(self._work.shape[0]))
        super().reset()

    def _law(self, st, ref, dt, out, dry_run):
        key = (float(ref.q[0]), float(ref.q[1]), float(ref.q[2]))
        if key != self._g_at:
            if self._state_d is None:
                self._state_d = State()
            self._g[:] = self.dyn.gravity(self.dyn.state(ref.q, out=self._state_d))
            self._g_at = key
        _pd(self.gains, st, ref, out)
        out += self._g
        return STATUS_OK

    def _pack_gains(self) -> None:
        self._gain_array[0] = self.gains.kp_n_per_m
        self._gain_array[1] = self.gains.kd_n_s_per_m

    def _law_compiled(self, st, ref, dt, out, dry_run):
        d = self.dyn
        kin = d.kin
        status = ck.pd_gravity_desired(d.tree_i, d.tree_f, kin.geom, kin.limits_array,
                                       kin._phi_guess, st.buf, ref.q, ref.qd, self._gain_array,
                                       self._g0, self._g0_scratch, out)
        if status < 0:
            _no_fk_at(ref.q, status)
        return STATUS_OK

    @staticmethod
    def refuse_desired(q_d: np.ndarray, status: int) -> None:
        """Raise what a refused FK at the desired position raises (the fused cycle too)."""
        _no_fk_at(q_d, status)

    def _bound_kernel(self, st, ref, out):
        # A new desired position: FK there (compiled; it shares the model's warm start like
        # ``_law``), then G, all in the kernel; refused FK raises as ``_law`` does. Every
        # array is bound here: the model's are fixed after construction, and a reset (which
        # replaces the cache and scratch) rebinds.
        d = self.dyn
        kin = d.kin
        kernel, ti, tf, geom, limits, phi = ck.pd_gravity_desired, d.tree_i, d.tree_f, \
            kin.geom, kin.limits_array, kin._phi_guess
        stb, q, qd, gains, g0, scratch = st.buf, ref.q, ref.qd, self._gain_array, self._g0, \
            self._g0_scratch

        def cycle(dt: float) -> int:
            status = kernel(ti, tf, geom, limits, phi, stb, q, qd, gains, g0, scratch, out)
            if status < 0:
                _no_fk_at(q, status)
            return STATUS_OK
        return cycle


def _no_fk_at(q_d: np.ndarray, status: int) -> None:
    raise KinematicsError(f"PD+G0: no forward kinematics at the desired position "
                          f"{tuple(float(x) for x in q_d)} m (status {status})")


@register
class PadenPanja(Controller):
    """τ = M(q) q̈_d + C(q, q̇) q̇_d + G(q) + F(q̇_d) − Kp e − Kd ė (thesis eq. 19)."""

    name = "paden_panja"
    gains: PdGains
    gains_type = PdGains
    gain_ranges = PD_RANGES

    def _law(self, st, ref, dt, out, dry_run):
        m, c, g = self.dyn.mcg(st)
        _pd(self.gains, st, ref, out)
        out += m @ ref.qdd + c @ ref.qd + g + self.dyn.friction(ref.qd)
        return STATUS_OK

    def _pack_gains(self) -> None:
        self._gain_array[0] = self.gains.kp_n_per_m
        self._gain_array[1] = self.gains.kd_n_s_per_m

    def _law_compiled(self, st, ref, dt, out, dry_run):
        d = self.dyn
        ck.paden_panja(d.tree_i, d.tree_f, st.buf, ref.q, ref.qd, ref.qdd, self._gain_array,
                       self._work, out)
        return STATUS_OK

    def _bound_kernel(self, st, ref, out):
        d = self.dyn
        return _bound(ck.paden_panja, d.tree_i, d.tree_f, st.buf, ref.q, ref.qd, ref.qdd,
                      self._gain_array, self._work, out)


def _computed_torque(dyn, st: State, v: np.ndarray, out: np.ndarray) -> None:
    """τ = M(q) v + C(q, q̇) q̇ + G(q) + F(q̇): the inverse-dynamics part both laws share."""
    m, c, g = dyn.mcg(st)
    out[:] = m @ v + c @ st.qd + g + dyn.friction(st.qd)


class _ComputedTorque(Controller):
    """The computed-torque laws: τ = M(q) v + C q̇ + G + F(q̇) with v from the gains; the
    regulation law (``tracking`` False) feeds no reference velocity nor acceleration forward."""

    gains: CtGains
    gains_type = CtGains
    gain_ranges = CT_RANGES
    #: True: v = q̈_d − Kd ė − Kp e (trajectory tracking); False: v = −Kd q̇ − Kp e.
    tracking: bool

    def _law(self, st, ref, dt, out, dry_run):
        g_ = self.gains
        e = np.asarray(st.cfg.q) - ref.q
        if self.tracking:
            v = ref.qdd - g_.kd_per_s * (st.qd - ref.qd) - g_.kp_per_s2 * e
        else:
            v = -g_.kd_per_s * st.qd - g_.kp_per_s2 * e
        _computed_torque(self.dyn, st, v, out)
        return STATUS_OK

    def _pack_gains(self) -> None:
        self._gain_array[0] = self.gains.kp_per_s2
        self._gain_array[1] = self.gains.kd_per_s

    def _law_compiled(self, st, ref, dt, out, dry_run):
        d = self.dyn
        ck.computed_torque(d.tree_i, d.tree_f, st.buf, ref.q, ref.qd, ref.qdd,
                           self._gain_array, self.tracking, self._work, out)
        return STATUS_OK

    def _bound_kernel(self, st, ref, out):
        d = self.dyn
        return _bound(ck.computed_torque, d.tree_i, d.tree_f, st.buf, ref.q, ref.qd, ref.qdd,
                      self._gain_array, self.tracking, self._work, out)


@register
class ComputedTorquePtp(_ComputedTorque):
    """τ = M(q)(−Kd q̇ − Kp e) + C q̇ + G + F(q̇) (thesis eq. 29): regulation to q_d."""

    name = "computed_torque_ptp"
    tracking = False


@register
class ComputedTorqueTrajectory(_ComputedTorque):
    """τ = M(q)(q̈_d − Kd ė − Kp e) + C q̇ + G + F(q̇) (thesis eq. 31): ë + Kd ė + Kp e = 0."""

    name = "computed_torque"
    tracking = True
