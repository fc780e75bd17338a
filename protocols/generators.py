"""Protocol generators: stream one protocol's references into the 1 kHz loop.

Per-cycle API (CONVENTIONS 6, like ruckig): build with :func:`make_generator` (reads the files
the protocol names; malformed inputs raise :class:`~rt.errors.ProtocolValidationError`), call
``validate()`` once before the run (computes the whole reference, returns a
:class:`~protocols.output.ValidationReport`), then ``update(out)`` once per cycle into a
preallocated :class:`~protocols.output.ReferenceOutput`; it returns a
:class:`~protocols.output.GeneratorStatus` and never raises; the precomputed kinds copy one table
row and create no object that outlives the call (active assist: see its module). ``reset()``
rewinds to the first sample.

How each kind is produced (``dt`` = loop period):

* sine_fz — force mode. F(t) = w(t)·(mean + A sin(2π f (t - ramp_in))), w the product of a
  raised-cosine ramp in and one out, so F and dF/dt are 0 at both ends and dF/dt is continuous.
  The ramp out is stretched by < dt so the last sample lands on the grid.
* gait_replay — force mode. The selected stance is resampled at the loop rate by a
  shape-preserving cubic (scipy ``PchipInterpolator``: no overshoot, so no force above the
  record's peak sample or below 0; C¹) or linearly; played ``time_scale`` times slower; scaled
  by ``percent_body_weight/100 × patient_weight_kg / source body mass`` (the file's
  PROCESSING:Bodymass, else ``source_body_weight_kg``) after a plausibility check of the
  stance's peak against that mass; the plate's unloaded offset removed (the noise left around
  0 N before contact is clipped at 0: a plate cannot be pulled); tapered to 0 N over ``ramp_s``
  at both ends of every stance, on the unloaded lead-in (``gait.select_stance``);
  ``repetitions`` stances separated by ``rest_between_s`` at 0 N. Traceability (source sha256,
  plate, stance window, offset removed, scale factor, source body mass) in ``info``.
* ankle_rom, isometric_hold — position mode. An angular path (``protocols.profiles``) of
  rest-to-rest jerk-limited or raised-cosine moves and holds, converted to slider references.
* position_playback — position mode. The CSV is read, checked and resampled by
  ``rt.references.playback.TrajectoryPlayback``; the platform pose comes from forward
  kinematics of every sample (pose rates by central differences).
* active_assist — position mode, computed online from the patient's torque
  (:class:`ActiveAssistGenerator`).
* isometric_hold with ankle-torque targets — position mode, the holds' angles precomputed and
  the regulated holds computed online from the patient's torque
  (``protocols.torque_hold.TorqueHoldGenerator``).

Position kinds get their slider references from the pose path through ``kinematics.ik``
(``protocols.base``); force kinds hold the pose (``q_ref`` = its IK) and stream fz.
Precomputed references are checked whole by ``validate()``; the active-assist reference depends
on the patient and ``validate()`` bounds it instead (``protocols.active_assist``). Anatomical
directions: :data:`FOOT_MOUNTING`.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from scipy.interpolate import PchipInterpolator

from protocols import gait
from protocols.active_assist import ActiveAssistGenerator
from protocols.base import (
    BLOCK_POSITION,
    FOOT_MOUNTING,
    MAX_PRECOMPUTED_S,
    ForceGenerator,
    Generator,
    PositionGenerator,
    TableGenerator,
    anatomical_to_platform,
)
from protocols.output import (
    FZ,
    FZ_DOT,
    POSE,
    POSE_DOT,
    POSITION_BLOCK,
    QD,
    QDD,
    Mode,
    Q,
    ValidationReport,
)
from protocols.profiles import AnglePath, cosine_ramp
from protocols.reference_kernels import fk_path
from protocols.schema import (
    ActiveAssist,
    AnkleRom,
    GaitReplay,
    IsometricHold,
    PositionPlayback,
    ProtocolModel,
    SineFz,
)
from rt.errors import ConfigurationError, ConvergenceError, ProtocolValidationError, WorkspaceError
from rt.model.ankle import AnkleSetup
from rt.model.kinematics import FK_MAX_ITERATIONS, FK_STEP_TOL_RAD, Kinematics
from rt.references.playback import TrajectoryPlayback

__all__ = ["FOOT_MOUNTING", "MAX_PRECOMPUTED_S", "ActiveAssistGenerator", "AnkleRomGenerator",
           "GaitReplayGenerator", "Generator", "IsometricHoldGenerator",
           "PositionPlaybackGenerator", "SineFzGenerator", "anatomical_to_platform",
           "make_generator"]


# ------------------------------------------------------------------------------ kinds
class SineFzGenerator(ForceGenerator):
    """Sinusoidal force in Z with raised-cosine ramps (module docstring)."""

    protocol: SineFz

    def __init__(self, protocol: SineFz, dt: float, kinematics: Kinematics, source: str) -> None:
        super().__init__(protocol, dt, kinematics, source)
        p = protocol
        self._t_out = p.ramp_in_s + p.cycles / p.frequency_hz
        n_periods = math.ceil((self._t_out + p.ramp_out_s) / dt - 1e-9)
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


class GaitReplayGenerator(ForceGenerator):
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
        st = p.stance
        try:
            record = gait.read_grf(base_dir / p.source, p.plate_index)
            if st.select == "auto":
                # Start before contact: the tapers (ramp_s in played time) act on the unloaded
                # lead-in, never on the heel-strike transient.
                lead = p.ramp_s / p.time_scale + gait.LEAD_MARGIN_S
                stance = gait.select_stance(record, threshold_n=st.threshold_n,
                                            occurrence=st.occurrence, lead_s=lead)
            else:
                stance = gait.select_stance(record, start_s=st.start_s, end_s=st.end_s)
        except ProtocolValidationError as exc:
            raise self._refuse("source", str(exc)) from None
        mass, mass_from = self._source_mass(record)
        plate = f"force platform {p.plate_index}: " if p.plate_index is not None else ""
        try:
            self.peak_bw = gait.check_plausible_peak(stance, mass, mass_from, plate)
        except ProtocolValidationError as exc:
            raise self._refuse("source", str(exc)) from None
        self.source_mass_kg, self.source_mass_from = mass, mass_from
        self.scale = p.percent_body_weight / 100.0 * self.patient_weight_kg / mass
        if p.include_shear and not stance.has_shear:
            raise self._refuse("include_shear", f"the record {record.source} has no fx, fy "
                               "(a CSV needs the header t,fz,fx,fy)")
        self.stance = stance
        played = stance.duration_s * p.time_scale
        if 2.0 * p.ramp_s >= played:
            raise self._refuse("ramp_s", f"ramps of {p.ramp_s:g} s at both ends do not fit in "
                               f"the {played:.3f} s stance (time_scale {p.time_scale:g})")
        # Samples of one stance (the last at or before its end) and of one rest.
        self._n_stance = math.floor(played / dt + 1e-9) + 1
        self._n_rest = round(p.rest_between_s / dt)
        self._period = self._n_stance - 1 + self._n_rest
        self._set_length((p.repetitions - 1) * self._period + self._n_stance)

    def _source_mass(self, record: gait.GroundReactionForce) -> tuple[float, str]:
        """The source subject's body mass (kg) and where it comes from."""
        given = self.protocol.source_body_weight_kg
        stated = record.body_mass_kg
        if stated is not None:
            if given is not None and abs(given - stated) > 0.5:
                raise self._refuse("source_body_weight_kg", f"{given:g} kg, but the record "
                                   f"{record.source} states PROCESSING:Bodymass = {stated:g} "
                                   "kg: remove source_body_weight_kg or make it agree")
            return stated, "PROCESSING:Bodymass"
        if given is None:
            raise self._refuse("source_body_weight_kg", f"required: the record {record.source} "
                               "does not state the subject's body mass (PROCESSING:Bodymass)")
        return given, "source_body_weight_kg"

    @property
    def info(self) -> dict:
        """Traceability of the replayed force (kg, N, s; JSON-ready)."""
        st = self.stance
        return {"source": st.source, "source_sha256": st.sha256, "plate_index": st.plate_index,
                "stance_window_s": [round(st.start_s, 6), round(st.start_s + st.duration_s, 6)],
                "contact_s": None if st.contact_s is None else [round(x, 6)
                                                                for x in st.contact_s],
                "offset_removed_n": {"fx": st.offset_n[0], "fy": st.offset_n[1],
                                     "fz": st.offset_n[2]},
                "offset_measured": st.offset_measured,
                "scale_factor": self.scale, "source_body_mass_kg": self.source_mass_kg,
                "source_body_mass_from": self.source_mass_from,
                "source_peak_n": float(st.fz.max()), "source_peak_bw": self.peak_bw,
                "patient_weight_kg": self.patient_weight_kg}

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
        # Noise around 0 N before contact and after toe off (offset removed): a plate cannot be
        # pulled, so the replayed vertical force is clipped at 0.
        channels: list[tuple[int, np.ndarray]] = [(0, np.maximum(st.fz, 0.0))]
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
        st = self.stance
        report.notes.append(f"scale {self.scale:.4f} = {self.protocol.percent_body_weight:g} % "
                            f"x {self.patient_weight_kg:g} kg / {self.source_mass_kg:g} kg "
                            f"({self.source_mass_from}); stance {st.start_s:.3f} .. "
                            f"{st.start_s + st.duration_s:.3f} s of {st.source} (sha256 "
                            f"{(st.sha256 or '?')[:12]}…), "
                            + (f"offset removed {st.offset_n[2]:.2f} N" if st.offset_measured
                               else "no unloaded stretch: offset not measured, not removed")
                            + f", peak {self.peak_bw:.2f} BW")
        return table


