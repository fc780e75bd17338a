"""Live telemetry for the Run page, decoded off the GUI thread (Qt-free; tested without Qt).

The link's subscriber thread pushes every published sample into a :class:`TelemetryRing`: a
preallocated numpy array of the plotted columns (SI: s, N, rad), written in place, so the GUI
thread's frame costs one small copy (:meth:`TelemetryRing.snapshot`) and ``setData`` per curve,
never per-sample Python work or a growing list. The same thread counts repetitions
(:class:`RepetitionCounter`) of range-of-motion and active-assist exercises from the measured
platform angles while the reference is in its ``play`` phase.

During an exercise about the patient's ankle the RT process also publishes the ankle's state in
clinical terms (:func:`ankle_state`: angles from the neutral pose, torques about the ankle
centre, the centre's displacement); they fill the ``ankle_*`` columns (SI: rad, N·m, m), NaN
in samples without them, so the Run page shows the ankle view only while they arrive. Two
shapes are read: the sample's ``ankle`` object (the RT process's last ``/ankle/state`` message,
``rt.model.ankle.AnkleMonitor``) or flat ``ankle_*`` fields (:data:`ANKLE_FIELDS`).
"""
from __future__ import annotations

import math
import threading
from dataclasses import dataclass, field
from typing import Any

import numpy as np

#: The ankle's live state: ring column → (flat telemetry field, the ``ankle`` object's field
#: as ``/ankle/state`` names it, factor to SI). Signs of ``rt.model.ankle``: plantarflexion,
#: inversion and their efforts positive; the displacement is the centre's horizontal one
#: from where it was at the neutral pose (its x, y, z in mm, or its horizontal size).
ANKLE_FIELDS = {
    "ankle_dfpf": ("ankle_dfpf_deg", "plantarflexion_deg", math.pi / 180.0),
    "ankle_inev": ("ankle_inev_deg", "inversion_deg", math.pi / 180.0),
    "ankle_torque_dfpf": ("ankle_torque_dfpf_nm", "plantarflexion_torque_nm", 1.0),
    "ankle_torque_inev": ("ankle_torque_inev_nm", "inversion_torque_nm", 1.0),
    "ankle_displacement": ("ankle_centre_displacement_mm", "centre_displacement_mm", 1e-3)}
#: The ring's columns, in order (SI units: s, N, rad, N·m, m; progress 0..1).
COLUMNS = ("t", "force_ref", "force", "roll", "pitch", "roll_ref", "pitch_ref", "progress",
           *ANKLE_FIELDS)
_COL = {name: i for i, name in enumerate(COLUMNS)}
#: A repetition's end counts when the angle passes this share of the prescribed amplitude
#: (half: a patient who reaches half their range did the movement; noise near neutral does not).
REACH_SHARE = 0.5
#: With one end at neutral, the neutral end counts within this share of the other end's amplitude.
NEUTRAL_SHARE = 0.25


def _f(x: Any) -> float:
    """A float, NaN for a missing value (None, or a malformed field)."""
    try:
        return math.nan if x is None else float(x)
    except (TypeError, ValueError):
        return math.nan


def horizontal(x: Any) -> float:
    """A displacement's horizontal size (what pre-flight's comfort limit bounds,
    ``rt.model.ankle``): the value itself, or the norm of a vector's x and y (the ankle
    centre's displacement comes as its x, y, z); NaN when missing or malformed."""
    if isinstance(x, (list, tuple)):
        parts = [_f(v) for v in x[:2]]
        return math.hypot(*parts) if len(parts) == 2 else math.nan
    return _f(x)


def ankle_state(msg: dict[str, Any]) -> dict[str, float]:
    """The sample's ankle state in clinical units (column → deg, N·m, mm: the displacement's
    size), NaN for what it lacks (:data:`ANKLE_FIELDS`)."""
    nested = msg.get("ankle")
    nested = nested if isinstance(nested, dict) else {}
    out = {}
    for column, (flat, name, _factor) in ANKLE_FIELDS.items():
        x = msg[flat] if flat in msg else nested.get(name)
        out[column] = horizontal(x) if column == "ankle_displacement" else _f(x)
    return out


