"""What a session report shows, as plain data, and how it is read from a recording.

:class:`SessionReportInput` is the seam between where a session comes from and the PDF: a
recording (:func:`session_input_from_recording`, streamed) or the clinical database (the
caller builds it from the session's row and, when the file exists, its recording: see
:func:`session_input_from_record`).

Reading a recording streams it once (``rt.recording.reader.RecordingScan``): the 1 kHz
channels ``/robot/state``, ``/robot/wrench`` and ``/protocol/reference`` are joined by loop
cycle into blocks of samples, which feed :class:`protocols.session_figures.SessionFigures`
(exact figures from every sample) and envelope decimators (plots). Memory stays bounded by
the channels' skew in the file (under a second as written) and the plot budget, whatever the
length. Truncated (crashed) recordings are read up to their last complete chunk and the report
says so; anything missing (metadata, summary, limits, a channel) becomes a note in the report.
"""
from __future__ import annotations

import hashlib
import math
import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from protocols.session_figures import (
    FORCE_KINDS,
    PHASE_BY_NAME,
    PHASE_UNKNOWN,
    Phase,
    SampleBlock,
    SessionFigures,
)
from reports.decimate import Envelope, EnvelopeDecimator
from reports.inputs import ReportInputError
from rt.recording.channels import ANKLE, CYCLE, EVENTS, METADATA, REFERENCE, STATE, WRENCH
from rt.recording.reader import RecordingScan

#: The lead's end-of-session message: the summary dict (incl. ``preflight``, ``stops``, ``rt``).
SUMMARY_TOPIC = "/session/summary"
#: Samples per block handed to the figures (≈ 4 s at 1 kHz).
BLOCK_SAMPLES = 4096
#: A channel with no message for this many cycles while the others go on is treated as having
#: a gap there (its values NaN) instead of being waited for: bounds memory on damaged files
#: (≈ 3 × 120 000 buffered rows, ≈ 60 MB, at worst).
MAX_SKEW_CYCLES = 120_000
#: Plot budget: buckets per decimated signal.
PLOT_BUCKETS = 1500

_STATE_FIELDS = ("q", "qd", "q_ref", "tau")


@dataclass
class RecordingRef:
    """Where the figures come from: file name, sha256 (hex), size, readable to the end."""

    path: str
    sha256: str
    bytes: int
    complete: bool
    tail: str | None = None
    messages: dict[str, int] = field(default_factory=dict)

    @property
    def file_name(self) -> str:
        return os.path.basename(self.path)


@dataclass
class SessionReportInput:
    """Everything a session report shows (plain data; SI units, angles in radians in series).

    ``metadata``: the recording's ``/protocol/metadata`` message (protocol, parameters,
    patient pseudonym, clinician, limits when recorded). ``summary``: the session summary
    written at the end (``/session/summary``) or kept by the database, None when absent.
    ``figures``: :meth:`SessionFigures.result` of the recording (None without a recording).
    ``series``: decimated signals for the plots (names below). ``events``: every safety event.
    ``notes``: what is missing or doubtful, in words, printed in the report.
    ``identity``: the patient's identifying data, only when the user may read it and asked
    (``--identify``); None otherwise.

    Series: ``force_n``, ``force_ref_n``, ``force_error_n`` (force-control samples only),
    ``roll``, ``pitch`` (rad), ``q0..q2``, ``q_ref0..q_ref2`` (m).
    """

    metadata: dict[str, Any]
    summary: dict[str, Any] | None
    figures: dict[str, Any] | None
    series: dict[str, Envelope]
    events: list[dict[str, Any]]
    recording: RecordingRef | None
    notes: list[str] = field(default_factory=list)
    session_id: str | None = None
    identity: dict[str, str] | None = None

    @property
    def limits(self) -> dict[str, Any] | None:
        """The patient's limits in force (PatientLimits dict), when recorded."""
        lim = self.metadata.get("limits")
        return lim if isinstance(lim, dict) else None