class AnkleRomGenerator(PositionGenerator):
    """Passive range of motion (module docstring; ``schema.AnkleRom``)."""

    protocol: AnkleRom

    def __init__(self, protocol: AnkleRom, dt: float, kinematics: Kinematics, source: str,
                 side: str, ankle: AnkleSetup | None = None) -> None:
        self.side = side
        super().__init__(protocol, dt, kinematics, source, ankle)

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


class IsometricHoldGenerator(PositionGenerator):
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


class PositionPlaybackGenerator(TableGenerator):
    """Slider positions from a CSV through ``rt.references.playback.TrajectoryPlayback``."""

    protocol: PositionPlayback
    mode = Mode.POSITION
    _block_id = BLOCK_POSITION

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
        # Compiled: every sample's forward kinematics in one call, warm-started from the last
        # solution as ``kin.fk`` is; a sample it refuses takes the interpreted loop below,
        # which words the refusal.
        pos, vel, acc = pb.states()
        q = np.ascontiguousarray(pos[:n], dtype=np.float64)
        # Newton from the nominal rod angles, then from each sample's solution: the same
        # solutions as ``kin.fk`` to its step tolerance (1e-12 rad) whatever its warm start.
        phi = np.full(3, kin.phi_nominal)
        pose = np.empty((n, 3))
        if fk_path(kin.geom, kin.limits_array, q, phi, FK_STEP_TOL_RAD, FK_MAX_ITERATIONS,
                   pose) < 0:
            table[:, Q], table[:, QD], table[:, QDD] = q, vel[:n], acc[:n]
            table[:, POSE] = pose
            return self._finish_playback(table)
        for k in range(n):
            row = table[k]
            pb.state_at(k, row[Q], row[QD], row[QDD])
            try:
                c = kin.fk(row[Q], check=True)
            except (WorkspaceError, ConvergenceError) as exc:
                report.violations.append(f"t = {k * self.dt:.3f} s: {exc}")
                return None
            row[9], row[10], row[11] = c.z, c.roll, c.pitch
        return self._finish_playback(table)

    def _finish_playback(self, table: np.ndarray) -> np.ndarray:
        n = table.shape[0]
        if n >= 3:
            table[:, POSE_DOT] = np.gradient(table[:, POSE], self.dt, axis=0, edge_order=2)
        table[:, FZ] = table[:, FZ_DOT] = math.nan
        self._const[:] = 0.0
        return table



