"""Isometric holds with an ankle-torque target, regulated by the RT process (issue 17).

A hold with ``torque`` (``schema.Hold``) is played as: the platform moves to the hold's angles
(precomputed, as any isometric hold); the target ramps in (raised cosine, ``ramp_s``), is held
``hold_s`` and ramps out; meanwhile the platform turns the foot about the hold's axis through an
admittance driven by the torque error (``protocols.admittance``, no guide, no spring):

    I θ̈ + B θ̇ = τ - τ*,        |θ| ≤ max_excursion, |θ̇| ≤ ω_max, |θ̈| ≤ α

θ the angle from the hold's angle on the platform axis of the hold's direction (pitch for DF/PF,
roll for INV/EV), τ the measured torque about the patient's ankle centre on that axis (the ATI
wrench moved to the centre, ``rt.model.ankle``, as active assist does) and τ* the target as a
platform torque. The torques are the foot's on the platform: a plantarflexion target τ* > 0 is
reached when the patient pushes the toes down with τ* — the platform pushes back with it. A
patient holding still against the platform contracts isometrically at the target; a passive
foot is turned until its passive stiffness K gives τ* (I θ̈ + B θ̇ + K θ = -τ*: stable for any
K ≥ 0; with the defaults I = 0.2 kg m², B = 20 N m s/rad the twin's K = 45 N m/rad settles
with a 0.45 s time constant and a patient resisting at 2000 N m/rad is damped at ζ = 0.5); a
patient who yields is turned at most ``max_excursion_deg``. This is the admittance scheme of
``rt.control.force.Admittance`` (the force error drives a virtual mass-damper tracked by the
inner position law) applied to the ankle torque: the loop's position law, supervisor and
limits are unchanged.

After the ramp out the rate is braked to rest at α and the angle returns to the hold's angle by
a raised cosine, within ``return_s`` (the schema checks the speed and acceleration this takes
from the largest excursion); the rest and the next move are precomputed again.

``validate()`` computes the precomputed path exactly and bounds the regulated part for any
patient: the hold's angle ± the excursion on its axis at ± the speed and acceleration limits
(angles, slider positions, speeds and accelerations, the ankle centre's displacement).
``update`` costs three ``kinematics.ik`` calls during a regulated hold (as active assist) and a
table row copy otherwise.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from protocols.admittance import step_axis
from protocols.base import DERIVATIVE_STEP_S, check_limits
from protocols.generators import IsometricHoldGenerator
from protocols.output import (
    FZ,
    FZ_DOT,
    GeneratorInput,
    GeneratorStatus,
    ReferenceOutput,
    ValidationReport,
)
from protocols.profiles import AnglePath
from protocols.schema import IsometricHold
from rt.errors import KinematicsError, ProtocolValidationError
from rt.model.ankle import AnkleSetup, sensor_to_ankle_S
from rt.model.kinematics import Kinematics

#: Clinical direction → (platform axis: 0 roll, 1 pitch; sign of the clinical quantity).
_DIRECTIONS = {"plantarflexion": (1, 1.0), "dorsiflexion": (1, -1.0),
               "inversion": (0, 1.0), "eversion": (0, -1.0)}
#: Points per half-excursion at which the regulated part's bounds are evaluated.
_BOUND_POINTS = 3


@dataclass(frozen=True)
class TorqueWindow:
    """One regulated hold, in sample indices of the program (sample k at k·dt from its start).

    ``k_arrive``: the platform is at the hold's angles, target 0; ``k_full``: the target
    reaches full; ``k_release``: the ramp out begins; ``k_zero``: the target is 0 again and the
    return begins; ``k_back``: the foot is back at the hold's angles. ``axis`` 0 = roll,
    1 = pitch; ``platform_target_nm`` the target as a torque about that platform axis (N·m;
    the clinical torque is ``clinical_sign`` × the platform torque for this foot);
    ``roll_rad``, ``pitch_rad`` the hold's platform angles.
    """

    hold: int
    direction: str
    target_nm: float
    axis: int
    clinical_sign: float
    platform_target_nm: float
    roll_rad: float
    pitch_rad: float
    k_arrive: int
    k_full: int
    k_release: int
    k_zero: int
    k_back: int

    def target_at(self, k: int) -> float:
        """The target (platform torque, N·m) at sample ``k`` (raised-cosine ramps)."""
        if k <= self.k_arrive or k >= self.k_zero:
            return 0.0
        if k < self.k_full:
            x = (k - self.k_arrive) / (self.k_full - self.k_arrive)
            return self.platform_target_nm * 0.5 * (1.0 - math.cos(math.pi * x))
        if k <= self.k_release:
            return self.platform_target_nm
        x = (k - self.k_release) / (self.k_zero - self.k_release)
        return self.platform_target_nm * 0.5 * (1.0 + math.cos(math.pi * x))

    def as_dict(self, dt: float) -> dict[str, Any]:
        """JSON-ready, with the full-target stretch in seconds of the program."""
        d = asdict(self)
        d["full_s"] = [self.k_full * dt, self.k_release * dt]
        return d


def torque_sign(direction: str, side: str) -> tuple[int, float]:
    """(platform axis, clinical sign) of a clinical direction for a foot: the clinical torque
    in that direction is sign × the platform torque (``rt.model.ankle.ankle_torques``:
    inversion is +roll for a right foot, -roll for a left one)."""
    axis, sign = _DIRECTIONS[direction]
    if axis == 0 and side == "left":
        sign = -sign
    return axis, sign


class TorqueHoldGenerator(IsometricHoldGenerator):
    """Isometric holds, some with an ankle-torque target regulated online (module docstring).

    ``update(out, inp)`` reads the patient's wrench from ``inp`` (``ProgramInput``; None = a
    passive patient: no torque).
    """

    protocol: IsometricHold

    def __init__(self, protocol: IsometricHold, dt: float, kinematics: Kinematics, source: str,
                 ankle: AnkleSetup | None) -> None:
        if ankle is None:
            k = next(i for i, h in enumerate(protocol.holds) if h.torque is not None)
            raise ProtocolValidationError(
                f"{source}: holds[{k}].torque: an ankle-torque target is about the patient's "
                "ankle centre, and no ankle setup was given: enter it (height above the sole, "
                "offsets, side) or measure it with the camera")
        self.side = ankle.side
        self.windows: list[TorqueWindow] = []
        super().__init__(protocol, dt, kinematics, source, ankle)
        tc = protocol.torque_control
        rad = math.radians
        self._exc = rad(tc.max_excursion_deg)
        self._w_max = rad(tc.max_speed_deg_s)
        self._a_max = rad(tc.max_acceleration_deg_s2)
        self._imk = (tc.virtual_inertia_kg_m2, tc.damping_n_m_s_rad, 0.0)
        self._r_ankle = sensor_to_ankle_S(ankle)
        self._passive = GeneratorInput()
        self.reset()

    # ------------------------------------------------------------------ the path
    def _build_path(self) -> np.ndarray:
        p, rad = self.protocol, math.radians
        r0, p0 = self._neutral()
        v, a, j = (rad(p.transition_speed_deg_s), rad(p.max_acceleration_deg_s2),
                   rad(p.max_jerk_deg_s3))
        tc = p.torque_control
        target_n = math.nan if p.target_force_n is None else p.target_force_n
        path = AnglePath(self.dt, r0, p0)
        self.windows = []
        for i, h in enumerate(p.holds):
            path.move_to(rad(h.roll_deg), rad(h.pitch_deg), v, a, j, p.profile)
            if h.torque is None:
                path.hold(h.hold_s, target_n)
                path.hold(h.rest_s)
                continue
            marks = [path.n_samples - 1]
            for duration in (tc.ramp_s, h.hold_s, tc.ramp_s, tc.return_s):
                path.hold(duration)
                marks.append(path.n_samples - 1)
            path.hold(h.rest_s)
            axis, sign = torque_sign(h.torque.direction, self.side)
            self.windows.append(TorqueWindow(
                hold=i, direction=h.torque.direction, target_nm=h.torque.target_nm, axis=axis,
                clinical_sign=sign, platform_target_nm=sign * h.torque.target_nm,
                roll_rad=rad(h.roll_deg), pitch_rad=rad(h.pitch_deg), k_arrive=marks[0],
                k_full=marks[1], k_release=marks[2], k_zero=marks[3], k_back=marks[4]))
        path.move_to(r0, p0, v, a, j, p.profile)
        return path.samples()

    def _extremes(self) -> list[tuple[float, float, int]]:
        """(roll, pitch, sample) of each regulated hold's angle ± the excursion on its axis."""
        out = []
        for w in self.windows:
            for s in np.linspace(-1.0, 1.0, 2 * _BOUND_POINTS + 1):
                d = float(s) * self._exc_of_protocol()
                out.append((w.roll_rad + (d if w.axis == 0 else 0.0),
                            w.pitch_rad + (d if w.axis == 1 else 0.0), w.k_full))
        return out

    def _exc_of_protocol(self) -> float:
        # Also needed while the base class builds (before __init__ sets self._exc).
        return math.radians(self.protocol.torque_control.max_excursion_deg)

    def _ankle_samples(self, path: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        rolls, pitches, times = super()._ankle_samples(path)
        ext = self._extremes()
        if not ext:
            return rolls, pitches, times
        e = np.array(ext)
        return (np.r_[rolls, e[:, 0]], np.r_[pitches, e[:, 1]], np.r_[times, e[:, 2] * self.dt])

    # ------------------------------------------------------------------ validation
    def validate(self) -> ValidationReport:
        report = super().validate()
        self.reset()
        if not report.ok:
            return report
        # Bounds of the regulated part, for any patient (module docstring).
        kin, hv = self.kinematics, self.ankle.heave
        z_hold = self.protocol.pose.z_m
        h = DERIVATIVE_STEP_S
        hh = 0.5 * h * h
        (r_lo, r_hi), (p_lo, p_hi) = report.roll_range_rad, report.pitch_range_rad
        q_lo, q_hi = report.q_range_m
        qd_peak, qdd_peak = report.peak_slider_speed_m_s, report.peak_slider_accel_m_s2
        for r, pt, k in self._extremes():
            w = next(x for x in self.windows if x.k_full == k)
            r_lo, r_hi = min(r_lo, r), max(r_hi, r)
            p_lo, p_hi = min(p_lo, pt), max(p_hi, pt)
            z = z_hold if hv is None else hv.z_for(r, pt)
            try:
                c = kin.ik(z, r, pt, check=True)
            except KinematicsError as exc:
                report.violations.append(
                    f"holds[{w.hold}].torque: at roll {math.degrees(r):.2f} deg, pitch "
                    f"{math.degrees(pt):.2f} deg (the hold's angle turned by up to "
                    f"torque_control.max_excursion_deg): {exc}")
                break
            q_lo, q_hi = min(q_lo, *c.q), max(q_hi, *c.q)
            for sv in (-1.0, 1.0):
                for sa in (-1.0, 1.0):
                    vr = sv * self._w_max if w.axis == 0 else 0.0
                    vp = sv * self._w_max if w.axis == 1 else 0.0
                    ar = sa * self._a_max if w.axis == 0 else 0.0
                    ap = sa * self._a_max if w.axis == 1 else 0.0
                    rp_, pp_ = r + h * vr + hh * ar, pt + h * vp + hh * ap
                    rm_, pm_ = r - h * vr + hh * ar, pt - h * vp + hh * ap
                    zp_ = z if hv is None else hv.z_for(rp_, pp_)
                    zm_ = z if hv is None else hv.z_for(rm_, pm_)
                    gp_ = kin.ik(zp_, rp_, pp_, check=False).q
                    gm_ = kin.ik(zm_, rm_, pm_, check=False).q
                    for i in range(3):
                        qd_peak = max(qd_peak, abs(gp_[i] - gm_[i]) / (2.0 * h))
                        qdd_peak = max(qdd_peak, abs(gp_[i] - 2.0 * c.q[i] + gm_[i]) / (h * h))
        report.roll_range_rad, report.pitch_range_rad = (r_lo, r_hi), (p_lo, p_hi)
        if any(w.axis == 0 for w in self.windows):
            report.peak_roll_rate_rad_s = max(report.peak_roll_rate_rad_s, self._w_max)
        if any(w.axis == 1 for w in self.windows):
            report.peak_pitch_rate_rad_s = max(report.peak_pitch_rate_rad_s, self._w_max)
        report.q_range_m = (q_lo, q_hi)
        report.peak_slider_speed_m_s = qd_peak
        report.peak_slider_accel_m_s2 = qdd_peak
        report.notes.append(
            "ankle-torque holds: "
            + "; ".join(f"hold {w.hold}: {w.direction} {w.target_nm:g} N m for "
                        f"{(w.k_release - w.k_full) * self.dt:g} s" for w in self.windows)
            + f"; angles, rates and slider bounds include ±{math.degrees(self._exc):g} deg "
            "about each hold's angle for any patient")
        if report.ok:
            check_limits(report, self.protocol)
        self._ready = report.ok
        self.last_report = report
        return report

    @property
    def info(self) -> dict[str, Any]:
        """The regulated holds (JSON-ready: the summary's per-hold figures use them)."""
        return {"torque_holds": [w.as_dict(self.dt) for w in self.windows],
                "dt": self.dt}

    def live_target(self) -> dict[str, Any] | None:
        """The regulated hold being played and its target now (clinical N·m, ramps included),
        for live views (the RT process's telemetry, another thread: reads ``index`` only);
        None outside the regulated holds."""
        k = self.index
        for w in self.windows:
            if w.k_arrive < k <= w.k_zero:
                return {"hold": w.hold, "direction": w.direction, "target_nm": w.target_nm,
                        "now_nm": w.clinical_sign * w.target_at(k)}
        return None

    # ------------------------------------------------------------------ the cycle
    def reset(self) -> None:
        super().reset()
        self._win = 0            # the first window not yet finished
        self._th = self._w = self._a = 0.0
        self._braking = False
        self._cos_from: tuple[int, float] | None = None   # (sample, angle) of the cosine

    def _regulate(self, w: TorqueWindow, k: int, inp: GeneratorInput) -> int:
        """Advance the offset θ of window ``w`` to sample ``k``; a status when it fails."""
        if k <= w.k_zero:
            rx, ry, rz = self._r_ankle
            if w.axis == 0:
                tau = inp.tau_roll_nm - (ry * inp.force_z_n - rz * inp.force_y_n)
            else:
                tau = inp.tau_pitch_nm - (rz * inp.force_x_n - rx * inp.force_z_n)
            if not math.isfinite(tau):
                return GeneratorStatus.ERROR_INPUT
            self._th, self._w, self._a = step_axis(
                self._th, self._w, tau - w.target_at(k), 0.0, 0.0, self._imk, -self._exc,
                self._exc, 0.0, self._a_max, self._w_max, self.dt)
            self._braking = True
            self._cos_from = None
            return GeneratorStatus.RUNNING
        if self._braking and self._w != 0.0:   # brake to rest at α, within the range
            dw = min(abs(self._w), self._a_max * self.dt)
            w_new = self._w - math.copysign(dw, self._w)
            th = min(max(self._th + w_new * self.dt, -self._exc), self._exc)
            self._a = (w_new - self._w) / self.dt
            self._th, self._w = th, w_new
            return GeneratorStatus.RUNNING
        self._braking = False
        if self._cos_from is None:
            self._cos_from = (k - 1, self._th)
        k0, th0 = self._cos_from
        n = w.k_back - k0
        x = (k - k0) / n if n > 0 else 1.0
        if x >= 1.0:
            self._th = self._w = self._a = 0.0
            return GeneratorStatus.RUNNING
        big_t = n * self.dt
        self._th = th0 * 0.5 * (1.0 + math.cos(math.pi * x))
        self._w = -th0 * 0.5 * math.pi / big_t * math.sin(math.pi * x)
        self._a = -th0 * 0.5 * (math.pi / big_t) ** 2 * math.cos(math.pi * x)
        return GeneratorStatus.RUNNING

    def update(self, out: ReferenceOutput, inp: GeneratorInput | None = None) -> int:
        if not self._ready:
            return GeneratorStatus.ERROR_NOT_VALIDATED
        k = self.index
        wins = self.windows
        while self._win < len(wins) and k > wins[self._win].k_back:
            self._win += 1
        w = wins[self._win] if self._win < len(wins) else None
        if w is None or k <= w.k_arrive:
            return super().update(out, inp)
        status = self._regulate(w, k, inp if inp is not None else self._passive)
        if status < 0:
            return status
        # The hold's row (angles, heave, still), turned by θ on the window's axis.
        row = self._table[k]
        th, om, al = self._th, self._w, self._a
        r, pt = float(row[10]), float(row[11])
        vr = vp = ar = ap = 0.0
        if w.axis == 0:
            r, vr, ar = r + th, om, al
        else:
            pt, vp, ap = pt + th, om, al
        h = DERIVATIVE_STEP_S
        hh = 0.5 * h * h
        rp_, pp_ = r + h * vr + hh * ar, pt + h * vp + hh * ap
        rm_, pm_ = r - h * vr + hh * ar, pt - h * vp + hh * ap
        hv = self.ankle.heave
        z = zp_ = zm_ = float(row[9])
        if hv is not None:
            z, zp_, zm_ = hv.z_for(r, pt), hv.z_for(rp_, pp_), hv.z_for(rm_, pm_)
        kin = self.kinematics
        try:
            q = kin.ik(z, r, pt, check=False).q
            gp_ = kin.ik(zp_, rp_, pp_, check=False).q
            gm_ = kin.ik(zm_, rm_, pm_, check=False).q
        except KinematicsError:
            return GeneratorStatus.ERROR_KINEMATICS
        b = out.buf
        b[:] = self._const
        for i in range(3):
            b[i] = q[i]
            b[3 + i] = (gp_[i] - gm_[i]) / (2.0 * h)
            b[6 + i] = (gp_[i] - 2.0 * q[i] + gm_[i]) / (h * h)
        b[9], b[10], b[11] = z, r, pt
        b[12], b[13], b[14] = (zp_ - zm_) / (2.0 * h), vr, vp
        b[FZ] = b[FZ_DOT] = math.nan
        out.mode = self.mode
        out.index = k
        out.done = k >= self.n_samples - 1
        self.index = k + 1
        return GeneratorStatus.FINISHED if out.done else GeneratorStatus.RUNNING


class TorqueHoldFigures:
    """Per regulated hold, from the session tap's play rows: the torque about the ankle centre
    the product reports (the sensor's wrench moved there) over the full-target stretch — its
    mean and RMS error against the target (N·m, clinical sign: the target's direction +) —
    and, when ``truth`` rows are given (the twin's joint torque, foot axes), the RMS error of
    the reported torque against the true one.

    ``windows`` are :meth:`TorqueWindow.as_dict` entries; play row i (0-based, counted from
    the session's first play row) is program sample i + 1 (the sequencer consumes sample 0
    when the approach ends).
    """

    def __init__(self, windows: list[dict[str, Any]], setup: AnkleSetup) -> None:
        self.windows = windows
        self.r = sensor_to_ankle_S(setup)
        self._seen = 0
        n = len(windows)
        self._n = [0] * n
        self._sum = [0.0] * n
        self._se = [0.0] * n
        self._truth_se = [0.0] * n
        self._truth_sum = [0.0] * n
        self._truth_n = [0] * n

    def platform_torques(self, wrench: np.ndarray) -> np.ndarray:
        """(n, 2) torques about the ankle centre on the platform's roll and pitch axes (N·m)
        from (n, 6) sensor wrench rows (``rt.model.ankle.transfer_wrench``, vectorized)."""
        rx, ry, rz = self.r
        fx, fy, fz, mx, my = (wrench[:, i] for i in range(5))
        return np.column_stack((mx - (ry * fz - rz * fy), my - (rz * fx - rx * fz)))

    def add(self, wrench: np.ndarray, truth: np.ndarray | None = None) -> None:
        """The wrench rows of consecutive play samples (and the twin's true joint torques on
        the roll and pitch axes, (n, 2), for the same samples)."""
        if not len(wrench):
            return
        k = self._seen + 1 + np.arange(len(wrench))
        self._seen += len(wrench)
        tau = self.platform_torques(wrench)
        for i, w in enumerate(self.windows):
            sel = (k >= w["k_full"]) & (k <= w["k_release"])
            if not sel.any():
                continue
            sign, axis = w["clinical_sign"], w["axis"]
            reported = sign * tau[sel, axis]
            ok = np.isfinite(reported)
            reported = reported[ok]
            self._n[i] += len(reported)
            self._sum[i] += float(reported.sum())
            self._se[i] += float(((reported - w["target_nm"]) ** 2).sum())
            if truth is not None:
                true = sign * truth[sel, axis][ok]
                good = np.isfinite(true)
                self._truth_n[i] += int(good.sum())
                self._truth_sum[i] += float(true[good].sum())
                self._truth_se[i] += float(((reported[good] - true[good]) ** 2).sum())

    def result(self) -> list[dict[str, Any]]:
        """Per hold: direction, target, samples, reported mean and RMS error against the
        target (N·m); with the truth, its mean and the reported-vs-true RMS error (N·m)."""
        out = []
        for i, w in enumerate(self.windows):
            n = self._n[i]
            entry: dict[str, Any] = {
                "hold": w["hold"], "direction": w["direction"], "target_nm": w["target_nm"],
                "samples": n,
                "reported_mean_nm": self._sum[i] / n if n else None,
                "rms_error_to_target_nm": math.sqrt(self._se[i] / n) if n else None}
            m = self._truth_n[i]
            if m:
                entry["true_mean_nm"] = self._truth_sum[i] / m
                entry["rms_reported_vs_true_nm"] = math.sqrt(self._truth_se[i] / m)
            out.append(entry)
        return out