def file_sha256(path: str | os.PathLike[str]) -> str:
    """sha256 of a file (hex), read in 1 MiB pieces."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for piece in iter(lambda: f.read(1 << 20), b""):
            h.update(piece)
    return h.hexdigest()


# ------------------------------------------------------------------------------ joining

class _Column:
    """One channel's samples waiting to be joined, keyed by loop cycle."""

    def __init__(self) -> None:
        self.rows: dict[int, tuple[float, ...]] = {}
        self.last = -1          # highest cycle seen (messages arrive in time order per channel)
        self.seen = False


def _f(x: Any) -> float:
    return float(x) if isinstance(x, (int, float)) and not isinstance(x, bool) else math.nan


def _vec(x: Any, n: int = 3) -> tuple[float, ...]:
    if isinstance(x, list) and len(x) == n:
        return tuple(_f(v) for v in x)
    return (math.nan,) * n


class _Joiner:
    """Joins state, wrench and reference messages by cycle into :class:`SampleBlock` s."""

    def __init__(self, rate_hz: float, force_kind: bool):
        self.rate_hz = rate_hz
        self.force_kind = force_kind
        self.cols = {STATE: _Column(), WRENCH: _Column(), REFERENCE: _Column()}
        self.pending = 0
        self.prev_phase = PHASE_UNKNOWN

    def add(self, topic: str, m: dict[str, Any]) -> None:
        t = m.get("t")
        if not isinstance(t, (int, float)) or math.isnan(t):
            return
        k = round(t * self.rate_hz)
        col = self.cols[topic]
        row: tuple[Any, ...]
        if topic == STATE:
            # The fast path keeps the lists as decoded (None, a non-finite value, becomes NaN
            # when the block is built with dtype float); anything malformed goes the slow way.
            try:
                q, qd, q_ref, tau = m["q"], m["qd"], m["q_ref"], m["tau"]
                if len(q) != 3 or len(qd) != 3 or len(q_ref) != 3 or len(tau) != 3:
                    raise TypeError
                row = (t, *q, *qd, *q_ref, *tau)
            except (KeyError, TypeError):
                row = (t,) + sum((_vec(m.get(f)) for f in _STATE_FIELDS), ())
        elif topic == WRENCH:
            fz = m.get("fz")
            row = (-fz if isinstance(fz, (int, float)) else math.nan,)
        else:
            force = m.get("force")
            fz = _f(force[2]) if isinstance(force, list) and len(force) == 3 else math.nan
            phase = PHASE_BY_NAME.get(str(m.get("phase")), PHASE_UNKNOWN)
            mode = m.get("mode")
            row = (fz, float(phase), -1.0 if mode is None else float(mode == "force"))
        col.rows[k] = row
        col.last = max(col.last, k)
        col.seen = True
        self.pending += 1

    def ready(self, final: bool = False) -> Iterator[SampleBlock]:
        """Blocks of the cycles every channel has passed (all cycles when ``final``)."""
        state = self.cols[STATE]
        if not state.rows:
            return
        if final:
            upto = max(c.last for c in self.cols.values())
        else:
            lead = max(c.last for c in self.cols.values())
            upto = min((c.last if c.seen and c.last > lead - MAX_SKEW_CYCLES
                        else lead - MAX_SKEW_CYCLES) for c in self.cols.values())
        keys = sorted(k for k in state.rows if k <= upto)
        for i in range(0, len(keys), BLOCK_SAMPLES):
            yield self._block(keys[i:i + BLOCK_SAMPLES])
        # State rows up to the horizon are done; a wrench/reference row is done once the state
        # has passed its cycle (the writer may put the state ring's rows far behind the other
        # channels in the file: their rows wait for it, they are not dropped).
        done_state = upto
        done_others = keys[-1] if keys else -1
        for topic, col in self.cols.items():
            limit = done_state if topic == STATE else done_others
            for k in [k for k in col.rows if k <= limit]:
                del col.rows[k]
        self.pending = sum(len(c.rows) for c in self.cols.values())

    def _block(self, keys: list[int]) -> SampleBlock:
        n = len(keys)
        srows = self.cols[STATE].rows
        try:
            st = np.array([srows[k] for k in keys], dtype=float)
        except (TypeError, ValueError):       # a value that is not a number: NaN it
            st = np.array([[_f(v) for v in srows[k]] for k in keys], dtype=float)
        wr, rf = self.cols[WRENCH].rows, self.cols[REFERENCE].rows
        nan1, nan3 = (math.nan,), (math.nan, float(PHASE_UNKNOWN), 0.0)
        w = np.array([wr.get(k, nan1) for k in keys]).reshape(n)
        r = np.array([rf.get(k, nan3) for k in keys]).reshape(n, 3)
        phase = r[:, 1].astype(np.int64)
        # Recordings without the reference's ``mode``: a force kind is in force control from
        # its second play cycle on (the cycle that enters play still runs the approach).
        play = phase == Phase.PLAY
        prev_play = np.r_[self.prev_phase == Phase.PLAY, play[:-1]]
        inferred = self.force_kind & play & prev_play
        force_mode = np.where(r[:, 2] >= 0, r[:, 2] > 0.5, inferred)
        self.prev_phase = int(phase[-1])
        return SampleBlock(t=st[:, 0], phase=phase,
                           force_mode=force_mode, force_n=w, force_ref_n=r[:, 0],
                           q=st[:, 1:4], qd=st[:, 4:7], q_ref=st[:, 7:10], tau=st[:, 10:13])


