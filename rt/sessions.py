"""Sessions in the RT process: what the RT process needs from whoever implements protocols.

The RT process (``rt.service``) owns the loop, the recording and the session's life; it does
not know what a protocol is. At the entry point (``talus.composition``) it is given a
:class:`SessionFactory` — the protocols package's — that turns a ``session_start`` request into
a :class:`PreparedSession`: a validated program, the pre-flight's prediction, the recording's
metadata and a figures accumulator that computes the summary while the session runs (an hour at
1 kHz is never held in memory).

The loop carries one :class:`~rt.components.blocks.SignalTap` with the session's signals
(:data:`SESSION_SIGNALS`); its rows are what the accumulator and the recorder's wrench and
reference channels are fed with.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from rt.model import RobotModel
from rt.model.ankle import AnkleMonitor, AnkleSetup
from rt.references.program import Program
from rt.safety.events import SafetyEvent
from rt.safety.limits import PatientLimits, ProtocolLimits, RobotLimits

#: The session tap's signals (after its time column), each (loop port name, width).
SESSION_SIGNALS: list[tuple[str, int]] = [
    ("q", 3), ("qd", 3), ("tau", 3), ("volts", 3), ("wrench", 6), ("flags", 2), ("force", 3),
    ("ctrl_mode", 1), ("phase", 1), ("progress", 1), ("tare", 10)]
#: Where each signal comes from in the loop.
SESSION_SOURCES: dict[str, str] = {
    "q": "encoders.q", "qd": "estimator.qd", "tau": "controller.tau",
    "volts": "supervisor.volts", "wrench": "force.wrench",
    "flags": "force.flags", "force": "reference.force", "ctrl_mode": "reference.ctrl_mode",
    "phase": "reference.phase", "progress": "reference.progress",
    # The ATI's tare at a force program's start (rt.components.tare): state, count, refusal,
    # mean force, offset.
    "tare": "force.tare"}


def _columns() -> dict[str, slice]:
    cols, k = {}, 1
    for name, width in SESSION_SIGNALS:
        cols[name] = slice(k, k + width)
        k += width
    return cols


#: Column slices of a session-tap row by signal name (column 0 is the loop time, s).
COLUMNS: dict[str, slice] = _columns()
#: Single columns used per sample: Fz measured (sensor frame), F_d, control mode, phase.
COL_FZ = COLUMNS["wrench"].start + 2
COL_FREF = COLUMNS["force"].start
COL_CTRL_MODE = COLUMNS["ctrl_mode"].start
COL_PHASE = COLUMNS["phase"].start
COL_PROGRESS = COLUMNS["progress"].start
COL_TARE = COLUMNS["tare"].start


@dataclass(frozen=True)
class PatientInfo:
    """The patient as the RT process sees it: a pseudonymous code, never identifying data."""

    id: str
    weight_kg: float | None = None
    limits: PatientLimits = field(default_factory=PatientLimits)
    #: Where the patient's ankle centre is on the platform (None: not entered); ankle
    #: exercises then turn the foot about it (``rt.model.ankle``).
    ankle: AnkleSetup | None = None


@dataclass(frozen=True)
class SessionContext:
    """What the factory may use to prepare a session: the robot the RT process drives, its
    limits, the loop rate, and whether the backend is the twin (``twin``)."""

    model: RobotModel
    robot_limits: RobotLimits
    rate_hz: float
    twin: bool


class SessionFigures(Protocol):
    """Accumulates a session's figures from the session tap's rows, as they are drained."""

    def add(self, rows: np.ndarray) -> None: ...

    def result(self, events: list[SafetyEvent]) -> dict[str, Any]:
        """The summary (today's shape: protocol, kind, rms_error_pct, peak_force_n, rom_deg,
        stops, completed ...), the stops taken from ``events``."""
        ...


class PreparedSession(Protocol):
    """A session ready to run: validated, pre-flighted on the twin, not started."""

    name: str
    kind: str
    program: Program
    protocol_limits: ProtocolLimits | None
    #: Recording metadata (JSON-able): protocol, parameters, traceability of data files.
    metadata: dict[str, Any]
    #: The pre-flight's predicted peaks (JSON-able).
    preflight: dict[str, Any]
    #: Platform pose (z m, roll rad, pitch rad) where the program starts: on the twin, the
    #: patient's foot is placed there, unloaded, before the approach.
    start_pose: tuple[float, float, float]

    def figures(self, preload_n: float) -> SessionFigures:
        """A fresh accumulator; ``preload_n`` is the force law's floor (N) in this loop."""
        ...


