"""Protocol generators: stream one protocol's references into the 1 kHz loop.

Per-cycle API (CONVENTIONS 6, like ruckig): build with :func:`make_generator` (reads the files
the protocol names; malformed inputs raise :class:`~rt.errors.ProtocolValidationError`), call
``validate()`` once before the run (computes the whole reference, returns a
:class:`~protocols.output.ValidationReport`), then ``update(out)`` once per cycle into a
preallocated :class:`~protocols.output.ReferenceOutput`; it returns a
:class:`~protocols.output.GeneratorStatus` and never raises or allocates arrays. ``reset()``
rewinds to the first sample.

How each kind is produced (``dt`` = loop period):

* sine_fz — force mode. F(t) = w(t)·(mean + A sin(2π f (t - ramp_in))), w the product of a
  raised-cosine ramp in and one out, so F and dF/dt are 0 at both ends and dF/dt is continuous.
  The ramp out is stretched by < dt so the last sample lands on the grid.
* gait_replay — force mode. The selected stance is resampled at the loop rate by a
  shape-preserving cubic (scipy ``PchipInterpolator``: no overshoot, so no force above the
  record's peak sample or below 0; C¹) or linearly; played ``time_scale`` times slower; scaled
  by ``percent_body_weight/100 × patient_weight_kg / source_body_weight_kg``; tapered to 0 N
  over ``ramp_s`` at both ends of every stance; ``repetitions`` stances separated by
  ``rest_between_s`` at 0 N.
* ankle_rom, isometric_hold — position mode. An angular path (``protocols.profiles``) of
  rest-to-rest jerk-limited or raised-cosine moves and holds, converted to slider references.
* position_playback — position mode. The CSV is read, checked and resampled by
  ``rt.references.playback.TrajectoryPlayback``; the platform pose comes from forward
  kinematics of every sample (pose rates by central differences).
* active_assist — position mode, computed online from the patient's torque
  (:class:`ActiveAssistGenerator`).

Slider references from a pose path: q = ``kinematics.ik(z, roll, pitch)`` at every sample, and
the exact derivatives of q along the local quadratic path g(h) = ik(p + h ṗ + h²/2 p̈):
q̇ = (g(H) - g(-H))/2H, q̈ = (g(H) - 2 g(0) + g(-H))/H², H = 1 ms (truncation ~1e-10 m/s,
round-off ~1e-10 m/s²). Holds reuse the previous sample's solution.

Precomputed references (every kind but active assist) are stored as one table: 136 B per sample
in position mode, 32 B in force mode; ``MAX_PRECOMPUTED_S`` bounds it.

Foot mounting (:data:`FOOT_MOUNTING`): the foot lies along the platform's +x axis (toes towards
+x), the ankle axis along y. Plantarflexion (toes down) is positive pitch (R_y(β) takes +x
down); inversion (medial border up) is positive roll for a right foot (medial side +y) and
negative roll for a left foot.
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod
from pathlib import Path

import numpy as np
from scipy.interpolate import PchipInterpolator

from protocols import gait
from protocols.output import (FORCE_BLOCK, FZ, FZ_DOT, N_FIELDS, POSE, POSE_DOT, POSITION_BLOCK,
                              Q, QD, QDD, SHEAR, GeneratorInput, GeneratorStatus, Mode,
                              ReferenceOutput, ValidationReport)
from protocols.profiles import PITCH, PITCH_D, ROLL, ROLL_D, TARGET, AnglePath, cosine_ramp
from protocols.schema import (ActiveAssist, AnkleRom, GaitReplay, IsometricHold,
                              PositionPlayback, ProtocolModel, SineFz)
from rt.errors import (ConfigurationError, ConvergenceError, KinematicsError,
                       ProtocolValidationError, WorkspaceError)
from rt.model.kinematics import Kinematics
from rt.references.playback import TrajectoryPlayback

FOOT_MOUNTING = "foot along +x (toes +x); plantarflexion = +pitch; inversion = +roll (right foot)"
#: Longest precomputed protocol (s): 20 min is 163 MB of position table at 1 kHz.
MAX_PRECOMPUTED_S = 1200.0
#: Step along the local path for the slider-velocity/acceleration differences (s).
DERIVATIVE_STEP_S = 1.0e-3
#: Active assist: largest sqrt(K/I)·dt and B·dt/I the semi-implicit Euler step is allowed
#: (stable up to 2; 0.2 keeps the discrete response within a few % of the continuous one).
ASSIST_MAX_STEP_RATIO = 0.2
_SLACK_RAD = 1e-9
_BLOCK_POSITION, _BLOCK_FORCE = 0, 1


def anatomical_to_platform(plantar_rad: float, inversion_rad: float, side: str
                           ) -> tuple[float, float]:
    """(roll, pitch) offsets (rad) for a plantarflexion and an inversion angle (rad; negative
    values are dorsiflexion and eversion), for the ``side`` foot (:data:`FOOT_MOUNTING`)."""
    sign = 1.0 if side == "right" else -1.0
    return sign * inversion_rad, plantar_rad


# ------------------------------------------------------------------------------ helpers
def _joint_references(kin: Kinematics, z: float, path: np.ndarray, dt: float,
                      q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> str | None:
    """Fill q, q̇, q̈ (n, 3) from an angle path (n, 7); returns the first workspace problem."""
    h = DERIVATIVE_STEP_S
    hh = 0.5 * h * h
    for k in range(path.shape[0]):
        r, p, vr, vp, ar, ap = (float(x) for x in path[k, :6])
        still = vr == 0.0 and vp == 0.0 and ar == 0.0 and ap == 0.0
        if still and k > 0 and r == path[k - 1, ROLL] and p == path[k - 1, PITCH]:
            q[k] = q[k - 1]
            qd[k] = qdd[k] = 0.0
            continue
        try:
            c = kin.ik(z, r, p, check=True)
        except KinematicsError as exc:
            return f"t = {k * dt:.3f} s (roll {math.degrees(r):.2f} deg, pitch " \
                   f"{math.degrees(p):.2f} deg): {exc}"
        q[k] = c.q
        if still:
            qd[k] = qdd[k] = 0.0
            continue
        gp = kin.ik(z, r + h * vr + hh * ar, p + h * vp + hh * ap, check=False).q
        gm = kin.ik(z, r - h * vr + hh * ar, p - h * vp + hh * ap, check=False).q
        for i in range(3):
            qd[k, i] = (gp[i] - gm[i]) / (2.0 * h)
            qdd[k, i] = (gp[i] - 2.0 * c.q[i] + gm[i]) / (h * h)
    return None


def _nan_extrema(x: np.ndarray) -> tuple[float, float]:
    if x.size == 0 or np.all(np.isnan(x)):
        return math.nan, math.nan
    return float(np.nanmin(x)), float(np.nanmax(x))


def _fill_motion(report: ValidationReport, table: np.ndarray) -> None:
    """Peaks of a position table (columns as ReferenceOutput.buf)."""
    pose, pose_dot = table[:, POSE], table[:, POSE_DOT]
    report.roll_range_rad = _nan_extrema(pose[:, 1])
    report.pitch_range_rad = _nan_extrema(pose[:, 2])
    report.peak_roll_rate_rad_s = float(np.max(np.abs(pose_dot[:, 1])))
    report.peak_pitch_rate_rad_s = float(np.max(np.abs(pose_dot[:, 2])))
    report.q_range_m = (float(table[:, Q].min()), float(table[:, Q].max()))
    report.peak_slider_speed_m_s = float(np.max(np.abs(table[:, QD])))
    report.peak_slider_accel_m_s2 = float(np.max(np.abs(table[:, QDD])))


def _fill_force(report: ValidationReport, fz: np.ndarray, fz_dot: np.ndarray) -> None:
    report.min_fz_n, report.peak_fz_n = _nan_extrema(fz)
    rate = np.abs(fz_dot)
    report.peak_fz_rate_n_s = math.nan if np.all(np.isnan(rate)) else float(np.nanmax(rate))


def _check_limits(report: ValidationReport, protocol: ProtocolModel) -> None:
    """Append violations of the protocol's own ``limits`` block to the report."""
    lim = protocol.limits
    if lim is None:
        return
    deg, rad = math.degrees, math.radians
    for axis, (lo, hi), rate in (("roll", report.roll_range_rad, report.peak_roll_rate_rad_s),
                                 ("pitch", report.pitch_range_rad, report.peak_pitch_rate_rad_s)):
        lim_lo, lim_hi = getattr(lim, f"{axis}_min_deg"), getattr(lim, f"{axis}_max_deg")
        if lim_lo is not None and lo < rad(lim_lo) - _SLACK_RAD:
            report.violations.append(f"limits.{axis}_min_deg: the reference reaches {axis} "
                                     f"{deg(lo):.2f} deg, below the protocol's {lim_lo} deg")
        if lim_hi is not None and hi > rad(lim_hi) + _SLACK_RAD:
            report.violations.append(f"limits.{axis}_max_deg: the reference reaches {axis} "
                                     f"{deg(hi):.2f} deg, above the protocol's {lim_hi} deg")
        if lim.max_angular_speed_deg_s is not None and \
                rate > rad(lim.max_angular_speed_deg_s) + _SLACK_RAD:
            report.violations.append(f"limits.max_angular_speed_deg_s: the {axis} rate reaches "
                                     f"{deg(rate):.2f} deg/s, above the protocol's "
                                     f"{lim.max_angular_speed_deg_s} deg/s")
    if lim.max_force_n is not None and report.peak_fz_n > lim.max_force_n:
        report.violations.append(f"limits.max_force_n: the force reaches "
                                 f"{report.peak_fz_n:.1f} N, above the protocol's "
                                 f"{lim.max_force_n} N")