# ------------------------------------------------------------------------------ reading

def _load_robot(robot: Any) -> Any:
    if robot is not None:
        return robot
    from rt.model import RobotModel
    return RobotModel.load()


class AnkleFigures:
    """The ankle in clinical terms from ``/ankle/state`` messages: angles reached per direction
    (deg from neutral), peak torques per direction (N·m, the foot's effort), the ankle centre's
    largest displacement (mm, horizontal and vertical)."""

    def __init__(self) -> None:
        self.n = 0
        self._lo = {"plantarflexion_deg": math.inf, "inversion_deg": math.inf,
                    "plantarflexion_torque_nm": math.inf, "inversion_torque_nm": math.inf}
        self._hi = {k: -math.inf for k in self._lo}
        self._horizontal_mm = 0.0
        self._vertical_mm = 0.0

    def add(self, m: dict[str, Any]) -> None:
        for k in self._lo:
            v = m.get(k)
            if isinstance(v, (int, float)) and math.isfinite(v):
                self._lo[k] = min(self._lo[k], float(v))
                self._hi[k] = max(self._hi[k], float(v))
        d = m.get("centre_displacement_mm")
        if isinstance(d, list) and len(d) == 3 and all(isinstance(x, (int, float)) for x in d):
            self._horizontal_mm = max(self._horizontal_mm, math.hypot(d[0], d[1]))
            self._vertical_mm = max(self._vertical_mm, abs(d[2]))
        self.n += 1

    def result(self) -> dict[str, Any] | None:
        if not self.n:
            return None
        lo, hi = self._lo, self._hi

        def pos(x: float) -> float | None:
            return max(x, 0.0) if math.isfinite(x) else None

        return {"rom_deg": {"dorsiflexion": pos(-lo["plantarflexion_deg"]),
                            "plantarflexion": pos(hi["plantarflexion_deg"]),
                            "inversion": pos(hi["inversion_deg"]),
                            "eversion": pos(-lo["inversion_deg"])},
                "peak_torque_nm": {"dorsiflexion": pos(-lo["plantarflexion_torque_nm"]),
                                   "plantarflexion": pos(hi["plantarflexion_torque_nm"]),
                                   "inversion": pos(hi["inversion_torque_nm"]),
                                   "eversion": pos(-lo["inversion_torque_nm"])},
                "centre_displacement_mm": {"horizontal": self._horizontal_mm,
                                           "vertical": self._vertical_mm},
                "messages": self.n}


