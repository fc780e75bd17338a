"""Active-assisted exercise: a reference computed online from the patient's torque.

Unlike the precomputed kinds, ``update`` runs the admittance and three inverse kinematics each
cycle: one compiled call (``rt.model.ik_kernels.ik_three``) on rows allocated at construction,
the same arithmetic as ``kinematics.ik`` (which cost ≈ 20 µs per cycle interpreted and built a
``Configuration`` per call). No object outlives a cycle (tests/test_protocols.py measures it).
"""
from __future__ import annotations

import math

import numpy as np

from protocols.admittance import step_axis, stop_speed
from protocols.base import (
    DERIVATIVE_STEP_S,
    AnkleCentre,
    Generator,
    anatomical_to_platform,
    check_limits,
)
from protocols.output import (
    FZ,
    FZ_DOT,
    GeneratorInput,
    GeneratorStatus,
    Mode,
    ReferenceOutput,
    ValidationReport,
)
from protocols.schema import ActiveAssist
from rt.errors import KinematicsError
from rt.model.ankle import AnkleSetup, sensor_to_ankle_S
from rt.model.ik_kernels import IK_ROW, ik_three
from rt.model.kinematics import Kinematics

#: Largest sqrt(g·K/I)·dt and B·dt/I the semi-implicit Euler step is allowed (stable up to 2;
#: 0.2 keeps the discrete response within a few % of the continuous one).
ASSIST_MAX_STEP_RATIO = 0.2