def _band(extent_neg: float, extent_pos: float) -> tuple[float, float]:
    """(low, high) thresholds for an axis moved ``extent_neg`` below and ``extent_pos`` above
    neutral (degrees, both ≥ 0)."""
    hi = REACH_SHARE * extent_pos if extent_pos > 0 else -NEUTRAL_SHARE * extent_neg
    lo = -REACH_SHARE * extent_neg if extent_neg > 0 else NEUTRAL_SHARE * extent_pos
    return lo, hi


@dataclass
class _Axis:
    """One axis' repetition state. The angle's zones are "low" (≤ lo) and "high" (≥ hi); a
    repetition is two zone entries (one visit to each end: neutral → end → other end →
    neutral, or one period of a back-and-forth guide). Re-entering the zone last visited, e.g.
    wobbling at an end, is not an entry."""

    column: str
    lo_deg: float
    hi_deg: float
    last_zone: int = 0          # -1 low, +1 high, 0 none yet
    entries: int = 0

    @property
    def count(self) -> int:
        return self.entries // 2

    def feed(self, angle_deg: float) -> None:
        if math.isnan(angle_deg):
            return
        zone = -1 if angle_deg <= self.lo_deg else 1 if angle_deg >= self.hi_deg else 0
        if zone and zone != self.last_zone:
            self.last_zone = zone
            self.entries += 1


