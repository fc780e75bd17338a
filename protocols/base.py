"""Shared machinery of the protocol generators: the :class:`Generator` base, the precomputed
(table) generators, slider references from a pose path, and the report helpers.

Slider references from a pose path: q = ``kinematics.ik(z, roll, pitch)`` at every sample, and
the derivatives of q along the local quadratic path g(h) = ik(p + h ṗ + h²/2 p̈) by central
differences, q̇ = (g(H) - g(-H))/2H and q̈ = (g(H) - 2 g(0) + g(-H))/H² with H = 1 ms
(truncation ~1e-10 m/s, round-off ~1e-10 m/s² for these motions). Holds reuse the previous
sample's solution. The tables are computed by the compiled kernels of
``protocols.reference_kernels`` (milliseconds for a minute at 1 kHz); :func:`joint_references`
is the interpreted reference implementation, and it words every refusal.

Precomputed references are stored as one table: 136 B per sample in position mode (q, q̇, q̈,
pose, pose rate, force target), 32 B in force mode (fz, ḟz, fx, fy); ``MAX_PRECOMPUTED_S``
bounds it. ``update`` then copies one row into the caller's buffer.

Foot mounting (:data:`FOOT_MOUNTING`): the foot lies along the platform's +x axis (toes towards
+x), the ankle axis along y. Plantarflexion (toes down) is positive pitch (R_y(β) takes +x
down); inversion (medial border up) is positive roll for a right foot (medial side +y) and
negative roll for a left foot.
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod

import numpy as np

from protocols.output import (
    FORCE_BLOCK,
    FZ,
    FZ_DOT,
    N_FIELDS,
    POSE,
    POSE_DOT,
    POSITION_BLOCK,
    QD,
    QDD,
    SHEAR,
    GeneratorInput,
    GeneratorStatus,
    Mode,
    Q,
    ReferenceOutput,
    ValidationReport,
)
from protocols.profiles import PITCH, PITCH_D, ROLL, ROLL_D, TARGET
from protocols.reference_kernels import HEAVE_PARAMS, ankle_horizontal, path_references
from protocols.schema import ProtocolModel
from rt.errors import KinematicsError, ProtocolValidationError
from rt.model.ankle import (
    DEFAULT_COMFORT_LIMIT_M,
    AnkleKinematics,
    AnkleSetup,
    describe_angles,
    platform_angles,
)
from rt.model.kinematics import Kinematics
from rt.references.program import ProgramTable

FOOT_MOUNTING = "foot along +x (toes +x); plantarflexion = +pitch; inversion = +roll (right foot)"
#: Longest precomputed protocol (s): 20 min is 163 MB of position table at 1 kHz.
MAX_PRECOMPUTED_S = 1200.0
#: Step along the local path for the slider-velocity/acceleration differences (s).
DERIVATIVE_STEP_S = 1.0e-3
_SLACK_RAD = 1e-9
#: Indices into ReferenceOutput.blocks (the columns a table generator writes per cycle).
BLOCK_POSITION, BLOCK_FORCE = 0, 1


def anatomical_to_platform(plantar_rad: float, inversion_rad: float, side: str
                           ) -> tuple[float, float]:
    """(roll, pitch) offsets (rad) for a plantarflexion and an inversion angle (rad; negative
    values are dorsiflexion and eversion), for the ``side`` foot (:data:`FOOT_MOUNTING`)."""
    return platform_angles(plantar_rad, inversion_rad, side)


# ------------------------------------------------------------------------------ helpers
def joint_references(kin: Kinematics, z: float, path: np.ndarray, dt: float,
                     q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
                     ankle: AnkleKinematics | None = None,
                     z_out: np.ndarray | None = None) -> str | None:
    """Fill q, q̇, q̈ (n, 3) from an angle path (n, 7); returns the first workspace problem.

    With ``ankle`` the heave follows the angles (``AnkleKinematics.z_for``: the ankle centre
    keeps its height) instead of ``z``, and is written to ``z_out``; the slider derivatives
    then include the heave's."""
    h = DERIVATIVE_STEP_S
    hh = 0.5 * h * h

    def heave(r: float, p: float) -> float:
        return z if ankle is None else ankle.z_for(r, p)

    for k in range(path.shape[0]):
        r, p, vr, vp, ar, ap = (float(x) for x in path[k, :6])
        zk = heave(r, p)
        if z_out is not None:
            z_out[k] = zk
        still = vr == 0.0 and vp == 0.0 and ar == 0.0 and ap == 0.0
        if still and k > 0 and r == path[k - 1, ROLL] and p == path[k - 1, PITCH]:
            q[k] = q[k - 1]
            qd[k] = qdd[k] = 0.0
            continue
        try:
            c = kin.ik(zk, r, p, check=True)
        except KinematicsError as exc:
            return f"t = {k * dt:.3f} s (roll {math.degrees(r):.2f} deg, pitch " \
                   f"{math.degrees(p):.2f} deg): {exc}"
        q[k] = c.q
        if still:
            qd[k] = qdd[k] = 0.0
            continue
        rp, pp = r + h * vr + hh * ar, p + h * vp + hh * ap
        rm, pm = r - h * vr + hh * ar, p - h * vp + hh * ap
        gp = kin.ik(heave(rp, pp), rp, pp, check=False).q
        gm = kin.ik(heave(rm, pm), rm, pm, check=False).q
        for i in range(3):
            qd[k, i] = (gp[i] - gm[i]) / (2.0 * h)
            qdd[k, i] = (gp[i] - 2.0 * c.q[i] + gm[i]) / (h * h)
    return None


