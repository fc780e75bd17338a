"""The RT process's side of identification: the ``identify_excitation`` program.

``talus identify run --backend rt`` (:mod:`rt.identification.rt_runner`) sends
``run identify_excitation {excitation, duration_s, out, label}`` to the RT process. The RT process
(this module, composed in by ``talus.composition``) plays the excitation like any position
program — approach to its first sample, play, return, rest — under its supervisor, and records
it as an MCAP session recording at ``out``:

* ``/robot/state`` (1 kHz: t, q, q̇, q_ref, τ, V) from the loop's recorder ring: the encoder
  positions and the drive voltages after the supervisor are what identification fits;
* ``/protocol/reference`` (phase per cycle: the fit keeps the ``play`` rows) and
  ``/robot/wrench`` from the session tap, as a session records them;
* ``/safety/events``; ``/identification/summary`` once at the end: outcome (``completed`` or
  ``stopped``), the loop time of the first and last played cycle, the supervisor's causes.

The metadata carries the excitation's coefficients, the robot description the RT process
believes (name and full content, so ``talus identify fit`` can refit from the file alone) and,
on the twin only, the twin's own truth — for the twin figures (relative error of each
identified parameter); a rig has no truth to record.

The file is written to a partial file beside ``out`` and hard-linked to ``out`` once closed
(``rt.output_files``): ``out`` appears complete or not at all, so the client waits for it;
an existing ``out`` is refused before anything moves.

Limits: ruckig (community edition) ignores position limits, and the supervisor would only stop
a trajectory that leaves them. The program therefore checks the whole trajectory before it is
accepted (:func:`check_trajectory`): stroke with the supervisor's margin, slider speed and
acceleration, platform roll/pitch range and angular speed of the limits in force. A trajectory
that leaves any of them is refused, naming the limit, and nothing moves.
"""
from __future__ import annotations

import logging
import math
import os
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from rt.errors import InputError, KinematicsError, validation_summary
from rt.identification.excitation import N_HARMONICS, FourierExcitation
from rt.model.kinematics import Kinematics
from rt.references.program import (
    Mode,
    ProgramInput,
    ProgramStatus,
    ProgramTable,
    ReferenceOutput,
)
from rt.references.sequencer import STOP_EVENTS_SETTLE_S, Phase, program_outcome
from rt.safety.limits import EffectiveLimits

if TYPE_CHECKING:
    from rt.service import RtService

log = logging.getLogger(__name__)

PROGRAM_NAME = "identify_excitation"
SUMMARY_TOPIC = "/identification/summary"
#: The recording ends this long after the program's duration at the latest (s): approach and
#: return at the sequencer's limits.
END_MARGIN_S = 60.0
#: Longest excitation (s): 10 min of 1 kHz table is 43 MB; identification needs ~1-2 min.
MAX_DURATION_S = 600.0
#: Pose check every this many samples (the excitation's highest harmonic is < 1 Hz).
POSE_CHECK_EVERY = 10