@dataclass
class RepetitionCounter:
    """Counts repetitions of an exercise from measured platform angles (degrees).

    ``axes`` maps a ring column (``pitch``/``roll``) to its (low, high) thresholds; a
    repetition on an axis is a visit to each threshold's side, in either order. ``expected``
    is the prescribed count (None when the protocol does not fix one).
    """

    axes: dict[str, tuple[float, float]]
    expected: int | None = None
    _state: list[_Axis] = field(default_factory=list, repr=False)

    def __post_init__(self) -> None:
        self._state = [_Axis(col, lo, hi) for col, (lo, hi) in self.axes.items()]

    @classmethod
    def for_protocol(cls, document: dict[str, Any]) -> RepetitionCounter | None:
        """The counter for a protocol document, None for kinds without repetitions (force
        protocols, holds, playback).

        ``ankle_rom``: ``dorsi_plantar`` and ``circuit`` count on pitch (plantarflexion is
        +pitch, dorsiflexion −pitch), ``inversion_eversion`` on roll (its sign depends on the
        foot: the smaller of the two amplitudes on both sides), ``repetitions`` per item.
        ``active_assist``: one repetition per guide period on the first axis.
        """
        kind = document.get("kind")
        if kind == "ankle_rom":
            amp = document.get("amplitude_deg") or {}
            seq = list(document.get("sequence") or [])
            reps = int(document.get("repetitions") or 1)
        elif kind == "active_assist":
            amp = document.get("rom_deg") or {}
            seq = list(document.get("axes") or [])[:1]
            period = _f(document.get("guide_period_s"))
            duration = _f(document.get("duration_s"))
            reps = int(duration // period) if period > 0 and duration > 0 else 0
        else:
            return None

        def extent(name: str) -> float:
            v = _f(amp.get(name))
            return 0.0 if math.isnan(v) else abs(v)
        axes: dict[str, tuple[float, float]] = {}
        pitch_items = sum(1 for s in seq if s in ("dorsi_plantar", "circuit"))
        roll_items = sum(1 for s in seq if s == "inversion_eversion")
        if pitch_items:
            axes["pitch"] = _band(extent("dorsiflexion"), extent("plantarflexion"))
        if roll_items and "circuit" not in seq:   # a circuit's roll swing is not a repetition
            side = min(extent("inversion"), extent("eversion")) or \
                max(extent("inversion"), extent("eversion"))
            axes["roll"] = _band(side, side)
        if not axes:
            return None
        expected = reps * (pitch_items + (roll_items if "roll" in axes else 0)) \
            if kind == "ankle_rom" else reps
        return cls(axes, expected or None)

    @property
    def count(self) -> int:
        return sum(a.count for a in self._state)

    def feed(self, pitch_deg: float, roll_deg: float) -> None:
        for a in self._state:
            a.feed(pitch_deg if a.column == "pitch" else roll_deg)


class TelemetryRing:
    """The last ``capacity`` telemetry samples as numpy columns, written by the subscriber
    thread, read by the GUI thread at the frame rate (thread-safe)."""

    def __init__(self, capacity: int) -> None:
        if capacity < 2:
            raise ValueError(f"telemetry ring capacity {capacity}: at least 2 samples")
        self.capacity = capacity
        self._data = np.full((capacity, len(COLUMNS)), math.nan)
        self._written = 0
        self._lock = threading.Lock()
        self._latest: dict[str, Any] | None = None
        self._session: str | None = None
        self._counter: RepetitionCounter | None = None

    @property
    def written(self) -> int:
        """Samples pushed since the last :meth:`clear` (a frame with no new sample is skipped)."""
        return self._written

    @property
    def latest(self) -> dict[str, Any] | None:
        """The last sample as published (phase, progress, session, ...)."""
        return self._latest

    def push(self, msg: dict[str, Any]) -> None:
        """Decode one published sample into the ring (subscriber thread)."""
        pose: list[Any] = list(msg.get("pose") or ())
        ref: list[Any] = list(msg.get("pose_ref") or ())
        row = (_f(msg.get("t")), _f(msg.get("force_ref_n")), _f(msg.get("force_n")),
               _f(pose[1]) if len(pose) > 2 else math.nan,
               _f(pose[2]) if len(pose) > 2 else math.nan,
               _f(ref[1]) if len(ref) > 2 else math.nan,
               _f(ref[2]) if len(ref) > 2 else math.nan,
               _f(msg.get("progress")),
               *(value * ANKLE_FIELDS[column][2]
                 for column, value in ankle_state(msg).items()))
        with self._lock:
            self._data[self._written % self.capacity] = row
            self._written += 1
            self._latest = msg
            counter = self._counter
            if counter is not None and msg.get("session") == self._session \
                    and msg.get("phase") == "play":
                # The ankle's angles from neutral when the telemetry has them (the prescribed
                # amplitudes are from neutral), else the platform's.
                pitch, roll = row[_COL["ankle_dfpf"]], row[_COL["ankle_inev"]]
                if math.isnan(pitch) or math.isnan(roll):
                    pitch, roll = row[_COL["pitch"]], row[_COL["roll"]]
                counter.feed(math.degrees(pitch), math.degrees(roll))

    def snapshot(self) -> tuple[int, dict[str, np.ndarray]]:
        """(samples written, each column oldest first) — copies, safe to keep and draw."""
        with self._lock:
            n, cap = self._written, self.capacity
            if n <= cap:
                block = self._data[:n].copy()
            else:
                i = n % cap
                block = np.concatenate((self._data[i:], self._data[:i]))
        return n, {name: block[:, j] for j, name in enumerate(COLUMNS)}

    def clear(self) -> None:
        with self._lock:
            self._data.fill(math.nan)
            self._written = 0

    def count_repetitions(self, session: str | None,
                          counter: RepetitionCounter | None) -> None:
        """Count with ``counter`` from now on, on samples of ``session`` only (None: stop)."""
        with self._lock:
            self._session, self._counter = session, counter

    def repetitions(self) -> tuple[int, int | None] | None:
        """(counted, expected) of the current count, None when nothing is counted."""
        with self._lock:
            c = self._counter
            return None if c is None else (c.count, c.expected)