def path_joint_references(kin: Kinematics, z: float, path: np.ndarray, dt: float,
                          q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
                          ankle: AnkleKinematics | None = None,
                          z_out: np.ndarray | None = None) -> str | None:
    """:func:`joint_references` compiled (``protocols.reference_kernels``): the same outputs
    to round-off in milliseconds. A path with a problem is handed to :func:`joint_references`,
    which words the refusal (or raises) exactly as before."""
    n = path.shape[0]
    heave = np.zeros(HEAVE_PARAMS)
    if ankle is not None:
        heave[0] = 1.0
        heave[1] = ankle.start[2]
        heave[2:5] = ankle.centre_P
    # Contiguous buffers (callers pass column views of a table: one compiled signature),
    # copied out on success.
    zs = np.empty(n)
    qq, qqd, qqdd = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3))
    bad = path_references(kin.geom, kin.limits_array, float(z), heave,
                          np.ascontiguousarray(path, dtype=np.float64), DERIVATIVE_STEP_S,
                          qq, qqd, qqdd, zs)
    if bad >= 0:
        return joint_references(kin, z, path, dt, q, qd, qdd, ankle, z_out)
    q[:], qd[:], qdd[:] = qq, qqd, qqdd
    if z_out is not None:
        z_out[:] = zs
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


def check_limits(report: ValidationReport, protocol: ProtocolModel) -> None:
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

    @property
    def info(self) -> dict:
        """Traceability of the reference's sources (JSON-ready: the session summary and the
        recording's metadata carry it); empty for protocols that read no record."""
        return {}

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


class TableGenerator(Generator):
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
                if self._block_id == BLOCK_POSITION:
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
                check_limits(report, self.protocol)
        self.last_report = report
        self._ready = report.ok
        self.index = 0
        return report

    def table_view(self) -> ProgramTable | None:
        """The validated table as the loop's compiled sequencer plays it (``ProgramTable``:
        this block's columns over ``_const``); None before a passing ``validate()`` and for a
        subclass whose ``update`` does more than copy a row (it is then called each cycle)."""
        if not self._ready or type(self).update is not TableGenerator.update:
            return None
        col0 = (POSITION_BLOCK if self._block_id == BLOCK_POSITION else FORCE_BLOCK).start
        return ProgramTable(np.ascontiguousarray(self._table, dtype=np.float64), col0,
                            self._const.copy(), self.mode)

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
        block = POSITION_BLOCK if self._block_id == BLOCK_POSITION else FORCE_BLOCK
        full[:, block] = self._table
        return {"t": np.arange(self.n_samples) * self.dt, "q": full[:, Q], "qd": full[:, QD],
                "qdd": full[:, QDD], "pose": full[:, POSE], "pose_dot": full[:, POSE_DOT],
                "fz": full[:, FZ], "fz_dot": full[:, FZ_DOT], "shear": full[:, SHEAR]}