# ------------------------------------------------------------------------------ base
class Generator(ABC):
    """One protocol's reference stream (module docstring for the API).

    Attributes:
        protocol: the validated protocol model.
        dt: loop period (s).
        mode: :class:`Mode` of every sample.
        duration_s: time from the first to the last sample (s).
        n_samples: samples emitted, the first at t = 0 and the last at ``duration_s``.
        index: the sample the next ``update`` writes.
    """

    mode: Mode

    def __init__(self, protocol: ProtocolModel, dt: float, kinematics: Kinematics,
                 source: str) -> None:
        self.protocol = protocol
        self.dt = dt
        self.kinematics = kinematics
        self.source = source
        self.index = 0
        self.n_samples = 1
        self.duration_s = 0.0
        self._ready = False
        self.last_report: ValidationReport | None = None

    def _set_length(self, n_samples: int) -> None:
        self.n_samples = n_samples
        self.duration_s = (n_samples - 1) * self.dt

    def _new_report(self) -> ValidationReport:
        return ValidationReport(name=self.protocol.name, kind=self.protocol.kind,
                                source=self.source, mode=self.mode, dt=self.dt,
                                duration_s=self.duration_s, n_samples=self.n_samples)

    def _refuse(self, field: str, reason: str) -> ProtocolValidationError:
        return ProtocolValidationError(f"{self.source}: {field}: {reason}")

    @abstractmethod
    def validate(self) -> ValidationReport:
        """Compute the reference and predict its peaks; ``update`` runs only if it is ok."""

    def reset(self) -> None:
        """Rewind: the next ``update`` writes sample 0."""
        self.index = 0

    @abstractmethod
    def update(self, out: ReferenceOutput, inp: GeneratorInput | None = None) -> int:
        """Write the next sample into ``out``; returns a :class:`GeneratorStatus`."""

    @staticmethod
    def new_output() -> ReferenceOutput:
        """A fresh output struct (allocate once, before the run)."""
        return ReferenceOutput()