def session_input_from_recording(path: str | os.PathLike[str], robot: Any = None,
                                 session_id: str | None = None) -> SessionReportInput:
    """Read a session recording (complete or truncated) for its report, in one pass.

    Args:
        path: the ``.mcap`` file.
        robot: the ``RobotModel`` the session ran with (default: the nominal description).
        session_id: the database's id of the session, when known.

    Raises:
        ReportInputError: the file does not exist, is not an MCAP recording, or holds no
            session (no robot state at all).
    """
    from rt.recording.reader import RecordingFileError

    path = Path(path)
    if not path.is_file():
        raise ReportInputError(f"{path}: no such recording")
    notes: list[str] = []
    model = _load_robot(robot)
    scan = RecordingScan(path, topics=[STATE, WRENCH, REFERENCE, EVENTS, METADATA,
                                       SUMMARY_TOPIC, ANKLE])
    ankle = AnkleFigures()
    it = iter(scan)
    # The metadata is the file's first message: it says the kind, which sets the figures.
    metadata: dict[str, Any] = {}
    summary: dict[str, Any] | None = None
    events: list[dict[str, Any]] = []
    buffered: list[tuple[str, Any]] = []
    try:
        for rec in it:
            if rec.topic == METADATA:
                metadata = rec.payload if isinstance(rec.payload, dict) else {}
                break
            buffered.append((rec.topic, rec.payload))
            if len(buffered) > 10_000:
                break
    except RecordingFileError as exc:
        raise ReportInputError(str(exc)) from exc
    if not metadata:
        notes.append("The recording holds no session metadata (protocol, parameters, patient): "
                     "those fields are shown as unknown.")
    raw_params = metadata.get("parameters")
    params: dict[str, Any] = raw_params if isinstance(raw_params, dict) else {}
    kind = str(params.get("kind", "unknown"))
    amplitude = params.get("amplitude_n")
    rate_hz = 1000.0
    for ch in scan.channels.values():
        # talus.v4 records the state inside /robot/cycle, whose metadata carries the rate.
        if ch.topic in (STATE, CYCLE) and "rate_hz" in ch.metadata:
            try:
                rate_hz = float(ch.metadata["rate_hz"])
            except ValueError:
                notes.append(f"/robot/state declares rate_hz {ch.metadata['rate_hz']!r}; "
                             "1000 Hz assumed.")
    preload = metadata.get("preload_n", 0.0)
    figures = SessionFigures(model.kin, kind, float(amplitude) if isinstance(
        amplitude, (int, float)) else None, rate_hz=rate_hz,
        preload_n=float(preload) if isinstance(preload, (int, float)) else 0.0)
    joiner = _Joiner(rate_hz, kind in FORCE_KINDS)
    width = 1.0 / rate_hz
    dec = {name: EnvelopeDecimator(PLOT_BUCKETS, width) for name in (
        "force_n", "force_ref_n", "force_error_n", "roll", "pitch",
        "q0", "q1", "q2", "q_ref0", "q_ref1", "q_ref2")}

    def consume(block: SampleBlock) -> None:
        angles = figures.add(block)
        t = block.t
        dec["force_n"].add(t, block.force_n)
        ref = np.where(block.force_mode, block.force_ref_n, np.nan)
        dec["force_ref_n"].add(t, ref)
        dec["force_error_n"].add(t, ref - block.force_n)
        for i in range(3):
            dec[f"q{i}"].add(t, block.q[:, i])
            dec[f"q_ref{i}"].add(t, block.q_ref[:, i])
        dec["roll"].add(angles.t, angles.roll)
        dec["pitch"].add(angles.t, angles.pitch)

    def handle(topic: str, payload: Any) -> None:
        nonlocal summary
        if not isinstance(payload, dict):
            return
        if topic in joiner.cols:
            joiner.add(topic, payload)
        elif topic == EVENTS:
            events.append(payload)
        elif topic == SUMMARY_TOPIC:
            summary = payload
        elif topic == ANKLE:
            ankle.add(payload)

    def flush(final: bool = False) -> None:
        for block in joiner.ready(final):
            consume(block)

    try:
        for topic, payload in buffered:
            handle(topic, payload)
        # Join every BLOCK_SAMPLES new rows: the cost of a join is the rows pending, so this
        # keeps reading linear even when a channel lags far behind the others in the file.
        next_join = BLOCK_SAMPLES
        for rec in it:
            handle(rec.topic, rec.payload)
            if joiner.pending >= next_join:
                flush()
                next_join = joiner.pending + BLOCK_SAMPLES
    except RecordingFileError as exc:
        raise ReportInputError(str(exc)) from exc
    flush(final=True)
    info = scan.info
    if figures.samples == 0:
        raise ReportInputError(f"{path}: the recording holds no robot state (/robot/state is "
                               f"{'empty' if info.messages.get(STATE) is not None else 'absent'}"
                               "): there is no session to report")
    result = figures.result(events)
    if ankle.n:
        result["ankle"] = ankle.result()
    if not info.complete:
        notes.append(f"The recording is incomplete ({info.tail}): its writer did not finish. "
                     f"Figures cover the {result['duration_s']:.1f} s that could be read "
                     "(up to the last complete chunk).")
    for topic, what in ((WRENCH, "force measurements"), (REFERENCE, "protocol reference")):
        if not info.messages.get(topic):
            notes.append(f"The recording has no {what} ({topic}): force figures and phases "
                         "are missing.")
    if summary is None:
        notes.append("The recording has no session summary (/session/summary): pre-flight "
                     "predictions and the controller's own figures are not available; every "
                     "figure here is computed from the recording.")
    for key, what in (("limits", "the patient's limits in force"),
                      ("clinician", "the clinician")):
        if key not in metadata:
            notes.append(f"The recording does not say {what}.")
    if result["fk_failures"]:
        notes.append(f"Platform angles could not be computed for {result['fk_failures']} "
                     "samples (forward kinematics failed there).")
    ref = RecordingRef(str(path), file_sha256(path), info.file_bytes, info.complete, info.tail,
                       dict(info.messages))
    series = {name: d.envelope() for name, d in dec.items()}
    return SessionReportInput(metadata=metadata, summary=summary, figures=result,
                              series=series, events=events, recording=ref, notes=notes,
                              session_id=session_id)


