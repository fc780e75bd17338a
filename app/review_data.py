"""A past session's curves from its recording (Qt-free; run it on a worker thread).

Recordings hold the 1 kHz loop state in joint space; the platform angles are computed here by
forward kinematics at :data:`REVIEW_RATE_HZ` (plots need no more). Stops are the recorded
safety events with a reaction of soft stop or worse, marked on the time axis. A session run with
the patient's ankle setup also has ``/ankle/state`` (100 Hz): the foot's angles from neutral
and the torques about the ankle centre in clinical terms, which a clinician reads instead of
the platform's roll and pitch (kept for engineers).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rt.errors import KinematicsError
from rt.recording.channels import ANKLE, EVENTS, METADATA, REFERENCE, STATE, WRENCH
from rt.recording.reader import TruncatedRecordingError, read_recording, recover

#: Rate of the reviewed curves, Hz.
REVIEW_RATE_HZ = 100.0
_STOP_REACTIONS = ("soft_stop", "hard_stop")


@dataclass
class ReviewData:
    """Curves on one time axis starting at the first state sample (s); angles in degrees."""

    path: str
    complete: bool
    t: np.ndarray
    roll_deg: np.ndarray
    pitch_deg: np.ndarray
    t_force: np.ndarray
    force_n: np.ndarray
    t_ref: np.ndarray
    force_ref_n: np.ndarray
    stops: list[tuple[float, str, dict[str, Any]]] = field(default_factory=list)
    metadata: dict[str, Any] = field(default_factory=dict)
    #: ``/ankle/state`` on the same time axis (empty without an ankle setup): plantarflexion
    #: (+) / dorsiflexion (−) and inversion (+) / eversion (−) in degrees, their torques N·m.
    t_ankle: np.ndarray = field(default_factory=lambda: np.zeros(0))
    plantarflexion_deg: np.ndarray = field(default_factory=lambda: np.zeros(0))
    inversion_deg: np.ndarray = field(default_factory=lambda: np.zeros(0))
    plantarflexion_torque_nm: np.ndarray = field(default_factory=lambda: np.zeros(0))
    inversion_torque_nm: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def has_ankle(self) -> bool:
        return len(self.t_ankle) > 0


def _every(rows: list[dict[str, Any]], rate_hz: float) -> list[dict[str, Any]]:
    if len(rows) < 2:
        return rows
    span = float(rows[-1]["t"]) - float(rows[0]["t"])
    native = (len(rows) - 1) / span if span > 0 else rate_hz
    step = max(1, round(native / rate_hz))
    return rows[::step]


def recording_protocol_name(path: str | Path) -> str | None:
    """The protocol's name as the recording's metadata holds it (the file name carries only a
    filesystem-safe form of it: "300 ± 100 N" became "300---100-N"); None when the file holds
    no readable metadata.

    Raises:
        RecordingFileError: not a readable recording (the message names the file).
    """
    try:
        data = read_recording(path, [METADATA])
    except TruncatedRecordingError:
        data, _ = recover(path, [METADATA])
    meta = (data.get(METADATA) or [{}])[0]
    name = meta.get("protocol_name")
    return name if isinstance(name, str) and name.strip() else None


def load_review(path: str | Path, model: Any | None = None) -> ReviewData:
    """Read recording ``path`` (complete, or recovered up to its last whole chunk).

    Raises:
        RecordingFileError: not a readable recording (the message names the file).
    """
    topics = [STATE, WRENCH, EVENTS, METADATA, REFERENCE, ANKLE]
    try:
        data, complete = read_recording(path, topics), True
    except TruncatedRecordingError:
        data, _ = recover(path, topics)
        complete = False
    if model is None:
        from rt.model import RobotModel
        model = RobotModel.load()
    states = _every(data.get(STATE, []), REVIEW_RATE_HZ)
    t0 = float(states[0]["t"]) if states else 0.0
    t, roll, pitch = [], [], []
    for s in states:
        try:
            cfg = model.kin.fk(s["q"], check=False)   # warm-started from the previous sample
        except KinematicsError:   # a sample that does not assemble is a gap in the curve
            t.append(float(s["t"]) - t0)
            roll.append(math.nan)
            pitch.append(math.nan)
            continue
        t.append(float(s["t"]) - t0)
        roll.append(math.degrees(cfg.roll))
        pitch.append(math.degrees(cfg.pitch))
    wrench = _every(data.get(WRENCH, []), REVIEW_RATE_HZ)
    ref = _every([r for r in data.get(REFERENCE, []) if r.get("force")], REVIEW_RATE_HZ)
    stops = [(float(e["t"]) - t0, str(e.get("cause", "")), e) for e in data.get(EVENTS, [])
             if e.get("reaction") in _STOP_REACTIONS]
    meta = (data.get(METADATA) or [{}])[0]
    ankle = data.get(ANKLE, [])

    def column(key: str) -> np.ndarray:
        return np.array([float(a[key]) for a in ankle])
    review = ReviewData(
        str(path), complete, np.array(t), np.array(roll), np.array(pitch),
        np.array([float(w["t"]) - t0 for w in wrench]),
        np.array([-float(w["fz"]) for w in wrench]),   # the platform pushes up: F = −fz
        np.array([float(r["t"]) - t0 for r in ref]),
        np.array([float(r["force"][-1]) for r in ref]),
        stops, meta)
    if ankle:
        review.t_ankle = np.array([float(a["t"]) - t0 for a in ankle])
        review.plantarflexion_deg = column("plantarflexion_deg")
        review.inversion_deg = column("inversion_deg")
        review.plantarflexion_torque_nm = column("plantarflexion_torque_nm")
        review.inversion_torque_nm = column("inversion_torque_nm")
    return review