class _TableGenerator(Generator):
    """A generator whose whole reference is computed by ``validate`` into one table."""

    _block_id: int

    def __init__(self, protocol: ProtocolModel, dt: float, kinematics: Kinematics,
                 source: str) -> None:
        super().__init__(protocol, dt, kinematics, source)
        self._const = np.zeros(N_FIELDS)  # columns outside the table's block
        self._table = np.zeros((0, 0))

    @abstractmethod
    def _build(self, report: ValidationReport) -> np.ndarray | None:
        """Return the table (None after appending a violation that prevents building it)."""

    def validate(self) -> ValidationReport:
        self._ready = False
        report = self._new_report()
        if self.duration_s > MAX_PRECOMPUTED_S:
            report.violations.append(f"the protocol lasts {self.duration_s:.0f} s, longer than "
                                     f"the {MAX_PRECOMPUTED_S:.0f} s a precomputed protocol may; "
                                     "split it into several protocols")
        else:
            table = self._build(report)
            if table is not None:
                self._table = table
                if self._block_id == _BLOCK_POSITION:
                    _fill_motion(report, table)
                    _fill_force(report, table[:, FZ], table[:, FZ_DOT])
                else:
                    pose = self._const[POSE]
                    report.roll_range_rad = (float(pose[1]), float(pose[1]))
                    report.pitch_range_rad = (float(pose[2]), float(pose[2]))
                    report.peak_roll_rate_rad_s = report.peak_pitch_rate_rad_s = 0.0
                    q = self._const[Q]
                    report.q_range_m = (float(q.min()), float(q.max()))
                    report.peak_slider_speed_m_s = report.peak_slider_accel_m_s2 = 0.0
                    _fill_force(report, table[:, 0], table[:, 1])
                    if report.min_fz_n < -1e-9:
                        report.violations.append(
                            f"the force reference reaches {report.min_fz_n:.2f} N: below 0 N "
                            "it would pull on a contact that can only push")
                _check_limits(report, self.protocol)
        self.last_report = report
        self._ready = report.ok
        self.index = 0
        return report

    def update(self, out: ReferenceOutput, inp: GeneratorInput | None = None) -> int:
        if not self._ready:
            return GeneratorStatus.ERROR_NOT_VALIDATED
        k = self.index
        out.buf[:] = self._const
        out.blocks[self._block_id][:] = self._table[k]
        out.mode = self.mode
        out.index = k
        if k >= self.n_samples - 1:
            out.done = True
            return GeneratorStatus.FINISHED
        out.done = False
        self.index = k + 1
        return GeneratorStatus.RUNNING

    def samples(self) -> dict[str, np.ndarray]:
        """The whole validated reference as arrays (copies), for plots, reports and tests.

        Keys: ``t`` (s), ``q``, ``qd``, ``qdd`` (n, 3), ``pose``, ``pose_dot`` (n, 3),
        ``fz``, ``fz_dot`` (n,), ``shear`` (n, 2).
        """
        if not self._ready:
            raise ProtocolValidationError(f"{self.source}: validate() first (or it reported "
                                          "violations)")
        full = np.tile(self._const, (self.n_samples, 1))
        block = POSITION_BLOCK if self._block_id == _BLOCK_POSITION else FORCE_BLOCK
        full[:, block] = self._table
        return {"t": np.arange(self.n_samples) * self.dt, "q": full[:, Q], "qd": full[:, QD],
                "qdd": full[:, QDD], "pose": full[:, POSE], "pose_dot": full[:, POSE_DOT],
                "fz": full[:, FZ], "fz_dot": full[:, FZ_DOT], "shear": full[:, SHEAR]}


