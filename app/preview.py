"""The reference a protocol will play, for Prescribe's preview plot (Qt-free; run it on a
worker thread: a long exercise takes a second or two to compute)."""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from protocols.generators import make_generator
from protocols.library import LIBRARY_DIR
from protocols.schema import validate_protocol_data
from rt.errors import ProtocolValidationError
from rt.model import RobotModel

#: Preview sample period, s (the plot needs no more; the RT process runs at the loop rate).
PREVIEW_DT_S = 0.01


@dataclass(frozen=True)
class Preview:
    """A reference over time: t (s), fz (N), roll and pitch (deg); ``violations`` from the
    generator's own validation (empty when it can be played)."""

    t: np.ndarray
    fz_n: np.ndarray
    roll_deg: np.ndarray
    pitch_deg: np.ndarray
    duration_s: float
    violations: tuple[str, ...]
    force_protocol: bool


@lru_cache(maxsize=1)
def _model() -> RobotModel:
    return RobotModel.load()


def compute_preview(document: dict[str, Any], weight_kg: float | None = None,
                    side: str = "right") -> Preview:
    """The reference of protocol ``document`` (as ``protocol_document`` gives it).

    Raises:
        ProtocolValidationError: the document or a file it names is invalid.
    """
    protocol = validate_protocol_data(copy.deepcopy(document), "preview")
    gen = make_generator(protocol, dt=PREVIEW_DT_S, kinematics=_model().kin,
                         patient_weight_kg=weight_kg, base_dir=LIBRARY_DIR, side=side)
    report = gen.validate()
    violations = tuple(getattr(report, "violations", ()) or ())
    if violations:
        return Preview(np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0), 0.0, violations,
                       False)
    samples = getattr(gen, "samples", None)
    if samples is None:
        # An interactive protocol (active assist) follows the patient: there is no reference
        # to draw ahead of time, only its duration.
        return Preview(np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0),
                       float(gen.duration_s), (), False)
    s = samples()
    pose = np.asarray(s["pose"])
    fz = np.asarray(s["fz"], dtype=float)
    t = np.asarray(s["t"], dtype=float)
    force = bool(np.any(np.abs(fz) > 1e-9))
    duration = float(t[-1]) if len(t) else 0.0
    if not math.isfinite(duration):
        raise ProtocolValidationError("preview: the reference is not finite")
    return Preview(t, fz, np.degrees(pose[:, 1]), np.degrees(pose[:, 2]), duration, (),
                   force)