class SessionFactory(Protocol):
    """Turns a ``session_start`` request into a prepared session, or refuses it.

    ``prepare`` runs on a worker thread of the RT process (pre-flight takes seconds); it raises
    :class:`rt.errors.TalusError` (e.g. ``ProtocolValidationError``) with the reason to refuse.
    """

    def prepare(self, protocol: dict[str, Any], patient: PatientInfo,
                context: SessionContext) -> PreparedSession: ...


def recording_name(started_utc: str, patient_id: str, protocol_name: str) -> str:
    """The recording's file stem: ``20261123T172130Z_P-001_sine-fz`` (no characters a file
    system or a shell would mind)."""
    safe = "".join(c if c.isalnum() or c in "-." else "-" for c in protocol_name)[:48]
    stamp = started_utc.replace("-", "").replace(":", "").split(".")[0]
    return f"{stamp}_{patient_id}_{safe or 'session'}"


def unique_path(directory: Path, stem: str, suffix: str = ".mcap") -> Path:
    """``directory/stem.suffix``, or ``stem-2``, ``stem-3`` ... — a name no file has (the
    caller creates it with O_EXCL, so two sessions never share one)."""
    candidate = directory / f"{stem}{suffix}"
    n = 2
    while candidate.exists():
        candidate = directory / f"{stem}-{n}{suffix}"
        n += 1
    return candidate


def record_rows(recorder: Any, rows: np.ndarray, ankle: AnkleMonitor | None = None) -> None:
    """Session-tap rows → the recorder's ``/robot/wrench`` and ``/protocol/reference``
    channels, and ``/ankle/state`` with an ``ankle`` monitor (non-real-time; the recorder's
    methods only enqueue).

    The rows go as two blocks (``wrench_rows``, ``reference_rows``), encoded by the recorder's
    thread with numpy: this runs in a thread of the RT process, which shares the GIL with the
    loop, so it costs tens of µs per drained block instead of ≈ 10 µs per row."""
    from rt.references.sequencer import Phase

    if not len(rows):
        return
    wait = getattr(recorder, "wait_for_room", None)
    if wait is not None:
        wait()    # a fast twin run outpaces the writer: wait rather than drop
    w = COLUMNS["wrench"]
    flags = COLUMNS["flags"]
    t = rows[:, 0]
    recorder.wrench_rows(np.column_stack([t, rows[:, w], rows[:, flags] > 0.5]))
    force = np.zeros((len(rows), 3))
    force[:, 2] = rows[:, COL_FREF]
    if not _PHASE_NAMES:
        _PHASE_NAMES.update({int(p): p.name.lower() for p in Phase})
    names = _PHASE_NAMES
    phase = [names[c] for c in rows[:, COL_PHASE].astype(int).tolist()]
    mode = ["force" if m else "position" for m in (rows[:, COL_CTRL_MODE] > 0.5).tolist()]
    recorder.reference_rows(t, force, phase, mode)
    if ankle is not None:
        qc = COLUMNS["q"]
        for r in rows:
            tr = float(r[0])
            if ankle.due(tr):
                msg = ankle.message(tr, r[qc], r[w])
                if msg is not None:
                    recorder.publish("/ankle/state", msg)


#: Phase code → recorded name (filled on first use: the sequencer imports late).
_PHASE_NAMES: dict[int, str] = {}