class ExcitationSpec(BaseModel):
    """A Fourier excitation as it travels (``FourierExcitation``'s fields)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    a: list[list[float]]
    b: list[list[float]]
    q0: float = Field(allow_inf_nan=False)
    f0_hz: float = Field(gt=0.0, le=10.0, allow_inf_nan=False)

    def excitation(self) -> FourierExcitation:
        a = np.array(self.a, float)
        b = np.array(self.b, float)
        if a.shape != b.shape or a.ndim != 2 or a.shape[0] != 3 or not 1 <= a.shape[1] <= 16:
            raise InputError(f"excitation: a and b must both be 3 × K (K ≤ 16) coefficients, "
                             f"got {a.shape} and {b.shape}")
        if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
            raise InputError("excitation: coefficients must be finite")
        return FourierExcitation(a, b, self.q0, self.f0_hz)

    @classmethod
    def of(cls, exc: FourierExcitation) -> ExcitationSpec:
        return cls(a=np.asarray(exc.a).tolist(), b=np.asarray(exc.b).tolist(), q0=exc.q0,
                   f0_hz=exc.f0_hz)


class ExcitationProgram:
    """A precomputed slider trajectory (q, q̇, q̈ per sample) played as a position program; no
    allocation and no arithmetic beyond a row copy in ``update`` (CONVENTIONS 6)."""

    def __init__(self, table: np.ndarray, dt: float) -> None:
        if table.ndim != 2 or table.shape[1] != 9 or len(table) < 2:
            raise ValueError("table must be (n ≥ 2, 9): q, q̇, q̈")
        self.table = np.ascontiguousarray(table, dtype=np.float64)
        self.dt = float(dt)
        self.n_samples = len(table)
        self.duration_s = (self.n_samples - 1) * self.dt
        self.index = 0

    @staticmethod
    def new_output() -> ReferenceOutput:
        return ReferenceOutput()

    def reset(self) -> None:
        self.index = 0

    def table_view(self) -> ProgramTable:
        """The table as the compiled sequencer plays it (q, q̇, q̈ in columns 0-8)."""
        return ProgramTable(self.table, 0, ReferenceOutput().buf, Mode.POSITION)

    def update(self, out: ReferenceOutput, inp: ProgramInput | None = None) -> int:
        k = self.index if self.index < self.n_samples else self.n_samples - 1
        out.buf[0:9] = self.table[k]
        out.mode = Mode.POSITION
        out.index = k
        out.done = k >= self.n_samples - 1
        if self.index < self.n_samples:
            self.index += 1
        return ProgramStatus.FINISHED if out.done else ProgramStatus.RUNNING


def excitation_table(exc: FourierExcitation, duration_s: float, dt: float) -> np.ndarray:
    """(n, 9) samples of q, q̇, q̈ every ``dt`` s over ``duration_s`` (both ends included)."""
    n = round(duration_s / dt) + 1
    q, qd, qdd = exc.evaluate(np.arange(n) * dt)
    return np.hstack((q, qd, qdd))


def check_trajectory(table: np.ndarray, kin: Kinematics, limits: EffectiveLimits,
                     dt: float) -> None:
    """Refuse (InputError naming the limit) a trajectory that leaves the limits in force."""
    q, qd, qdd = table[:, 0:3], table[:, 3:6], table[:, 6:9]
    lo = limits.stroke_lo_m + limits.stroke_margin_m
    hi = limits.stroke_hi_m - limits.stroke_margin_m
    if q.min() < lo or q.max() > hi:
        raise InputError(f"excitation leaves the stroke: sliders span [{q.min():.4f}, "
                         f"{q.max():.4f}] m, allowed [{lo:.4f}, {hi:.4f}] m (stroke less the "
                         "supervisor's margin)")
    v = float(np.abs(qd).max())
    if v > limits.max_slider_speed_m_s:
        raise InputError(f"excitation slider speed {v:.3f} m/s exceeds the limit "
                         f"{limits.max_slider_speed_m_s:.3f} m/s")
    a = float(np.abs(qdd).max())
    if a > limits.max_slider_accel_m_s2:
        raise InputError(f"excitation slider acceleration {a:.3f} m/s² exceeds the limit "
                         f"{limits.max_slider_accel_m_s2:.3f} m/s²")
    idx = np.arange(0, len(q), POSE_CHECK_EVERY)
    if idx[-1] != len(q) - 1:
        idx = np.append(idx, len(q) - 1)
    angles = np.empty((len(idx), 2))
    for j, k in enumerate(idx):
        try:
            cfg = kin.fk(q[k], check=False)
        except KinematicsError:
            raise InputError(f"excitation leaves the mechanism's assembly range at "
                             f"t = {k * dt:.2f} s") from None
        angles[j] = (cfg.roll, cfg.pitch)
    for col, name, amin, amax in ((0, "roll", limits.roll_min, limits.roll_max),
                                  (1, "pitch", limits.pitch_min, limits.pitch_max)):
        if angles[:, col].min() < amin or angles[:, col].max() > amax:
            raise InputError(
                f"excitation {name} spans [{math.degrees(angles[:, col].min()):.1f}, "
                f"{math.degrees(angles[:, col].max()):.1f}]°, outside the limits in force "
                f"[{math.degrees(amin):.1f}, {math.degrees(amax):.1f}]°")
    rate = np.abs(np.diff(angles, axis=0)).max() / (POSE_CHECK_EVERY * dt) if len(idx) > 1 else 0
    if rate > limits.max_angular_speed:
        raise InputError(f"excitation platform angular speed {math.degrees(rate):.1f}°/s "
                         f"exceeds the limit {math.degrees(limits.max_angular_speed):.1f}°/s")


def _summary_channel() -> Any:
    from rt.recording.channels import ChannelSpec
    return ChannelSpec(SUMMARY_TOPIC, "talus.IdentificationSummary", {
        "type": "object", "title": "talus.IdentificationSummary",
        "description": "How the excitation ended, written once by the RT process.",
        "properties": {
            "t": {"type": "number", "description": "loop time, s"},
            "outcome": {"type": "string", "description": "completed or stopped"},
            "t_play_start": {"type": "number", "description": "first played cycle, loop s"},
            "t_play_end": {"type": "number", "description": "last played cycle, loop s"},
            "causes": {"type": "array", "items": {"type": "string"}}},
        "required": ["t", "outcome"]})


def _check_out(value: Any) -> Path:
    from rt.output_files import check_output

    if not isinstance(value, str) or not value:
        raise InputError(f"{PROGRAM_NAME}: out must be the path of the recording to write")
    out = Path(value)
    if out.suffix != ".mcap":
        raise InputError(f"{PROGRAM_NAME}: out {out} must end in .mcap")
    path = check_output(out, what=f"{PROGRAM_NAME}: recording")   # never overwritten
    if not os.access(path.parent if str(path.parent) else ".", os.W_OK):
        raise InputError(f"{PROGRAM_NAME}: {path.parent} is not writable")
    return path


def identify_excitation(params: dict[str, Any], service: RtService) -> ExcitationProgram:
    """``run identify_excitation {excitation, duration_s, out, label}`` (module docstring)."""
    from rt.output_files import partial_path
    from rt.recording.writer import SessionRecorder

    allowed = {"excitation", "duration_s", "out", "label"}
    extra = sorted(set(params) - allowed)
    if extra:
        raise InputError(f"{PROGRAM_NAME}: unknown parameter(s) {extra}; allowed: "
                         f"{sorted(allowed)}")
    try:
        spec = ExcitationSpec.model_validate(params.get("excitation"))
    except ValidationError as err:
        raise InputError(f"{PROGRAM_NAME}: excitation: {validation_summary(err)}") from None
    exc = spec.excitation()
    duration = params.get("duration_s")
    if isinstance(duration, bool) or not isinstance(duration, (int, float)) \
            or not math.isfinite(duration) or not 1.0 <= duration <= MAX_DURATION_S:
        raise InputError(f"{PROGRAM_NAME}: duration_s must be a number in [1, "
                         f"{MAX_DURATION_S:g}] s, got {duration!r}")
    label = params.get("label", "excitation")
    if not isinstance(label, str) or not label.isidentifier() or len(label) > 32:
        raise InputError(f"{PROGRAM_NAME}: label must be a short identifier, got {label!r}")
    out = _check_out(params.get("out"))
    pl = service.pl
    dt = 1.0 / service.config.rate_hz
    table = excitation_table(exc, float(duration), dt)
    check_trajectory(table, pl.model.kin, pl.supervisor.limits, dt)
    program = ExcitationProgram(table, dt)
    description = pl.model.description
    truth = None if pl.twin is None else pl.twin.plant.description
    meta = {"protocol_name": f"identification-{label}", "protocol_version": 1,
            "parameters": {"excitation": spec.model_dump(), "duration_s": float(duration),
                           "label": label, "rate_hz": service.config.rate_hz,
                           "n_harmonics": N_HARMONICS},
            "patient_id": "none", "robot_description": description.name,
            "robot": description.model_dump(mode="json"),
            "twin_truth": None if truth is None else truth.model_dump(mode="json"),
            "rt": {"pid": os.getpid(), "backend": service.config.backend}}
    partial = partial_path(out)
    channel = _summary_channel()
    t_now = float(pl.loop.stats().t)
    recorder = SessionRecorder(partial, meta, loop_t0=t_now, force=True,
                               extra_channels={SUMMARY_TOPIC: channel})
    recorder.attach_state_ring(pl.recorder, start=pl.recorder.written)
    # The pump gives these for every cycle: talus.v4 joins them with the state.
    recorder.expect("/robot/wrench", "/protocol/reference")
    threading.Thread(target=_record, args=(service, program, recorder, partial, out,
                                           service.tap.written, pl.events.count),
                     name=f"identify-{label}", daemon=True).start()
    return program


def _record(service: RtService, program: ExcitationProgram, recorder: Any, partial: Path,
            out: Path, start: int, first_event: int) -> None:
    """Drain the session tap into the recording until the robot is back at rest (or stopped),
    then close it and move it to ``out``. Its own thread, never the loop's."""
    from rt.output_files import commit_output
    from rt.sessions import COL_PHASE, record_rows

    tap = service.tap
    pl = service.pl
    seen_motion = False
    outcome = "timeout"
    t_play: list[float] = []
    deadline = time.monotonic() + program.duration_s + END_MARGIN_S
    # The loop's event log holds every event: record those from this program on.
    recorded_events = first_event
    try:
        while time.monotonic() < deadline and not service.shutting_down.is_set():
            time.sleep(0.05)
            for ev in pl.events.snapshot():
                if ev.id > recorded_events:
                    recorder.event(ev.as_dict())
                    recorded_events = ev.id
            rows, start = tap.drain(start)
            if not len(rows):
                continue
            record_rows(recorder, rows)
            phases = rows[:, COL_PHASE]
            played = rows[phases == Phase.PLAY, 0]
            if len(played):
                t_play = [t_play[0] if t_play else float(played[0]), float(played[-1])]
            seen_motion, decided = program_outcome(phases, seen_motion)
            if decided is not None:
                outcome = decided
                if decided == "stopped":
                    time.sleep(STOP_EVENTS_SETTLE_S)   # the stop's events reach the log
                break
        for ev in pl.events.snapshot():
            if ev.id > recorded_events:
                recorder.event(ev.as_dict())
        summary: dict[str, Any] = {"t": float(pl.loop.stats().t), "outcome": outcome,
                                   "causes": sorted(pl.supervisor.causes)}
        if t_play:
            summary["t_play_start"], summary["t_play_end"] = t_play
        recorder.publish(SUMMARY_TOPIC, summary)
        recorder.close()
        commit_output(partial, out, force=False)
    except Exception:  # the thread must not die silently: the client waits for ``out``
        log.exception("identification recording %s failed", out)
        try:
            recorder.close()
        finally:
            partial.unlink(missing_ok=True)


def rt_programs() -> dict[str, Any]:
    """The identification programs the RT process offers (``talus.composition``)."""
    return {PROGRAM_NAME: identify_excitation}