class _ForceGenerator(_TableGenerator):
    """Force in Z with the pose held: table columns fz, fz_dot, fx, fy."""

    mode = Mode.FORCE
    _block_id = _BLOCK_FORCE

    def _hold_pose(self, report: ValidationReport) -> bool:
        pose = self.protocol.pose  # type: ignore[union-attr]
        roll, pitch = math.radians(pose.roll_deg), math.radians(pose.pitch_deg)
        try:
            c = self.kinematics.ik(pose.z_m, roll, pitch, check=True)
        except KinematicsError as exc:
            report.violations.append(f"pose: {exc}")
            return False
        self._const[:] = 0.0
        self._const[Q] = c.q
        self._const[POSE] = (pose.z_m, roll, pitch)
        return True


class _PositionGenerator(_TableGenerator):
    """Slider references from an angle path at constant heave."""

    mode = Mode.POSITION
    _block_id = _BLOCK_POSITION

    def __init__(self, protocol: ProtocolModel, dt: float, kinematics: Kinematics,
                 source: str) -> None:
        super().__init__(protocol, dt, kinematics, source)
        self._path = self._build_path()
        self._set_length(self._path.shape[0])

    @abstractmethod
    def _build_path(self) -> np.ndarray:
        """The (n, 7) angle path (``protocols.profiles`` columns)."""

    def _build(self, report: ValidationReport) -> np.ndarray | None:
        z = self.protocol.pose.z_m  # type: ignore[union-attr]
        path = self._path
        n = path.shape[0]
        table = np.zeros((n, POSITION_BLOCK.stop))
        problem = _joint_references(self.kinematics, z, path, self.dt, table[:, Q],
                                    table[:, QD], table[:, QDD])
        if problem is not None:
            report.violations.append(problem)
            return None
        table[:, 9] = z
        table[:, 10], table[:, 11] = path[:, ROLL], path[:, PITCH]
        table[:, 13], table[:, 14] = path[:, ROLL_D], path[:, PITCH_D]
        table[:, FZ] = path[:, TARGET]
        table[:, FZ_DOT] = np.where(np.isnan(path[:, TARGET]), math.nan, 0.0)
        self._const[:] = 0.0
        return table

    def _neutral(self) -> tuple[float, float]:
        pose = self.protocol.pose  # type: ignore[union-attr]
        return math.radians(pose.roll_deg), math.radians(pose.pitch_deg)