class ForceGenerator(TableGenerator):
    """Force in Z with the pose held: table columns fz, fz_dot, fx, fy."""

    mode = Mode.FORCE
    _block_id = BLOCK_FORCE

    def force_at(self, index: int, out: np.ndarray) -> None:
        """F_d (N) and Ḟ_d (N/s) of sample ``index`` (clamped to the table) into ``out[0:2]``:
        the whole reference is known before it plays, so the loop can read it ahead
        (``rt.references.program.ForcePreview``)."""
        table = self._table
        if table.shape[0] == 0:                 # not validated: nothing plays either
            out[0] = out[1] = 0.0
            return
        k = min(max(index, 0), table.shape[0] - 1)
        out[0] = table[k, 0]
        out[1] = table[k, 1]

    def force_at_reads_table(self) -> bool:
        """True when :meth:`force_at` is the table's F_d, Ḟ_d columns (those of
        ``table_view()``) at the index clamped: the loop's compiled sequencer then reads ahead
        itself (``rt.references.sequencer_kernel.read_ahead``). A subclass that overrides
        ``force_at`` is read through it."""
        return type(self).force_at is ForceGenerator.force_at

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


class AnkleCentre:
    """How an ankle exercise treats the patient's ankle centre (``rt.model.ankle``).

    ``kinematics`` is None without an ankle setup (angles about the platform's centre, as
    before); with one, ``compensate`` says whether the heave follows the angles (the protocol's
    ``centre``: ``ankle``, the default when a setup is known, or ``platform``), and the ankle
    centre's horizontal displacement is checked against ``limit_m`` either way.
    """

    def __init__(self, protocol: ProtocolModel, kinematics: Kinematics, setup: AnkleSetup | None,
                 neutral: tuple[float, float, float], source: str) -> None:
        centre = getattr(protocol, "centre", None)
        limit_mm = getattr(protocol, "ankle_displacement_limit_mm", None)
        self.limit_m = DEFAULT_COMFORT_LIMIT_M if limit_mm is None else limit_mm * 1e-3
        if setup is None:
            if centre == "ankle":
                raise ProtocolValidationError(
                    f"{source}: centre: 'ankle' needs the patient's ankle setup (its height "
                    "above the sole, foot placement offsets and side), and none was given: "
                    "enter it or measure it with the camera")
            self.kinematics: AnkleKinematics | None = None
            self.compensate = False
            return
        self.kinematics = AnkleKinematics(kinematics, setup,
                                          list(kinematics.description.sensor.offset_m),
                                          neutral)
        self.compensate = centre != "platform"

    @property
    def heave(self) -> AnkleKinematics | None:
        """The ankle kinematics when the heave follows the angles, else None."""
        return self.kinematics if self.compensate else None

    def horizontal_displacements(self, rolls: np.ndarray, pitches: np.ndarray) -> np.ndarray:
        """The ankle centre's horizontal displacement (m) at each platform angle (rad):
        ``AnkleKinematics.pose_for_platform_angles(...).horizontal_m``, compiled (one IK per
        sample; an unreachable angle takes the interpreted path, which raises as before)."""
        ak = self.kinematics
        assert ak is not None
        rolls = np.ascontiguousarray(rolls, dtype=np.float64)
        pitches = np.ascontiguousarray(pitches, dtype=np.float64)
        d = np.empty(len(rolls))
        kin = ak.kinematics
        if ankle_horizontal(kin.geom, ak.neutral[0], np.asarray(ak.start),
                            np.asarray(ak.centre_P), rolls, pitches, d) >= 0:
            for k, (r, p) in enumerate(zip(rolls, pitches, strict=True)):
                d[k] = ak.pose_for_platform_angles(float(r), float(p),
                                                   self.compensate).horizontal_m
        return d

    def check(self, report: ValidationReport, rolls: np.ndarray, pitches: np.ndarray,
              times: np.ndarray | None) -> None:
        """Peak and RMS horizontal displacement of the ankle centre over the angle samples
        (rad); a violation naming the first ankle angle beyond the limit (and its time, s, when
        ``times`` are given), with the largest angle in that direction that stays within it."""
        ak = self.kinematics
        if ak is None:
            return
        d = self.horizontal_displacements(rolls, pitches)
        report.ankle_peak_displacement_m = float(d.max()) if len(d) else math.nan
        report.ankle_rms_displacement_m = float(np.sqrt(np.mean(d ** 2))) if len(d) else \
            math.nan
        report.ankle_displacement_limit_m = self.limit_m
        over = np.flatnonzero(d > self.limit_m)
        if not len(over):
            return
        k = int(over[0])
        plantar, inversion = ak.angles(float(rolls[k]), float(pitches[k]))
        # The worst sample in the same direction sets how far that direction may go.
        frac = ak.limit_along(plantar, inversion, self.limit_m, self.compensate)
        when = f" (t = {float(times[k]):.2f} s)" if times is not None else ""
        report.violations.append(
            f"ankle centre: at {describe_angles(plantar, inversion)}{when} it would move "
            f"{d[k] * 1e3:.1f} mm horizontally, beyond the comfort limit "
            f"{self.limit_m * 1e3:.0f} mm (peak {d.max() * 1e3:.1f} mm): narrow the range in "
            f"that direction to {describe_angles(frac * plantar, frac * inversion)} or raise "
            "ankle_displacement_limit_mm")