class ActiveAssistGenerator(Generator):
    """Active-assisted exercise computed online from the patient's torque.

    Per axis (θ the angle from the neutral pose, rad):
    ``I θ̈ + B (θ̇ - g θ̇_guide) + g K (θ - θ_guide) = τ_patient``, integrated by semi-implicit
    Euler at dt, with ``g = assistance_gain`` and the guide θ_guide(t) = env(t)·(c + r sin(2π t/T
    + φ)) spanning the ROM (env: raised-cosine fade over ``ramp_s`` at both ends). With g = 1
    the spring-damper pulls towards the guide's angle *and* rate, so a passive foot follows the
    guide with an error of only I θ̈_guide / K (no damping lag); with g = 0 the platform is a
    mass-damper the patient moves alone. Then limited, in this order: θ̈ within ±α
    (``max_acceleration_deg_s2``); θ̇ within ``max_speed_deg_s``; θ̇ towards a ROM end within
    the speed from which braking at α stops at the end (:meth:`_stop_speed`); θ clamped to the
    ROM as a last resort (round-off only). An unused axis stays at neutral.

    ``update(out, inp)`` reads ``inp.tau_roll_nm``/``tau_pitch_nm`` (N·m; None = a passive
    patient) and costs one compiled call for its three inverse kinematics. ``validate()`` reports
    worst-case bounds valid for any patient input (the ROM, the speed limit, slider speeds and
    accelerations over a 7×7 grid of the ROM at the extreme rates and accelerations), not one
    simulated run.
    """

    protocol: ActiveAssist
    mode = Mode.POSITION

    def __init__(self, protocol: ActiveAssist, dt: float, kinematics: Kinematics, source: str,
                 side: str, ankle: AnkleSetup | None = None) -> None:
        super().__init__(protocol, dt, kinematics, source)
        p, rad = protocol, math.radians
        self.side = side
        self._set_length(round(p.duration_s / dt) + 1)
        self._z = p.pose.z_m
        self._r0, self._p0 = rad(p.pose.roll_deg), rad(p.pose.pitch_deg)
        self.ankle = AnkleCentre(p, kinematics, ankle, (self._z, self._r0, self._p0), source)
        # The ankle kinematics when the heave follows the angles (the ankle centre keeps its
        # height), else None (heave held).
        self._heave = self.ankle.heave
        # The patient's torque is taken about the ankle centre when it is known (the sensor
        # origin otherwise): the sensor's moment less r_SA × f.
        self._r_ankle = (0.0, 0.0, 0.0) if ankle is None else sensor_to_ankle_S(ankle)
        rom = p.rom_deg
        # Platform-frame ROM (relative to neutral) per axis: (lo, hi).
        d_lo, d_hi = -rad(rom.dorsiflexion or 0.0), rad(rom.plantarflexion or 0.0)
        r_a = anatomical_to_platform(0.0, rad(rom.inversion or 0.0), side)[0]
        r_b = anatomical_to_platform(0.0, -rad(rom.eversion or 0.0), side)[0]
        self._pitch_used = "dorsi_plantar" in p.axes
        self._roll_used = "inversion_eversion" in p.axes
        self._p_lo, self._p_hi = (d_lo, d_hi) if self._pitch_used else (0.0, 0.0)
        self._r_lo, self._r_hi = (min(r_a, r_b), max(r_a, r_b)) if self._roll_used \
            else (0.0, 0.0)
        self._w_max = rad(p.max_speed_deg_s)
        self._a_max = rad(p.max_acceleration_deg_s2)
        self._wg = 2.0 * math.pi / p.guide_period_s
        self._phi_r = -0.5 * math.pi if self._pitch_used else 0.0
        self._gain = p.assistance_gain
        self._ramp = p.ramp_s
        adm = p.admittance
        one = (1.0, 0.0, 0.0)
        self._p_imk = ((adm.pitch.virtual_mass_kg_m2, adm.pitch.damping_n_m_s_rad,
                        adm.pitch.stiffness_n_m_rad) if adm.pitch is not None else one)
        self._r_imk = ((adm.roll.virtual_mass_kg_m2, adm.roll.damping_n_m_s_rad,
                        adm.roll.stiffness_n_m_rad) if adm.roll is not None else one)
        self._passive = GeneratorInput()
        # ``update``'s IK inputs and rows (``rt.model.ik_kernels.ik_three``), allocated once.
        self._ik_z, self._ik_roll, self._ik_pitch = np.zeros(3), np.zeros(3), np.zeros(3)
        self._ik_rows = np.zeros((3, IK_ROW))
        self._warm_up()
        self.reset()

    def _warm_up(self) -> None:
        """Compile (or load from numba's cache) ``update``'s kernel now, never inside a cycle:
        at construction and where the generator is unpickled (the RT process receives it from
        the pre-flight worker)."""
        self._ik_z[:], self._ik_roll[:], self._ik_pitch[:] = self._z, self._r0, self._p0
        ik_three(self.kinematics.geom, self._ik_z, self._ik_roll, self._ik_pitch,
                 self._ik_rows)

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._warm_up()

    def reset(self) -> None:
        super().reset()
        self._th_r = self._th_p = 0.0
        self._w_r = self._w_p = 0.0
        self._a_r = self._a_p = 0.0

    def guide(self, t: float) -> tuple[float, float, float, float]:
        """Guide (roll, pitch) from neutral (rad) and their rates (rad/s) at time t (s)."""
        T, ramp = self.duration_s, self._ramp
        env, env_d = 1.0, 0.0
        if ramp > 0.0:
            x_in = min(max(t / ramp, 0.0), 1.0)
            x_out = min(max((T - t) / ramp, 0.0), 1.0)
            e_in = 0.5 * (1.0 - math.cos(math.pi * x_in))
            e_out = 0.5 * (1.0 - math.cos(math.pi * x_out))
            d_in = 0.5 * math.pi / ramp * math.sin(math.pi * x_in) if 0.0 < x_in < 1.0 else 0.0
            d_out = -0.5 * math.pi / ramp * math.sin(math.pi * x_out) \
                if 0.0 < x_out < 1.0 else 0.0
            env, env_d = e_in * e_out, d_in * e_out + e_in * d_out
        wg = self._wg
        gr = gp = gr_d = gp_d = 0.0
        if self._pitch_used:
            c, r = 0.5 * (self._p_hi + self._p_lo), 0.5 * (self._p_hi - self._p_lo)
            sn, cs = math.sin(wg * t), math.cos(wg * t)
            gp, gp_d = env * (c + r * sn), env_d * (c + r * sn) + env * r * wg * cs
        if self._roll_used:
            c, r = 0.5 * (self._r_hi + self._r_lo), 0.5 * (self._r_hi - self._r_lo)
            sn, cs = math.sin(wg * t + self._phi_r), math.cos(wg * t + self._phi_r)
            gr, gr_d = env * (c + r * sn), env_d * (c + r * sn) + env * r * wg * cs
        return gr, gp, gr_d, gp_d

    def _stop_speed(self, distance: float) -> float:
        """``protocols.admittance.stop_speed`` with this exercise's α and dt."""
        return stop_speed(distance, self._a_max, self.dt)

    def _step_axis(self, th: float, w: float, tau: float, guide: float, guide_rate: float,
                   imk: tuple[float, float, float], lo: float, hi: float
                   ) -> tuple[float, float, float]:
        return step_axis(th, w, tau, guide, guide_rate, imk, lo, hi, self._gain, self._a_max,
                         self._w_max, self.dt)

    def validate(self) -> ValidationReport:
        self._ready = False
        report = self._new_report()
        p, kin, z = self.protocol, self.kinematics, self._z
        for axis, used, imk in (("pitch", self._pitch_used, self._p_imk),
                                ("roll", self._roll_used, self._r_imk)):
            if not used:
                continue
            inertia, damping, stiffness = imk
            ratios = (math.sqrt(self._gain * stiffness / inertia) * self.dt,
                      damping * self.dt / inertia)
            if max(ratios) > ASSIST_MAX_STEP_RATIO:
                report.violations.append(
                    f"admittance.{axis}: sqrt(g·K/I)·dt = {ratios[0]:.3f}, B·dt/I = "
                    f"{ratios[1]:.3f} exceed {ASSIST_MAX_STEP_RATIO} at dt = {self.dt * 1e3:g} "
                    "ms: raise virtual_mass_kg_m2 or lower stiffness/damping")
        # Worst-case bounds over the ROM box: the kinematics at a 7x7 grid, every combination of
        # extreme rates and accelerations, slider derivatives along the local quadratic path.
        rolls = self._r0 + np.linspace(self._r_lo, self._r_hi, 7)
        pitches = self._p0 + np.linspace(self._p_lo, self._p_hi, 7)
        wr = self._w_max if self._roll_used else 0.0
        wp = self._w_max if self._pitch_used else 0.0
        ar = self._a_max if self._roll_used else 0.0
        ap = self._a_max if self._pitch_used else 0.0
        combos = [(sr * wr, sp * wp, tr * ar, tp * ap) for sr in (-1, 1) for sp in (-1, 1)
                  for tr in (-1, 1) for tp in (-1, 1)]
        h = DERIVATIVE_STEP_S
        hh = 0.5 * h * h
        q_lo, q_hi, qd_peak, qdd_peak = math.inf, -math.inf, 0.0, 0.0
        hv = self._heave
        for r, pt in ((float(r), float(pt)) for r in rolls for pt in pitches):
            if hv is not None:
                z = hv.z_for(r, pt)
            try:
                c = kin.ik(z, r, pt, check=True)
            except KinematicsError as exc:
                report.violations.append(f"rom_deg: the ROM point roll {math.degrees(r):.2f} "
                                         f"deg, pitch {math.degrees(pt):.2f} deg: {exc}")
                break
            q_lo, q_hi = min(q_lo, *c.q), max(q_hi, *c.q)
            for vr, vp, a_r, a_p in combos:
                rp_, pp_ = r + h * vr + hh * a_r, pt + h * vp + hh * a_p
                rm_, pm_ = r - h * vr + hh * a_r, pt - h * vp + hh * a_p
                zp_ = z if hv is None else hv.z_for(rp_, pp_)
                zm_ = z if hv is None else hv.z_for(rm_, pm_)
                gp_ = kin.ik(zp_, rp_, pp_, check=False).q
                gm_ = kin.ik(zm_, rm_, pm_, check=False).q
                for i in range(3):
                    qd_peak = max(qd_peak, abs(gp_[i] - gm_[i]) / (2.0 * h))
                    qdd_peak = max(qdd_peak, abs(gp_[i] - 2.0 * c.q[i] + gm_[i]) / (h * h))
        report.roll_range_rad = (self._r0 + self._r_lo, self._r0 + self._r_hi)
        report.pitch_range_rad = (self._p0 + self._p_lo, self._p0 + self._p_hi)
        report.peak_roll_rate_rad_s = wr
        report.peak_pitch_rate_rad_s = wp
        report.q_range_m = (q_lo, q_hi)
        report.peak_slider_speed_m_s = qd_peak
        report.peak_slider_accel_m_s2 = qdd_peak
        report.notes.append("active assist: angles, rates and slider speeds/accelerations are "
                            "worst-case bounds for any patient torque")
        grid_r, grid_p = np.meshgrid(rolls, pitches)
        self.ankle.check(report, grid_r.ravel(), grid_p.ravel(), None)
        check_limits(report, p)
        self.last_report = report
        self._ready = report.ok
        self.reset()
        return report

    def update(self, out: ReferenceOutput, inp: GeneratorInput | None = None) -> int:
        if not self._ready:
            return GeneratorStatus.ERROR_NOT_VALIDATED
        k = self.index
        if k >= self.n_samples:
            out.done = True
            return GeneratorStatus.FINISHED  # the last sample is already in ``out``
        src = inp if inp is not None else self._passive
        tau_r, tau_p = src.tau_roll_nm, src.tau_pitch_nm
        rx, ry, rz = self._r_ankle
        if rx != 0.0 or ry != 0.0 or rz != 0.0:
            fx, fy, fz = src.force_x_n, src.force_y_n, src.force_z_n
            tau_r -= ry * fz - rz * fy
            tau_p -= rz * fx - rx * fz
        if not (math.isfinite(tau_r) and math.isfinite(tau_p)):
            return GeneratorStatus.ERROR_INPUT
        if k > 0:  # sample 0 is the neutral pose at rest
            gr, gp, gr_d, gp_d = self.guide(k * self.dt)
            if self._pitch_used:
                self._th_p, self._w_p, self._a_p = self._step_axis(
                    self._th_p, self._w_p, tau_p, gp, gp_d, self._p_imk, self._p_lo, self._p_hi)
            if self._roll_used:
                self._th_r, self._w_r, self._a_r = self._step_axis(
                    self._th_r, self._w_r, tau_r, gr, gr_d, self._r_imk, self._r_lo, self._r_hi)
        z, r, pt = self._z, self._r0 + self._th_r, self._p0 + self._th_p
        vr, vp, ar, ap = self._w_r, self._w_p, self._a_r, self._a_p
        h = DERIVATIVE_STEP_S
        hh = 0.5 * h * h
        kin = self.kinematics
        rp_, pp_ = r + h * vr + hh * ar, pt + h * vp + hh * ap
        rm_, pm_ = r - h * vr + hh * ar, pt - h * vp + hh * ap
        zp_ = zm_ = z
        hv = self._heave
        if hv is not None:
            z, zp_, zm_ = hv.z_for(r, pt), hv.z_for(rp_, pp_), hv.z_for(rm_, pm_)
        # The three IK (sample, and the two difference points) in one compiled call on
        # preallocated rows: the interpreted ``kin.ik`` cost ≈ 20 µs per cycle.
        zz, rr, pp, rows = self._ik_z, self._ik_roll, self._ik_pitch, self._ik_rows
        zz[0], zz[1], zz[2] = z, zp_, zm_
        rr[0], rr[1], rr[2] = r, rp_, rm_
        pp[0], pp[1], pp[2] = pt, pp_, pm_
        if ik_three(kin.geom, zz, rr, pp, rows) >= 0:
            return GeneratorStatus.ERROR_KINEMATICS
        b = out.buf
        for i in range(3):
            qi, gp_i, gm_i = rows[0, i], rows[1, i], rows[2, i]
            b[i] = qi
            b[3 + i] = (gp_i - gm_i) / (2.0 * h)
            b[6 + i] = (gp_i - 2.0 * qi + gm_i) / (h * h)
        b[9], b[10], b[11] = z, r, pt
        b[12], b[13], b[14] = (zp_ - zm_) / (2.0 * h), vr, vp
        b[FZ] = b[FZ_DOT] = math.nan
        b[17] = b[18] = 0.0
        out.mode = self.mode
        out.index = k
        self.index = k + 1
        if k >= self.n_samples - 1:
            out.done = True
            return GeneratorStatus.FINISHED
        out.done = False
        return GeneratorStatus.RUNNING