# ------------------------------------------------------------------------------ kinds
class SineFzGenerator(_ForceGenerator):
    """Sinusoidal force in Z with raised-cosine ramps (module docstring)."""

    protocol: SineFz

    def __init__(self, protocol: SineFz, dt: float, kinematics: Kinematics, source: str) -> None:
        super().__init__(protocol, dt, kinematics, source)
        p = protocol
        self._t_out = p.ramp_in_s + p.cycles / p.frequency_hz
        n_periods = int(math.ceil((self._t_out + p.ramp_out_s) / dt - 1e-9))
        self._ramp_out = n_periods * dt - self._t_out  # ≥ ramp_out_s, < ramp_out_s + dt
        self._set_length(n_periods + 1)

    def _build(self, report: ValidationReport) -> np.ndarray | None:
        if not self._hold_pose(report):
            return None
        p = self.protocol
        t = np.arange(self.n_samples) * self.dt
        w_in, wd_in = cosine_ramp(t, p.ramp_in_s)
        w_up, wd_up = cosine_ramp(t - self._t_out, self._ramp_out)
        w, wd = w_in * (1.0 - w_up), wd_in * (1.0 - w_up) - w_in * wd_up
        omega = 2.0 * math.pi * p.frequency_hz
        phase = omega * (t - p.ramp_in_s)
        s = p.mean_n + p.amplitude_n * np.sin(phase)
        sd = p.amplitude_n * omega * np.cos(phase)
        table = np.zeros((self.n_samples, 4))
        table[:, 0] = w * s
        table[:, 1] = wd * s + w * sd
        table[-1, :2] = 0.0  # exactly: w = (1 + cos π)/2 leaves ~1e-17
        return table


class GaitReplayGenerator(_ForceGenerator):
    """Ground-reaction-force replay (module docstring)."""

    protocol: GaitReplay

    def __init__(self, protocol: GaitReplay, dt: float, kinematics: Kinematics, source: str,
                 patient_weight_kg: float | None, base_dir: Path) -> None:
        super().__init__(protocol, dt, kinematics, source)
        p = protocol
        if patient_weight_kg is None or not (math.isfinite(patient_weight_kg)
                                             and 0.0 < patient_weight_kg <= 400.0):
            raise self._refuse("percent_body_weight", "gait replay needs the patient's weight "
                               f"in (0, 400] kg at run time (got {patient_weight_kg!r})")
        self.patient_weight_kg = float(patient_weight_kg)
        self.scale = p.percent_body_weight / 100.0 * self.patient_weight_kg \
            / p.source_body_weight_kg
        st = p.stance
        try:
            record = gait.read_grf(base_dir / p.source, p.plate_index)
            if st.select == "auto":
                stance = gait.select_stance(record, threshold_n=st.threshold_n,
                                            occurrence=st.occurrence)
            else:
                stance = gait.select_stance(record, start_s=st.start_s, end_s=st.end_s)
        except ProtocolValidationError as exc:
            raise self._refuse("source", str(exc)) from None
        if p.include_shear and not stance.has_shear:
            raise self._refuse("include_shear", f"the record {record.source} has no fx, fy "
                               "(a CSV needs the header t,fz,fx,fy)")
        self.stance = stance
        played = stance.duration_s * p.time_scale
        if 2.0 * p.ramp_s >= played:
            raise self._refuse("ramp_s", f"ramps of {p.ramp_s:g} s at both ends do not fit in "
                               f"the {played:.3f} s stance (time_scale {p.time_scale:g})")
        # Samples of one stance (the last at or before its end) and of one rest.
        self._n_stance = int(math.floor(played / dt + 1e-9)) + 1
        self._n_rest = int(round(p.rest_between_s / dt))
        self._period = self._n_stance - 1 + self._n_rest
        self._set_length((p.repetitions - 1) * self._period + self._n_stance)

    def repetition_starts(self) -> np.ndarray:
        """Sample index where each stance starts (its force is 0 there)."""
        return np.arange(self.protocol.repetitions) * self._period

    def _stance_block(self) -> np.ndarray:
        p, st, dt = self.protocol, self.stance, self.dt
        n = self._n_stance
        tp = np.arange(n) * dt  # played time
        tau = np.minimum(tp / p.time_scale, st.t[-1])  # record time
        w_in, wd_in = cosine_ramp(tp, p.ramp_s)
        w_out, wd_out = cosine_ramp(tp[-1] - tp, p.ramp_s)
        w, wd = w_in * w_out, wd_in * w_out - w_in * wd_out
        block = np.zeros((n, 4))
        channels: list[tuple[int, np.ndarray]] = [(0, st.fz)]
        if p.include_shear and st.fx is not None and st.fy is not None:
            channels += [(2, st.fx), (3, st.fy)]
        for col, y in channels:
            if p.interpolation == "cubic":
                f = PchipInterpolator(st.t, y)
                val, der = f(tau), f.derivative()(tau)
            else:
                val = np.interp(tau, st.t, y)
                seg = np.clip(np.searchsorted(st.t, tau, side="right") - 1, 0, st.t.size - 2)
                der = np.diff(y)[seg] / np.diff(st.t)[seg]
            block[:, col] = self.scale * w * val
            if col == 0:
                block[:, 1] = self.scale * (wd * val + w * der / p.time_scale)
        block[0, :] = 0.0
        block[-1, :] = 0.0
        return block

    def _build(self, report: ValidationReport) -> np.ndarray | None:
        if not self._hold_pose(report):
            return None
        block = self._stance_block()
        table = np.zeros((self.n_samples, 4))
        for s0 in self.repetition_starts():
            table[s0:s0 + self._n_stance] = block
        report.notes.append(f"scale {self.scale:.4f} = {self.protocol.percent_body_weight:g} % "
                            f"x {self.patient_weight_kg:g} kg / "
                            f"{self.protocol.source_body_weight_kg:g} kg; stance "
                            f"{self.stance.duration_s:.3f} s from {self.stance.source}")
        return table


