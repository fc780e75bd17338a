"""Fault injection on the twin: what can break on the real rig, switchable at a given time.

Each fault has a kind, a target (axis, DAC card/channel) and a time window [t_start, t_end)
in twin time (s). ``FaultPlan.schedule(...)`` validates and records; the twin asks
``active(kind, t, ...)`` as it runs. Kinds:

* ``encoder_freeze`` (axis): the counter stops counting (pulses are lost, as with a cut cable).
* ``encoder_jump`` (axis, counts): spurious pulses add ``counts`` once at t_start.
* ``encoder_noise`` (axis, sigma_counts): spurious pulses every cycle, N(0, σ²) counts.
* ``dac_dead`` (card, channel): that output gives 0 V whatever is written.
* ``dac_stuck`` (card, channel): that output holds the value it had at t_start.
* ``ati_dropout`` / ``ati_stale`` / ``ati_saturation``: the force sensor sends nothing / repeats
  its last sample / flags gage saturation (delegated to the twin's ATI model).
* ``latency`` (seconds): sensor readings (encoders and ATI) arrive ``seconds`` late.
* ``hardware_estop`` / ``hand_stop``: the stop input reads pressed.
* ``contact_removed``: what the platform touches goes away (the patient's foot lifted out of
  the straps, the plate taken off the tool): the platform moves free until ``t_end``, then
  touches it again where it was.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from rt.epoch import bump
from rt.errors import InputError

KINDS = ("encoder_freeze", "encoder_jump", "encoder_noise", "dac_dead", "dac_stuck",
         "ati_dropout", "ati_stale", "ati_saturation", "latency", "hardware_estop", "hand_stop",
         "contact_removed")
_NEEDS_AXIS = {"encoder_freeze", "encoder_jump", "encoder_noise"}
_NEEDS_CHANNEL = {"dac_dead", "dac_stuck"}


@dataclass(frozen=True)
class Fault:
    kind: str
    t_start: float
    t_end: float = math.inf
    axis: int = -1
    card: int = -1
    channel: int = -1
    counts: int = 0
    sigma_counts: float = 0.0
    seconds: float = 0.0

    def active(self, t: float) -> bool:
        return self.t_start <= t < self.t_end


class FaultPlan:
    """The faults scheduled on one twin."""

    def __init__(self) -> None:
        self.faults: list[Fault] = []

    def schedule(self, kind: str, t_start: float = 0.0, t_end: float | None = None, *,
                 axis: int | None = None, card: int | None = None, channel: int | None = None,
                 counts: int | None = None, sigma_counts: float | None = None,
                 seconds: float | None = None) -> Fault:
        """Validate and add one fault; returns it. Bad arguments raise ``InputError``."""
        if kind not in KINDS:
            raise InputError(f"unknown fault kind {kind!r}; known: {', '.join(KINDS)}")
        if not math.isfinite(t_start) or t_start < 0.0:
            raise InputError(f"{kind}: t_start must be a time >= 0 s, got {t_start}")
        end = math.inf if t_end is None else float(t_end)
        if not end > t_start:
            raise InputError(f"{kind}: t_end ({t_end}) must be after t_start ({t_start})")
        fields: dict = {}
        if kind in _NEEDS_AXIS:
            if axis not in (0, 1, 2):
                raise InputError(f"{kind} needs axis 0, 1 or 2, got {axis!r}")
            fields["axis"] = axis
        if kind in _NEEDS_CHANNEL:
            if card not in (0, 1) or channel not in (0, 1, 2):
                raise InputError(f"{kind} needs card 0 or 1 and channel 0-2, got card {card!r}, "
                                 f"channel {channel!r}")
            fields.update(card=card, channel=channel)
        if kind == "encoder_jump":
            if not isinstance(counts, int) or counts == 0:
                raise InputError(f"encoder_jump needs a non-zero integer counts, got {counts!r}")
            fields["counts"] = counts
        if kind == "encoder_noise":
            if sigma_counts is None or not (math.isfinite(sigma_counts) and sigma_counts > 0):
                raise InputError(f"encoder_noise needs sigma_counts > 0, got {sigma_counts!r}")
            fields["sigma_counts"] = float(sigma_counts)
        if kind == "latency":
            if seconds is None or not (0.0 < seconds <= 0.5):
                raise InputError(f"latency needs 0 < seconds <= 0.5, got {seconds!r}")
            fields["seconds"] = float(seconds)
        fault = Fault(kind, float(t_start), end, **fields)
        self.faults.append(fault)
        bump()                        # the fused cycle's fast path leaves the twin's faults
        return fault

    def clear(self) -> None:
        self.faults.clear()

    def active(self, kind: str, t: float) -> list[Fault]:
        """The faults of ``kind`` active at time ``t``."""
        return [f for f in self.faults if f.kind == kind and f.active(t)]
