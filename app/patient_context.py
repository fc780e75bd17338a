"""The patient the GUI is working for (Qt-free): pseudonymous code, body mass, the limits in
force and who set them, where the ankle centre sits. What ``session_start``/``session_preflight`` send as ``patient``.
Identifying data never goes here: the RT process and the recordings only see the code."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from rt.safety.limits import PatientLimits


@dataclass(frozen=True)
class PatientContext:
    """One patient as the session pages need it.

    Attributes:
        code: pseudonymous patient code.
        weight_kg: body mass, kg (gait replay scales to it); None when not recorded.
        limits: ``PatientLimits`` fields in force (degrees, N, deg/s).
        limits_set_by: who set the limits, and when (shown next to them).
        side: the affected foot ("right" or "left").
        ankle: the ankle setup in force (``rt.model.ankle.AnkleSetup`` fields, m), None when
            none was entered (the exercise then turns about the platform's centre).
    """

    code: str
    weight_kg: float | None = None
    limits: dict[str, float] = field(default_factory=dict)
    limits_set_by: str | None = None
    side: str = "right"
    ankle: dict[str, Any] | None = None

    def patient_limits(self) -> PatientLimits:
        """The limits as the RT process validates them (raises pydantic's error if bad)."""
        return PatientLimits(**self.limits)

    def rt_patient(self) -> dict[str, Any]:
        """The ``patient`` argument of ``session_start`` / ``session_preflight``."""
        out: dict[str, Any] = {"id": self.code, "limits": dict(self.limits)}
        if self.weight_kg is not None:
            out["weight_kg"] = float(self.weight_kg)
        if self.ankle is not None:
            # Pre-flight predicts the ankle centre's displacement about it and the RT process
            # turns the foot about it: without it both would use the platform's centre.
            out["ankle"] = dict(self.ankle)
        return out