class AnkleRomGenerator(_PositionGenerator):
    """Passive range of motion (module docstring; ``schema.AnkleRom``)."""

    protocol: AnkleRom

    def __init__(self, protocol: AnkleRom, dt: float, kinematics: Kinematics, source: str,
                 side: str) -> None:
        self.side = side
        super().__init__(protocol, dt, kinematics, source)

    def _build_path(self) -> np.ndarray:
        p, rad = self.protocol, math.radians
        r0, p0 = self._neutral()
        amp = p.amplitude_deg
        v, a, j = rad(p.speed_deg_s), rad(p.max_acceleration_deg_s2), rad(p.max_jerk_deg_s3)
        path = AnglePath(self.dt, r0, p0)

        def go(plantar: float, inversion: float) -> None:
            dr, dp = anatomical_to_platform(plantar, inversion, self.side)
            path.move_to(r0 + dr, p0 + dp, v, a, j, p.profile)

        for item in p.sequence:
            if item == "circuit":
                d, pl = rad(amp.dorsiflexion or 0.0), rad(amp.plantarflexion or 0.0)
                inv, ev = rad(amp.inversion or 0.0), rad(amp.eversion or 0.0)
                # Ellipse through the four ends: pitch c ± r spans [-dorsi, +plantar], roll alike.
                sign = 1.0 if self.side == "right" else -1.0
                pc, pr = 0.5 * (pl - d), 0.5 * (pl + d)
                rc, rr = sign * 0.5 * (inv - ev), sign * 0.5 * (inv + ev)
                path.move_to(r0 + rc, p0 + pc + pr, v, a, j, p.profile)
                path.hold(p.hold_s)
                path.ellipse(r0 + rc, p0 + pc, rr, pr, p.repetitions, v, a, j, p.profile)
                path.hold(p.hold_s)
                path.move_to(r0, p0, v, a, j, p.profile)
                continue
            for _ in range(p.repetitions):
                if item == "dorsi_plantar":
                    ends = ((-rad(amp.dorsiflexion or 0.0), 0.0),
                            (rad(amp.plantarflexion or 0.0), 0.0))
                else:
                    ends = ((0.0, rad(amp.inversion or 0.0)), (0.0, -rad(amp.eversion or 0.0)))
                for plantar, inversion in ends:
                    go(plantar, inversion)
                    path.hold(p.hold_s)
                go(0.0, 0.0)
        return path.samples()


class IsometricHoldGenerator(_PositionGenerator):
    """Isometric holds at set platform angles (``schema.IsometricHold``)."""

    protocol: IsometricHold

    def _build_path(self) -> np.ndarray:
        p, rad = self.protocol, math.radians
        r0, p0 = self._neutral()
        v, a, j = (rad(p.transition_speed_deg_s), rad(p.max_acceleration_deg_s2),
                   rad(p.max_jerk_deg_s3))
        target = math.nan if p.target_force_n is None else p.target_force_n
        path = AnglePath(self.dt, r0, p0)
        for h in p.holds:
            path.move_to(rad(h.roll_deg), rad(h.pitch_deg), v, a, j, p.profile)
            path.hold(h.hold_s, target)
            path.hold(h.rest_s)
        path.move_to(r0, p0, v, a, j, p.profile)
        return path.samples()