def session_input_from_record(session: dict[str, Any], recording: str | os.PathLike[str] | None,
                              robot: Any = None) -> SessionReportInput:
    """The seam for the clinical database: a session's row as plain data (+ its recording).

    ``session`` holds what the database keeps: ``id``, ``metadata`` (protocol_name,
    parameters, patient_id, clinician, limits ...), ``summary`` (the session summary dict) and
    ``recording_sha256`` (the hash stored with the record). With a readable recording the
    report is built from it (and its hash checked against the record); without one, from the
    stored summary alone, and the report says the recording is missing.
    """
    sid = str(session.get("id")) if session.get("id") is not None else None
    stored_hash = session.get("recording_sha256")
    if recording is not None and Path(recording).is_file():
        inp = session_input_from_recording(recording, robot, sid)
        for key, value in (session.get("metadata") or {}).items():
            inp.metadata.setdefault(key, value)
        if inp.summary is None and isinstance(session.get("summary"), dict):
            inp.summary = session["summary"]
            inp.notes = [n for n in inp.notes if "/session/summary" not in n]
        if stored_hash and inp.recording is not None and inp.recording.sha256 != stored_hash:
            got, want = inp.recording.sha256[:16], str(stored_hash)[:16]
            inp.notes.insert(0, f"The recording's sha256 ({got}…) differs from the one stored "
                                f"with the session ({want}…): the file is not the one recorded.")
        return inp
    summary = session.get("summary") if isinstance(session.get("summary"), dict) else None
    if summary is None:
        raise ReportInputError(f"session {sid}: neither a recording nor a stored summary: "
                               "nothing to report")
    where = f" ({recording})" if recording is not None else ""
    notes = [(f"The session's recording is missing{where}: plots are not available and the "
             "figures are the session summary's as stored.")]
    return SessionReportInput(metadata=dict(session.get("metadata") or {}), summary=summary,
                              figures=None, series={}, events=list(summary.get("stops", [])),
                              recording=None, notes=notes, session_id=sid)