# ------------------------------------------------------------------------------ factory
def make_generator(protocol: ProtocolModel, *, dt: float = 1.0e-3, kinematics: Kinematics,
                   patient_weight_kg: float | None = None, base_dir: str | Path | None = None,
                   side: str | None = None, ankle: AnkleSetup | None = None) -> Generator:
    """Build the generator of a validated protocol model (``protocols.library.load_protocol``).

    Args:
        protocol: the protocol.
        dt: loop period (s), 1e-4 … 1e-2.
        kinematics: the robot's kinematic model (slider references, workspace checks).
        patient_weight_kg: the patient's weight (kg); required by gait replay.
        base_dir: where relative file names in the protocol are resolved; default the
            protocol file's folder (or the working directory for an in-memory protocol).
        side: ``"right"`` or ``"left"`` foot, for the anatomical directions (default: the
            ankle setup's side, else right).
        ankle: the patient's ankle setup (``rt.model.ankle``): ankle exercises then turn the
            foot about its ankle centre and pre-flight checks the centre's displacement.

    Raises:
        ProtocolValidationError: a file the protocol names is missing or malformed, or a value
            is inconsistent with it (e.g. ramps longer than the stance); the message names the
            file, the field and the reason.
        ConfigurationError: ``dt`` or ``side`` out of range.
    """
    if not (math.isfinite(dt) and 1e-4 <= dt <= 1e-2):
        raise ConfigurationError(f"dt must be in [1e-4, 1e-2] s (got {dt!r})")
    side_given = side
    side = side if side is not None else "right"
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
    if ankle is not None and isinstance(protocol, (AnkleRom, IsometricHold, ActiveAssist)):
        side = ankle.side if side_given is None else side_given
        if ankle.side != side:
            raise ProtocolValidationError(f"{source}: ankle setup: it is for the {ankle.side} "
                                          f"foot but the session is for the {side} foot")
    if isinstance(protocol, AnkleRom):
        return AnkleRomGenerator(protocol, dt, kinematics, source, side, ankle)
    if isinstance(protocol, IsometricHold):
        if protocol.has_torque_targets:
            # Imported here: protocols.torque_hold builds on this module's isometric holds.
            from protocols.torque_hold import TorqueHoldGenerator
            return TorqueHoldGenerator(protocol, dt, kinematics, source, ankle)
        return IsometricHoldGenerator(protocol, dt, kinematics, source, ankle)
    if isinstance(protocol, ActiveAssist):
        return ActiveAssistGenerator(protocol, dt, kinematics, source, side, ankle)
    if isinstance(protocol, PositionPlayback):
        return PositionPlaybackGenerator(protocol, dt, kinematics, source, base)
    raise ProtocolValidationError(f"{source}: kind: no generator for {protocol.kind!r}")