class PositionPlaybackGenerator(_TableGenerator):
    """Slider positions from a CSV through ``rt.references.playback.TrajectoryPlayback``."""

    protocol: PositionPlayback
    mode = Mode.POSITION
    _block_id = _BLOCK_POSITION

    def __init__(self, protocol: PositionPlayback, dt: float, kinematics: Kinematics,
                 source: str, base_dir: Path) -> None:
        super().__init__(protocol, dt, kinematics, source)
        # Reads, checks (stroke, velocity, acceleration) and resamples; raises with file/line.
        try:
            self.playback = TrajectoryPlayback.from_csv(
                base_dir / protocol.file, dt=dt, sample_rate_hz=protocol.sample_rate_hz,
                stroke=kinematics.stroke, interpolation=protocol.interpolation,
                uniform=protocol.uniform)
        except ProtocolValidationError as exc:
            raise self._refuse("file", str(exc)) from None
        self._set_length(self.playback.n_samples)

    def _build(self, report: ValidationReport) -> np.ndarray | None:
        pb, kin = self.playback, self.kinematics
        n = self.n_samples
        table = np.zeros((n, POSITION_BLOCK.stop))
        for k in range(n):
            row = table[k]
            pb.state_at(k, row[Q], row[QD], row[QDD])
            try:
                c = kin.fk(row[Q], check=True)
            except (WorkspaceError, ConvergenceError) as exc:
                report.violations.append(f"t = {k * self.dt:.3f} s: {exc}")
                return None
            row[9], row[10], row[11] = c.z, c.roll, c.pitch
        if n >= 3:
            table[:, POSE_DOT] = np.gradient(table[:, POSE], self.dt, axis=0, edge_order=2)
        table[:, FZ] = table[:, FZ_DOT] = math.nan
        self._const[:] = 0.0
        return table


class ActiveAssistGenerator(Generator):
    """Active-assisted exercise computed online from the patient's torque.

    Per axis (θ the angle from the neutral pose, rad):
    ``I θ̈ + B (θ̇ - g θ̇_guide) + g K (θ - θ_guide) = τ_patient``, integrated by semi-implicit
    Euler at dt, with ``g = assistance_gain`` and the guide θ_guide(t) = env(t)·(c + r sin(2π t/T
    + φ)) spanning the ROM (env: raised-cosine fade over ``ramp_s`` at both ends). With g = 1
    the spring-damper pulls towards the guide's angle *and* rate, so a passive foot follows the
    guide with an error of only I θ̈_guide / K (no damping lag); with g = 0 the platform is a
    mass-damper the patient moves alone. Then limited, in
    this order: θ̈ within ±α (``max_acceleration_deg_s2``); θ̇ within ``max_speed_deg_s``; θ̇
    towards a ROM end within the speed from which braking at α stops at the end
    (:meth:`_stop_speed`); θ clamped to the ROM as a last resort (round-off only).
    An unused axis stays at neutral.

    ``update(out, inp)`` reads ``inp.tau_roll_nm``/``tau_pitch_nm`` (N·m; None = a passive
    patient) and costs three ``kinematics.ik`` calls (≈ 30 µs). ``validate()`` reports
    worst-case bounds valid for any patient input (the ROM, the speed limit, slider speeds and
    accelerations over a 7×7 grid of the ROM at the extreme rates and accelerations), not one
    simulated run.
    """

    protocol: ActiveAssist
    mode = Mode.POSITION

    def __init__(self, protocol: ActiveAssist, dt: float, kinematics: Kinematics, source: str,
                 side: str) -> None:
        super().__init__(protocol, dt, kinematics, source)
        p, rad = protocol, math.radians
        self.side = side
        self._set_length(int(round(p.duration_s / dt)) + 1)
        self._z = p.pose.z_m
        self._r0, self._p0 = rad(p.pose.roll_deg), rad(p.pose.pitch_deg)
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
        self.reset()

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
        """Largest speed (rad/s) for this step from which braking at α stops within
        ``distance`` (rad): v·dt + v²/(2α) - v·dt/2 ≤ d (the step, then the discrete braking),
        and never more than reaches the end in this step (v·dt ≤ d), so the angle arrives at a
        ROM end with its rate, not by the clamp."""
        a, dt = self._a_max, self.dt
        if distance <= 0.0:
            return 0.0
        return min(a * (math.sqrt(0.25 * dt * dt + 2.0 * distance / a) - 0.5 * dt),
                   distance / dt)

    def _step_axis(self, th: float, w: float, tau: float, guide: float, guide_rate: float,
                   imk: tuple[float, float, float], lo: float, hi: float
                   ) -> tuple[float, float, float]:
        inertia, damping, stiffness = imk
        a_max, w_max, g = self._a_max, self._w_max, self._gain
        acc = (tau - damping * (w - g * guide_rate) - g * stiffness * (th - guide)) / inertia
        acc = min(max(acc, -a_max), a_max)
        w_new = min(max(w + acc * self.dt, -w_max), w_max)
        if w_new > 0.0:
            w_new = min(w_new, self._stop_speed(hi - th))
        elif w_new < 0.0:
            w_new = max(w_new, -self._stop_speed(th - lo))
        th_new = th + w_new * self.dt
        if th_new > hi:
            th_new, w_new = hi, 0.0
        elif th_new < lo:
            th_new, w_new = lo, 0.0
        return th_new, w_new, (w_new - w) / self.dt

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
        for r, pt in ((float(r), float(pt)) for r in rolls for pt in pitches):
            try:
                c = kin.ik(z, r, pt, check=True)
            except KinematicsError as exc:
                report.violations.append(f"rom_deg: the ROM point roll {math.degrees(r):.2f} "
                                         f"deg, pitch {math.degrees(pt):.2f} deg: {exc}")
                break
            q_lo, q_hi = min(q_lo, *c.q), max(q_hi, *c.q)
            for vr, vp, a_r, a_p in combos:
                gp_ = kin.ik(z, r + h * vr + hh * a_r, pt + h * vp + hh * a_p, check=False).q
                gm_ = kin.ik(z, r - h * vr + hh * a_r, pt - h * vp + hh * a_p, check=False).q
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
        _check_limits(report, p)
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
        try:
            q = kin.ik(z, r, pt, check=False).q
            gp_ = kin.ik(z, r + h * vr + hh * ar, pt + h * vp + hh * ap, check=False).q
            gm_ = kin.ik(z, r - h * vr + hh * ar, pt - h * vp + hh * ap, check=False).q
        except KinematicsError:
            return GeneratorStatus.ERROR_KINEMATICS
        b = out.buf
        for i in range(3):
            b[i] = q[i]
            b[3 + i] = (gp_[i] - gm_[i]) / (2.0 * h)
            b[6 + i] = (gp_[i] - 2.0 * q[i] + gm_[i]) / (h * h)
        b[9], b[10], b[11] = z, r, pt
        b[12], b[13], b[14] = 0.0, vr, vp
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


