"""Force control of Fz through the ATI sensor (DESIGN 5; thesis 3.7.5), hybrid with position:
force along the platform's z, roll and pitch held in position.

Sign convention: ``F`` is the force the platform applies along its z axis to what it touches
(N, positive pushing up), i.e. ``F = −w_S.fz`` of the sensor wrench (the environment's force
on the platform). Task coordinates x = (z, roll, pitch); task forces map to the sliders through
the forward-kinematics Jacobian: τ = J_fkᵀ Q_x (power: τᵀ q̇ = Q_xᵀ ẋ).

Unilateral contact: the platform only pushes on a foot, it never pulls. Both laws take the
reference no lower than a preload F_min (``preload_n``, default 10 N): F_d = max(F_d, F_min),
and the explicit law never commands a task force below F_min (its integral does not wind
further down while the command is held there). The supervisor soft-stops if the measured F
stays below 0 N anyway (``rt.safety.supervisor``).

* ``ExplicitForce`` — Q_z = F_d + Kp (F_d − F) + Ki ∫(F_d − F) − D (ż − ż_ff) (Kp, Ki
  scheduled on the contact's stiffness, below), plus the
  feedforward of the motion the force profile implies through the contact stiffness k:
  ż_ff = Ḟ_d / k, z̈_ff = F̈_d / k, compensated with the model (friction F(q̇_ff), inertia).
  k is estimated online (recursive least squares on F against z, with forgetting) from an
  initial guess. ż_ff is bounded by ``max_feedforward_speed_m_s``: a heel strike rises by
  0.5 BW in ~5 ms, which through a 1e5 N/m heel would ask 0.4 m/s of the platform, far beyond
  what its actuators can reach in that time; the bounded feedforward (z̈_ff too, by
  ``max_feedforward_accel_m_s2``) leaves the rest to the feedback instead of demanding
  kilonewtons. Roll/pitch: PID on the angles (integral below) with gravity compensation G(q).
  The integral is held (conditional integration) while a drive would be at its force limit
  in the direction the integral pushes (``drive_force_limit_n``: the amplifier's current or
  command limit), and while the reference is a rise beyond what the robot follows
  (``ForceReference.transient``): a heel strike asks 2.7-3 kN of ≈ 2 kN drives for a few ms,
  and an integral wound up there overshoots for tens of ms afterwards.
  Gain schedule on the contact's stiffness (``schedule_stiffness_n_per_m``, k_s): through a
  contact of stiffness k the force error moves the platform with the gain (1 + Kp) k (the 1 is
  the contact pushing back), and the integral's loop runs at Ki / (1 + Kp). Tuned on the foot
  (1e5 N/m), the same gains against the calibration plate (2e6 N/m) put the contact mode at
  ≈ 57 Hz with ζ ≈ 0.05 (a 20 N step rings at 53 Hz on the twin), with less damping than the
  sensor's filter and the loop's delay take away: only the sliders' Coulomb friction kept small
  oscillations from growing, and a tip sliding at its friction cone grew them into a 28-33 Hz
  limit cycle, the tip leaving the plate each cycle (ATI 0-1.1 kN, commands ±8.7 kN against
  ≈ 2 kN drives). Above k_s both (1 + Kp) and the integral's rate are scaled by k_s / k̂ (k̂:
  the online estimate below), so a stiffer contact has the loop's poles of k_s. k_s = 2.5e5:
  above the foot's k̂ (0.75-2.4e5 over a stance: its figures unchanged); at 5e5 the shear
  push under a fast roll still bounced (tests/test_force_stiff_contact.py).
  Approach (``approach_force_margin_n``): before contact (F ≤ ``CONTACT_TOUCH_N``) the law is
  a velocity loop that met the calibration plate at 45 mm/s (≈ 1.6 kN of impact, drives
  saturated); Q_z is bounded so the platform closes the gap no faster than margin / √(k m),
  k the contact it expects (the guess, or a remembered contact's), the integral held
  meanwhile (``rt.control.kernels.approach_speed``). Only until the first touch after each
  force-mode entry (latched, ``FS_TOUCHED``; ``reset`` re-arms it): an overload that sinks
  the platform away from the foot unloads the sensor too, and must meet the law unbounded.
  Roll and pitch: PD plus an integral (``angle_ki_n_m_per_rad_s``, clamped): a tip dragged
  across a plate at its friction cone resists with μ N h (≈ 60 N m under 600 N), which the PD
  alone leaves 0.8° short.
  Preview (``preview_s``): a reference known in advance (a protocol's table) is read that far
  ahead by the sequencer; the hybrid controller tracks the read-ahead reference while the
  program asks more than the robot follows (``rt.components.protocol_blocks``), so the push
  of a heel strike and the fall of a toe off start that much earlier.
* ``Admittance`` — the contact is rendered as a virtual mass-damper-spring in z driven by the
  force error, M_a z̈_c + D_a ż_c = F − F_d, and the resulting pose (z_c, roll_d, pitch_d) is
  tracked by the inner Paden-Panja position law (IK to slider references each cycle).
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Annotated, Any, TypeVar

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from rt.control import kernels as ck
from rt.control.base import GainRange, Reference, check_gain_ranges, check_range_table, create
from rt.errors import ConfigurationError
from rt.model import RobotModel
from rt.model import rigid_body as rb
from rt.model.dynamics import State
from rt.model.kernels import TREE_DOF

Pos = Annotated[float, Field(gt=0.0, allow_inf_nan=False)]
NonNeg = Annotated[float, Field(ge=0.0, allow_inf_nan=False)]


@dataclass
class ForceReference:
    """F_d (N), Ḟ_d (N/s), F̈_d (N/s²) and the held pose: z (m, used by admittance as the
    starting height), roll, pitch (rad) with their rates (rad/s)."""

    f: float = 0.0
    f_dot: float = 0.0
    f_ddot: float = 0.0
    roll: float = 0.0
    pitch: float = 0.0
    roll_rate: float = 0.0
    pitch_rate: float = 0.0
    #: The reference is a transient beyond what the robot follows (a heel strike, a fast toe
    #: off; ``rt.components.protocol_blocks.HybridController``): its error is the transient's,
    #: not a steady disturbance, so the integral holds instead of winding up for the
    #: overshoot after it.
    transient: bool = False


class ExplicitForceGains(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_assignment=True)
    # 40 N/N (was 20): on the realistic twin the nominal model's per-axis friction is up to
    # 30 % off the truth, and the proportional action is what rejects that error at the
    # sine's reversals (sine Fz 1 Hz: 2.16 → 1.32 % of amplitude; gait 1.08 → 0.75 % of peak;
    # the 2e6 N/m plate's push unchanged, 9.4 N RMS). Higher Ki made it worse (2000: 2.30 %).
    kp: NonNeg = 40.0                      # N/N
    ki_per_s: NonNeg = 1000.0              # N/(N s)
    damping_n_s_per_m: NonNeg = 2.0e4
    #: The integral's clamp (N of task force along z): the steady force along z the model
    #: does not account for, which only the integral carries with no force error left (the
    #: nominal model's friction and gravity errors, an amplifier's offset, an unmeasured load
    #: on the platform: 500 kg is 4.9 kN). It may need all the drives give along z; a lower
    #: clamp leaves the rest to the proportional term, i.e. a force error of excess/Kp (1500
    #: under 500 kg: 200 → 118 N on the foot). The law clamps at the smaller of this and the
    #: drives' capacity along z (``ExplicitForce.integral_limit_n``: ≈ 6.1 kN), and holds the
    #: integral below that while a drive is at its limit (conditional integration).
    integral_limit_n: Pos = 1.0e4
    angle_kp_n_m_per_rad: Pos = 4000.0
    angle_kd_n_m_s_per_rad: Pos = 200.0
    #: Integral action on roll and pitch: a contact's steady torque (a tip dragged across a
    #: plate at its friction cone, μ N h ≈ 58 N m under 600 N; an off-centre load) would
    #: otherwise leave the angles short by torque / angle Kp (0.8° here). 2e4: its zero at
    #: Ki/Kp = 5 rad/s, well under the angle loop's ≈ 22 rad/s; it winds 58 N m in ≈ 0.2 s.
    angle_ki_n_m_per_rad_s: NonNeg = 2.0e4
    #: The angle integral's clamp (N m per axis): well above such torques, a fifth of what
    #: the drives give about the platform's axes.
    angle_integral_limit_n_m: Pos = 100.0
    stiffness_guess_n_per_m: Annotated[float, Field(ge=1e3, le=1e8)] = 1.0e5
    estimate_stiffness: bool = True
    forgetting: Annotated[float, Field(gt=0.9, le=1.0)] = 0.999
    preload_n: Annotated[float, Field(ge=0.0, le=200.0, allow_inf_nan=False)] = 10.0
    max_feedforward_speed_m_s: Pos = 0.05
    max_feedforward_accel_m_s2: Pos = 1.0
    #: How far ahead (s) the law reads a force reference known in advance (a protocol's
    #: precomputed table) while the reference asks more than the robot follows (the hybrid
    #: controller's ``_lead``: a heel strike, a fast toe off). 5 ms: on the twin a 20 kN/s
    #: step lags 6-11 ms, and the preview takes its own length off that lag (tests/
    #: test_force_preview.py); functional_walk plate 0 is best at 5 ms (3 ms: 3.67 %, 8 ms:
    #: 3.44 %). The loop's builder hands it to the sequencer (``preview_steps``); the law's
    #: arithmetic does not use it.
    preview_s: Annotated[float, Field(ge=0.0, le=0.05, allow_inf_nan=False)] = 0.005
    #: Gain schedule on the contact's stiffness: against a contact stiffer than this (the
    #: estimate k̂), (1 + Kp) and the integral's rate are scaled by k_s / k̂, so the loop's
    #: gain from height to force, (1 + Kp) k, stays what it is at k_s (module docstring).
    #: 0: no schedule.
    schedule_stiffness_n_per_m: Annotated[float, Field(ge=0.0, le=1e8, allow_inf_nan=False)] = 2.5e5
    #: Friction compensation against a stiff contact: the model's (believed) Coulomb friction
    #: per axis, in the direction the force error asks, where the gain schedule weakened the
    #: feedback (none on the foot, k̂ ≤ k_s; in full at k̂ ≥ 2 k_s). Without it a hold on the
    #: plate sticks and slips (``rt.control.kernels.error_friction``). 0: off.
    friction_compensation: Annotated[float, Field(ge=0.0, le=1.0, allow_inf_nan=False)] = 1.0
    #: Its deadband on the force error (N), ramping to full over a second one: 3σ of the
    #: ATI's z noise (0.25 N: the Delta's resolution), so the sensor's noise does not flip
    #: the compensation's direction in a hold.
    friction_deadband_n: Annotated[float, Field(ge=0.0, le=20.0, allow_inf_nan=False)] = 0.75
    #: Before contact (from the force-mode entry until the first cycle with F >
    #: ``rt.control.kernels.CONTACT_TOUCH_N``; latched off after it) the law closes the gap
    #: no faster than the impact onto the contact it expects overshoots by this much (N):
    #: v ≤ margin / √(k m), k the remembered contact's stiffness or the guess, m the drives'
    #: inertia along z (``rt.control.kernels.approach_speed``): 200 N → 25 mm/s onto the
    #: guess (1e5 N/m), 5.7 mm/s onto a remembered plate (2e6 N/m). 0: unbounded (the law
    #: before: the plate was met at 45 mm/s, ≈ 1.6 kN of impact, drives saturated).
    approach_force_margin_n: Annotated[
        float, Field(ge=0.0, le=5000.0, allow_inf_nan=False)] = 200.0


#: Explicit force: Kp above ~50 N/N or Ki above ~5000 1/s make the loop through a stiff plate
#: (1e5-1e7 N/m) ring at 1 kHz; damping and angle gains follow the PD laws' 5-150 rad/s family
#: (platform ≈ 630 kg through the legs in z, ≈ 8 kg m² in roll/pitch); the integral's clamp
#: up to the three drives' ≈ 6 kN along z.
EXPLICIT_FORCE_RANGES = {
    "kp": GainRange(0.0, 50.0, "N/N"),
    "ki_per_s": GainRange(0.0, 5000.0, "1/s"),
    "damping_n_s_per_m": GainRange(0.0, 1.0e5, "N s/m"),
    # The integral's task force along z: up to what three ≈ 2 kN drives give along z (the
    # law takes the smaller of this and the model's drives' capacity).
    "integral_limit_n": GainRange(1.0, 1.0e4, "N"),
    "angle_kp_n_m_per_rad": GainRange(100.0, 5.0e4, "N m/rad"),
    "angle_kd_n_m_s_per_rad": GainRange(1.0, 2000.0, "N m s/rad"),
    "angle_ki_n_m_per_rad_s": GainRange(0.0, 1.0e5, "N m/(rad s)"),
    "angle_integral_limit_n_m": GainRange(1.0, 500.0, "N m"),
    "stiffness_guess_n_per_m": GainRange(1.0e3, 1.0e8, "N/m"),
    "forgetting": GainRange(0.9, 1.0, ""),
    # The floor the reference never goes below: the platform only pushes on a foot.
    "preload_n": GainRange(0.0, 200.0, "N"),
    # Bounds on the motion feedforward (a heel strike once asked for 16 kN without them).
    "max_feedforward_speed_m_s": GainRange(0.001, 0.2, "m/s"),
    "max_feedforward_accel_m_s2": GainRange(0.01, 5.0, "m/s²"),
    # Preview of a reference known in advance: a few times the loop's lag at most (the lag
    # measured on the twin is 3-5 ms); 0 = none.
    "preview_s": GainRange(0.0, 0.05, "s"),
    # The stiffness above which the force loop's gains are scaled down (0: never): above the
    # foot's (the heel pad 1e5 N/m, k̂ 0.75-2.4e5 over a stance), below a plate's (≥ 1e6).
    "schedule_stiffness_n_per_m": GainRange(0.0, 1.0e8, "N/m"),
    # The believed Coulomb friction's share compensated in the force error's direction (more
    # than the model's own level would overcompensate a rig whose friction is lower).
    "friction_compensation": GainRange(0.0, 1.0, ""),
    # From the sensor's noise (a few σ) to a few N (beyond it the hold is friction-limited
    # again).
    "friction_deadband_n": GainRange(0.0, 20.0, "N"),
    # The impact overshoot the approach allows: a fraction of a push's force up to the
    # drives' capacity along z (0: unbounded).
    "approach_force_margin_n": GainRange(0.0, 5000.0, "N"),
}
#: Admittance: a virtual mass below 1 kg or a rate above 0.2 m/s would let the platform jump
#: at a patient's push; above 500 kg / 1e5 N s/m it no longer yields to a person.
ADMITTANCE_RANGES = {
    "virtual_mass_kg": GainRange(1.0, 500.0, "kg"),
    "virtual_damping_n_s_per_m": GainRange(100.0, 1.0e5, "N s/m"),
    "virtual_stiffness_n_per_m": GainRange(0.0, 1.0e6, "N/m"),
    "max_speed_m_s": GainRange(0.001, 0.2, "m/s"),
    "preload_n": GainRange(0.0, 200.0, "N"),
}


_GainsT = TypeVar("_GainsT", bound=BaseModel)


def _validate(owner: str, model_type: type[_GainsT], ranges: Mapping[str, GainRange],
              gains: Mapping[str, Any] | None) -> _GainsT:
    try:
        validated = model_type.model_validate(gains or {})
    except ValidationError as exc:
        msgs = "; ".join(f"{'.'.join(map(str, e['loc']))}: {e['msg']}" for e in exc.errors())
        raise ConfigurationError(f"force controller gains invalid: {msgs}") from None
    check_gain_ranges(owner, ranges, validated)
    return validated


@dataclass
class _Rls:
    """F ≈ k z + c by recursive least squares with forgetting (k in N/m)."""

    theta: np.ndarray = field(default_factory=lambda: np.zeros(2))
    P: np.ndarray = field(default_factory=lambda: np.eye(2))

    def update(self, z: float, f: float, lam: float) -> None:
        phi0, phi1 = z, 1.0
        P = self.P
        p0 = P[0, 0] * phi0 + P[0, 1] * phi1
        p1 = P[1, 0] * phi0 + P[1, 1] * phi1
        denom = lam + phi0 * p0 + phi1 * p1
        k0, k1 = p0 / denom, p1 / denom
        err = f - (self.theta[0] * phi0 + self.theta[1] * phi1)
        self.theta[0] += k0 * err
        self.theta[1] += k1 * err
        P[0, 0] = (P[0, 0] - k0 * p0) / lam
        P[0, 1] = (P[0, 1] - k0 * p1) / lam
        P[1, 0] = (P[1, 0] - k1 * p0) / lam
        P[1, 1] = (P[1, 1] - k1 * p1) / lam


class ExplicitForce:
    """Hybrid explicit force (z) / position (roll, pitch) law; see the module docstring."""

    name = "explicit_force"
    gains_type = ExplicitForceGains
    gain_ranges = EXPLICIT_FORCE_RANGES

    def __init__(self, model: RobotModel, gains: dict | None = None, compiled: bool = True):
        self.model = model
        self.dyn = model.dyn
        self.gains = _validate(self.name, ExplicitForceGains, self.gain_ranges, gains)
        self.axis_inertia = model.description.drive.reflected_inertia_kg
        #: ``update`` runs the compiled kernel (``rt.control.kernels.explicit_force``);
        #: ``False`` runs the interpreted law, its reference. Both keep their state in
        #: ``_fs`` (the properties below and the RLS are views of it).
        self.compiled = compiled
        self._fs = np.zeros(ck.FS_SIZE)
        self._fg = np.zeros(ck.FG_SIZE)
        drive = model.description.drive
        #: The force a drive gives at its limit (N at the slider): the amplifier's current limit
        #: or its command limit, whichever binds first. The law holds its integral while a
        #: drive would be there (anti-windup); the supervisor clips the command itself.
        self.drive_force_limit_n = drive.force_per_amp_n * min(
            drive.current_limit_a, drive.amplifier_gain_a_per_v * drive.command_limit_v)
        self._work = np.zeros(30 + rb.work_size(TREE_DOF))
        self._pack_gains()
        self.reset()
        if compiled:
            ck.warm_up(self.dyn)

    def _pack_gains(self) -> None:
        g = self.gains
        self._fg[:] = (g.kp, g.ki_per_s, g.damping_n_s_per_m, self.integral_limit_n,
                       g.angle_kp_n_m_per_rad, g.angle_kd_n_m_s_per_rad,
                       g.stiffness_guess_n_per_m, 1.0 if g.estimate_stiffness else 0.0,
                       g.forgetting, g.preload_n, g.max_feedforward_speed_m_s,
                       g.max_feedforward_accel_m_s2, self.axis_inertia,
                       self.drive_force_limit_n, g.schedule_stiffness_n_per_m,
                       g.angle_ki_n_m_per_rad_s, g.angle_integral_limit_n_m,
                       g.friction_compensation, g.friction_deadband_n,
                       g.approach_force_margin_n)

    @property
    def z_capacity_n(self) -> float:
        """What the drives give along the platform's z (N; 0: no limit known): the sliders are
        vertical, so their forces add along z, each carrying S_z,i of a task force Q_z
        (Σ S_z,i = 1; a third each at the level pose): 3 × 2036 N ≈ 6.1 kN."""
        return 3.0 * self.drive_force_limit_n

    @property
    def integral_limit_n(self) -> float:
        """The integral's clamp in use (N of task force along z): the gain
        ``integral_limit_n``, at most the drives' capacity along z (:attr:`z_capacity_n`). An
        unmeasured load the drives can carry is then carried by the integral with the force
        error back to zero; one they cannot carry saturates them, the integral holds
        (conditional integration) and the supervisor's checks decide (``rt.safety``)."""
        limit = float(self.gains.integral_limit_n)
        cap = self.z_capacity_n
        return min(limit, cap) if cap > 0.0 else limit

    @property
    def integral(self) -> float:
        """∫(F_d − F) dt (N s)."""
        return float(self._fs[ck.FS_INTEGRAL])

    @integral.setter
    def integral(self, value: float) -> None:
        self._fs[ck.FS_INTEGRAL] = value

    @property
    def k_est(self) -> float:
        """The contact stiffness estimate (N/m)."""
        return float(self._fs[ck.FS_K])

    @k_est.setter
    def k_est(self, value: float) -> None:
        self._fs[ck.FS_K] = value

    @property
    def _last_z(self) -> float:
        return float(self._fs[ck.FS_LAST_Z])

    @_last_z.setter
    def _last_z(self, value: float) -> None:
        self._fs[ck.FS_LAST_Z] = value

    def reset(self, stiffness_n_per_m: float | None = None) -> None:
        """Integrals to zero, the stiffness estimate back to its prior: the gains' guess, or
        ``stiffness_n_per_m`` (N/m) when the contact is known (the last contact's estimate,
        ``rt.components.protocol_blocks.HybridController``), held within the estimate's own
        bounds (1/5..20× the guess). The offset of F ≈ k z + c is relearned either way: a
        contact starts wherever the pose puts it."""
        g = self.gains
        guess = g.stiffness_guess_n_per_m
        k0 = guess
        if stiffness_n_per_m is not None and math.isfinite(stiffness_n_per_m):
            k0 = min(20.0 * guess, max(0.2 * guess, float(stiffness_n_per_m)))
        self.integral = 0.0
        fs = self._fs
        fs[ck.FS_ANGLE_I:ck.FS_ANGLE_I + 2] = 0.0
        self.rls = _Rls(fs[ck.FS_THETA:ck.FS_THETA + 2], fs[ck.FS_P:ck.FS_P + 4].reshape(2, 2))
        self.rls.P[:] = np.eye(2)
        self.rls.theta[:] = 0.0
        self.rls.theta[0] = k0
        # Prior: the guess is good to about ±50 %; the offset c (= −k z_contact) is unknown.
        self.rls.theta[1] = -k0 * 0.7
        self.rls.P[:] = np.diag([(0.5 * k0) ** 2 / 1e-4, 1e10])
        self._last_z = math.nan
        self.k_est = k0
        fs[ck.FS_K_APPROACH] = k0
        # The approach's bound armed until the first touch (``rt.control.kernels``).
        fs[ck.FS_TOUCHED] = 0.0
        self.tau = np.zeros(3)

    def expect_stiffness(self, stiffness_n_per_m: float) -> None:
        """The approach to the next contact bounded for this stiffness (N/m, held within
        1/5..20× the guess) instead of the guess's: a remembered contact whose k̂ is applied
        only on its first loaded cycle (``rt.components.protocol_blocks.HybridController``).
        Until then the gains stay the guess's."""
        guess = self.gains.stiffness_guess_n_per_m
        self._fs[ck.FS_K_APPROACH] = min(20.0 * guess, max(0.2 * guess, float(stiffness_n_per_m)))

    def prime_stiffness(self, stiffness_n_per_m: float) -> None:
        """Start the stiffness estimate from a known contact's (N/m, held within 1/5..20× the
        guess) without touching the integrals: the first loaded cycle of a contact whose
        stiffness is remembered (``rt.components.protocol_blocks.HybridController``). The
        same arithmetic as the compiled cycle's (``rt.control.kernels.prime_stiffness``)."""
        ck.prime_stiffness.py_func(self._fg, self._fs, float(stiffness_n_per_m))

    def set_gains(self, **changes) -> None:
        self.gains = _validate(self.name, ExplicitForceGains, self.gain_ranges,
                               {**self.gains.model_dump(), **changes})
        self._pack_gains()

    def _winds_up(self, base: np.ndarray, S: np.ndarray, fz: float, e: float) -> bool:
        """True when a drive would be at its force limit with τ = base + S_z fz and the
        integral's action on that axis (the sign of S_z e) pushes it further."""
        limit = self.drive_force_limit_n
        if limit <= 0.0 or e == 0.0:
            return False
        for i in range(3):
            tau = base[i] + S[8, i] * fz
            push = S[8, i] * e
            if (tau >= limit and push > 0.0) or (tau <= -limit and push < 0.0):
                return True
        return False

    def update(self, st: State, force_n: float, ref: ForceReference, dt: float,
               out: np.ndarray) -> int:
        """τ (N) into ``out``. ``force_n`` is the measured F (NaN → the law holds its integral
        and runs on feedforward; the supervisor decides whether that is acceptable)."""
        if self.compiled:
            d = self.dyn
            # float(): an int that slipped into the reference would make numba compile anew.
            ck.explicit_force(d.tree_i, d.tree_f, st.buf, self._fg, self._fs, float(force_n),
                              float(ref.f), float(ref.f_dot), float(ref.f_ddot),
                              float(ref.roll), float(ref.pitch), float(ref.roll_rate),
                              float(ref.pitch_rate), 1.0 if ref.transient else 0.0,
                              float(dt), self._work, out)
            self.tau[:] = out
            return 0
        g = self.gains
        cfg = st.config
        S = st.S
        qd = st.qd
        zd = S[8, 0] * qd[0] + S[8, 1] * qd[1] + S[8, 2] * qd[2]
        rd = S[11, 0] * qd[0] + S[11, 1] * qd[1] + S[11, 2] * qd[2]
        pd = S[10, 0] * qd[0] + S[10, 1] * qd[1] + S[10, 2] * qd[2]
        floor = g.preload_n
        f_d, f_dot, f_ddot = ref.f, ref.f_dot, ref.f_ddot
        if not f_d > floor:                     # NaN too: hold the preload
            f_d, f_dot, f_ddot = floor, 0.0, 0.0
        k = self.k_est
        vmax = g.max_feedforward_speed_m_s
        z_dot_ff = max(-vmax, min(vmax, f_dot / k))
        amax = g.max_feedforward_accel_m_s2
        z_ddot_ff = max(-amax, min(amax, f_ddot / k)) if abs(f_dot / k) < vmax else 0.0
        integral = self.integral
        # The same float operations as the kernel (bit for bit).
        sched = ck.gain_schedule.py_func(g.schedule_stiffness_n_per_m, k)
        kp = (1.0 + g.kp) * sched - 1.0 if sched < 1.0 else g.kp
        kp = max(0.0, kp)
        if not math.isnan(force_n):
            e = f_d - force_n
            limit = self.integral_limit_n / g.ki_per_s if g.ki_per_s > 0 else 0.0
            if not ref.transient:
                integral = max(-limit, min(limit, integral + sched * e * dt))
            if g.estimate_stiffness and force_n > ck.CONTACT_LOADED_N:
                # Learn the contact's stiffness only while clearly in contact and moving a
                # little; the estimate stays within 1/5..20× the guess, so a poorly excited
                # stretch cannot turn the motion feedforward into nonsense.
                if not math.isnan(self._last_z) and abs(cfg.z - self._last_z) > 1e-7:
                    self.rls.update(cfg.z, force_n, g.forgetting)
                    guess = g.stiffness_guess_n_per_m
                    self.k_est = min(20.0 * guess, max(0.2 * guess, float(self.rls.theta[0])))
                self._last_z = cfg.z
        else:
            e = 0.0
        ki_a = g.angle_ki_n_m_per_rad_s
        a_lim = g.angle_integral_limit_n_m / ki_a if ki_a > 0 else 0.0
        ai = self._fs[ck.FS_ANGLE_I:ck.FS_ANGLE_I + 2]
        ai[0] = max(-a_lim, min(a_lim, ai[0] + (ref.roll - cfg.roll) * dt))
        ai[1] = max(-a_lim, min(a_lim, ai[1] + (ref.pitch - cfg.pitch) * dt))
        q_roll = (-g.angle_kp_n_m_per_rad * (cfg.roll - ref.roll)
                  - g.angle_kd_n_m_s_per_rad * (rd - ref.roll_rate) + ki_a * ai[0])
        q_pitch = (-g.angle_kp_n_m_per_rad * (cfg.pitch - ref.pitch)
                   - g.angle_kd_n_m_s_per_rad * (pd - ref.pitch_rate) + ki_a * ai[1])
        # Everything but the z task force: τ = G + J_fkᵀ (0, Q_roll, Q_pitch), J_fk = rows
        # (z, roll, pitch) of S, plus the feedforward of the motion the force profile implies
        # (slider space via J_ik).
        grav = self.dyn.gravity(st)
        j_ik = st.inverse_jacobian()
        qd_ff = j_ik[:, 0] * z_dot_ff
        qdd_ff = j_ik[:, 0] * z_ddot_ff
        fric = self.dyn.friction(qd_ff)
        for i in range(3):
            out[i] = (grav[i] + S[11, i] * q_roll + S[10, i] * q_pitch
                      + fric[i] + self.axis_inertia * qdd_ff[i])
        if not math.isnan(force_n):
            ck.error_friction.py_func(self.dyn.coulomb, self.dyn.coulomb_v, j_ik, z_dot_ff,
                                      ref.roll_rate, ref.pitch_rate, e, sched,
                                      g.friction_compensation, g.friction_deadband_n, out)
        held = self.integral

        def task(integ: float) -> float:
            return f_d + kp * e + g.ki_per_s * integ - g.damping_n_s_per_m * (zd - z_dot_ff)

        fz = task(integral)
        fs = self._fs
        if force_n > ck.CONTACT_TOUCH_N:
            fs[ck.FS_TOUCHED] = 1.0
        if fs[ck.FS_TOUCHED] == 0.0 and g.approach_force_margin_n > 0.0:
            # Before the entry's first touch: no faster than the expected contact takes
            # (``rt.control.kernels.approach_speed``: why, and why latched), the gap's error
            # not integrated.
            m_z = 0.0
            for i in range(3):
                m_z += j_ik[i, 0] * j_ik[i, 0]
            v_a = ck.approach_speed.py_func(g.approach_force_margin_n,
                                            float(self._fs[ck.FS_K_APPROACH]),
                                            self.axis_inertia * m_z)
            cap = g.damping_n_s_per_m * (v_a - zd)
            if fz > cap:
                fz = cap
                integral = held
        if fz < floor and not force_n > floor:
            # Never pull: with the foot carrying no more than the preload (or no reading) the
            # command is held at the preload, and the integral only moves up (conditional
            # integration: it does not wind down while the command is held). Above the
            # preload the feedback may command less than it: that moves the platform down
            # against its friction while the foot still pushes on it.
            fz = floor
            integral = max(held, integral)
        elif self._winds_up(out, S, fz, e):
            # A drive at its force limit in the direction the integral pushes: the integral is
            # held (conditional integration). A heel strike asks more than the drives give
            # for a few ms; a wound-up ∫e would then overshoot for tens of ms.
            integral = held
            fz = task(integral)
        self.integral = integral
        for i in range(3):
            out[i] += S[8, i] * fz
        self.tau[:] = out
        return 0