class PositionGenerator(TableGenerator):
    """Slider references from an angle path at constant heave, or with the heave that keeps
    the patient's ankle centre at its height (``ankle``)."""

    mode = Mode.POSITION
    _block_id = BLOCK_POSITION
    #: Every n-th sample's ankle displacement is evaluated (at 1 kHz: 100 Hz).
    ANKLE_DECIMATION = 10

    def __init__(self, protocol: ProtocolModel, dt: float, kinematics: Kinematics,
                 source: str, ankle: AnkleSetup | None = None) -> None:
        super().__init__(protocol, dt, kinematics, source)
        pose = protocol.pose  # type: ignore[union-attr]
        self.ankle = AnkleCentre(protocol, kinematics, ankle,
                                 (pose.z_m, math.radians(pose.roll_deg),
                                  math.radians(pose.pitch_deg)), source)
        self._path = self._build_path()
        self._set_length(self._path.shape[0])

    @abstractmethod
    def _build_path(self) -> np.ndarray:
        """The (n, 7) angle path (``protocols.profiles`` columns)."""

    def _ankle_samples(self, path: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The (roll, pitch, t) samples (rad, rad, s) whose ankle-centre displacement
        pre-flight checks: every ``ANKLE_DECIMATION``-th sample of the path and the last."""
        n = path.shape[0]
        idx = np.r_[np.arange(0, n, self.ANKLE_DECIMATION), n - 1] if n else np.arange(0)
        return path[idx, ROLL], path[idx, PITCH], idx * self.dt

    def _build(self, report: ValidationReport) -> np.ndarray | None:
        z = self.protocol.pose.z_m  # type: ignore[union-attr]
        path = self._path
        n = path.shape[0]
        table = np.zeros((n, POSITION_BLOCK.stop))
        table[:, 9] = z
        problem = path_joint_references(self.kinematics, z, path, self.dt, table[:, Q],
                                        table[:, QD], table[:, QDD], self.ankle.heave,
                                        table[:, 9])
        if problem is not None:
            report.violations.append(problem)
            return None
        if self.ankle.heave is not None and n >= 3:
            table[:, 12] = np.gradient(table[:, 9], self.dt, edge_order=2)
        self.ankle.check(report, *self._ankle_samples(path))
        table[:, 10], table[:, 11] = path[:, ROLL], path[:, PITCH]
        table[:, 13], table[:, 14] = path[:, ROLL_D], path[:, PITCH_D]
        table[:, FZ] = path[:, TARGET]
        table[:, FZ_DOT] = np.where(np.isnan(path[:, TARGET]), math.nan, 0.0)
        self._const[:] = 0.0
        return table

    def _neutral(self) -> tuple[float, float]:
        pose = self.protocol.pose  # type: ignore[union-attr]
        return math.radians(pose.roll_deg), math.radians(pose.pitch_deg)