# ------------------------------------------------------------------------------ factory
def make_generator(protocol: ProtocolModel, *, dt: float = 1.0e-3, kinematics: Kinematics,
                   patient_weight_kg: float | None = None, base_dir: str | Path | None = None,
                   side: str = "right") -> Generator:
    """Build the generator of a validated protocol model (``protocols.library.load_protocol``).

    Args:
        protocol: the protocol.
        dt: loop period (s), 1e-4 … 1e-2.
        kinematics: the robot's kinematic model (slider references, workspace checks).
        patient_weight_kg: the patient's weight (kg); required by gait replay.
        base_dir: where relative file names in the protocol are resolved; default the
            protocol file's folder (or the working directory for an in-memory protocol).
        side: ``"right"`` or ``"left"`` foot, for the anatomical directions.

    Raises:
        ProtocolValidationError: a file the protocol names is missing or malformed, or a value
            is inconsistent with it (e.g. ramps longer than the stance); the message names the
            file, the field and the reason.
        ConfigurationError: ``dt`` or ``side`` out of range.
    """
    if not (math.isfinite(dt) and 1e-4 <= dt <= 1e-2):
        raise ConfigurationError(f"dt must be in [1e-4, 1e-2] s (got {dt!r})")
    if side not in ("right", "left"):
        raise ConfigurationError(f"side must be 'right' or 'left' (got {side!r})")
    src_path = protocol.loaded_from
    source = str(src_path) if src_path is not None else f"<protocol {protocol.name!r}>"
    if base_dir is not None:
        base = Path(base_dir)
    elif src_path is not None:
        base = Path(src_path).parent
    else:
        base = Path.cwd()
    if isinstance(protocol, SineFz):
        return SineFzGenerator(protocol, dt, kinematics, source)
    if isinstance(protocol, GaitReplay):
        return GaitReplayGenerator(protocol, dt, kinematics, source, patient_weight_kg, base)
    if isinstance(protocol, AnkleRom):
        return AnkleRomGenerator(protocol, dt, kinematics, source, side)
    if isinstance(protocol, IsometricHold):
        return IsometricHoldGenerator(protocol, dt, kinematics, source)
    if isinstance(protocol, ActiveAssist):
        return ActiveAssistGenerator(protocol, dt, kinematics, source, side)
    if isinstance(protocol, PositionPlayback):
        return PositionPlaybackGenerator(protocol, dt, kinematics, source, base)
    raise ProtocolValidationError(f"{source}: kind: no generator for {protocol.kind!r}")