class AdmittanceGains(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_assignment=True)
    virtual_mass_kg: Pos = 20.0
    virtual_damping_n_s_per_m: Pos = 4000.0
    virtual_stiffness_n_per_m: NonNeg = 0.0
    max_speed_m_s: Pos = 0.05
    preload_n: Annotated[float, Field(ge=0.0, le=200.0, allow_inf_nan=False)] = 10.0


class Admittance:
    """Force error → virtual mass-damper(-spring) in z → pose → inner Paden-Panja."""

    name = "admittance"
    gains_type = AdmittanceGains
    gain_ranges = ADMITTANCE_RANGES

    def __init__(self, model: RobotModel, gains: dict | None = None,
                 inner: str = "paden_panja", inner_gains: dict | None = None):
        self.model = model
        self.gains = _validate(self.name, AdmittanceGains, self.gain_ranges, gains)
        self.inner = create(inner, model, inner_gains)
        self._ref = Reference()
        self.reset()

    def set_gains(self, **changes) -> None:
        """Change gains at run time; a value outside its range is refused, nothing changes."""
        self.gains = _validate(self.name, AdmittanceGains, self.gain_ranges,
                               {**self.gains.model_dump(), **changes})

    def reset(self, z0: float | None = None) -> None:
        self.z = z0
        self.zd = 0.0
        self.inner.reset()

    def update(self, st: State, force_n: float, ref: ForceReference, dt: float,
               out: np.ndarray) -> int:
        g = self.gains
        if self.z is None:
            self.z = st.config.z
        f_d = max(g.preload_n, ref.f)    # never below the preload
        e = 0.0 if math.isnan(force_n) else force_n - f_d      # pushing too hard → yield
        zdd = (-e - g.virtual_damping_n_s_per_m * self.zd) / g.virtual_mass_kg
        self.zd = max(-g.max_speed_m_s, min(g.max_speed_m_s, self.zd + zdd * dt))
        self.z += self.zd * dt
        kin = self.model.kin
        cfg = kin.ik(self.z, ref.roll, ref.pitch, check=False)
        ahead = kin.ik(self.z + self.zd * 1e-4, ref.roll + ref.roll_rate * 1e-4,
                       ref.pitch + ref.pitch_rate * 1e-4, check=False)
        r = self._ref
        for i in range(3):
            r.q[i] = cfg.q[i]
            r.qd[i] = (ahead.q[i] - cfg.q[i]) / 1e-4
            r.qdd[i] = 0.0
        return self.inner.update(st, r, dt, out)


for _law in (ExplicitForce, Admittance):
    check_range_table(_law.name, _law.gain_ranges, _law.gains_type)
