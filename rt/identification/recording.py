"""Reading an identification recording (``identify_excitation``'s MCAP) back into the samples
least squares needs.

What is kept: the ``/robot/state`` rows between the first and the last played cycle (the
recording's ``/identification/summary``), encoder positions ``q`` and the drive voltages after
the supervisor ``volts``. The actuator force is what the current-mode amplifiers were told:
τ = V × ``force_per_volt_n`` of the description the lab believes (drive constants from the
motor and amplifier datasheets, not identified here).

The loop's own time ``t`` is the time base: a late cycle on a loaded machine leaves a gap in
``t`` during which the drives held their command. Positions are interpolated linearly and the
voltages held (zero-order hold, what the DAC did) onto a uniform grid at the recording's rate
before the zero-phase filter of :func:`rt.identification.estimate.prepare`.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rt.identification.estimate import IdentificationData, IdentificationError, prepare
from rt.identification.program import SUMMARY_TOPIC, ExcitationSpec
from rt.model.description import RobotDescription, description_from_dict
from rt.recording.channels import METADATA, STATE

#: A gap in the loop's time longer than this (s) is reported (the fit still resamples over it).
GAP_WARN_S = 0.005


@dataclass
class ExcitationRecording:
    """The played part of an identification recording: t (s), q (m) and volts (V), each row
    one loop cycle, plus the recording's metadata and summary."""

    path: Path
    t: np.ndarray
    q: np.ndarray
    volts: np.ndarray
    metadata: dict[str, Any]
    summary: dict[str, Any]

    @property
    def rate_hz(self) -> float:
        return float(self.metadata["parameters"]["rate_hz"])

    @property
    def label(self) -> str:
        return str(self.metadata["parameters"].get("label", "excitation"))

    @property
    def max_gap_s(self) -> float:
        return float(np.diff(self.t).max()) if len(self.t) > 1 else 0.0

    def robot(self) -> RobotDescription:
        """The description the RT process believed while recording."""
        return description_from_dict(self.metadata["robot"], f"recording {self.path.name}")

    def truth(self) -> RobotDescription | None:
        """The twin's truth (recorded on the twin only): for the twin figures."""
        raw = self.metadata.get("twin_truth")
        return None if raw is None else description_from_dict(raw, "the twin's truth")

    def excitation(self) -> ExcitationSpec:
        return ExcitationSpec.model_validate(self.metadata["parameters"]["excitation"])

    def data(self, description: RobotDescription) -> IdentificationData:
        """Uniformly resampled, filtered samples with τ = V × the drive's force per volt."""
        rate = self.rate_hz
        n = int(np.floor((self.t[-1] - self.t[0]) * rate)) + 1
        grid = self.t[0] + np.arange(n) / rate
        q = np.column_stack([np.interp(grid, self.t, self.q[:, i]) for i in range(3)])
        # Zero-order hold: the last command written at or before each grid instant.
        k = np.clip(np.searchsorted(self.t, grid + 1e-9, side="right") - 1, 0, len(self.t) - 1)
        tau = self.volts[k] * description.drive.force_per_volt_n
        return prepare(q, tau, rate, amplifier=description.drive)


def load_excitation_recording(path: str | Path) -> ExcitationRecording:
    """Read and check an ``identify_excitation`` recording; IdentificationError names what is
    wrong (not an identification recording, stopped by the supervisor, no played cycle)."""
    from rt.recording.reader import read_recording

    path = Path(path)
    msgs = read_recording(path, topics=[STATE, METADATA, SUMMARY_TOPIC])
    meta_msgs = msgs.get(METADATA) or []
    if not meta_msgs:
        raise IdentificationError(f"{path}: no metadata: not a talus recording")
    meta = meta_msgs[0]
    if isinstance(meta, (bytes, str)):
        meta = json.loads(meta)
    params = meta.get("parameters") or {}
    if not str(meta.get("protocol_name", "")).startswith("identification-") \
            or "excitation" not in params or "robot" not in meta:
        raise IdentificationError(f"{path}: not an identification recording (protocol "
                                  f"{meta.get('protocol_name')!r}); record one with `talus "
                                  "identify run --backend rt`")
    summaries = msgs.get(SUMMARY_TOPIC) or []
    if not summaries:
        raise IdentificationError(f"{path}: the recording has no summary: the excitation did "
                                  "not end (RT process stopped while recording?)")
    summary = summaries[-1]
    if summary.get("outcome") != "completed":
        causes = ", ".join(summary.get("causes") or []) or "no cause recorded"
        raise IdentificationError(f"{path}: the excitation was {summary.get('outcome')} "
                                  f"({causes}); it cannot be used for identification")
    if "t_play_start" not in summary:
        raise IdentificationError(f"{path}: no cycle of the excitation was played")
    t0, t1 = float(summary["t_play_start"]), float(summary["t_play_end"])
    rows = [m for m in msgs.get(STATE, []) if t0 <= float(m["t"]) <= t1]
    if len(rows) < 2:
        raise IdentificationError(f"{path}: no /robot/state rows while the excitation played")
    t = np.array([float(m["t"]) for m in rows])
    q = np.array([m["q"] for m in rows], float)
    volts = np.array([m["volts"] for m in rows], float)
    order = np.argsort(t, kind="stable")
    t, q, volts = t[order], q[order], volts[order]
    keep = np.concatenate(([True], np.diff(t) > 0.0))        # one row per loop instant
    return ExcitationRecording(path, t[keep], q[keep], volts[keep], meta, summary)
