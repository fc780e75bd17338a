"""The safety supervisor's logic: every check, every cycle, on plain floats.

Reactions escalate warn → soft stop → hard stop and latch until ``request_reset()``, which is
honoured only if none of the latched causes is still present (the cause is re-checked). Every
new cause is recorded once as a ``SafetyEvent`` with the loop time and the values that tripped it.

Checks (robot, patient and protocol limits combined in ``EffectiveLimits``):

* stop inputs: GUI/CLI/keyboard e-stop and the hardware e-stop chain → hard stop; the patient's
  hand-held comfort stop → soft stop;
* forward kinematics failed → hard stop (the platform pose is unknown);
* encoder jump beyond physics (the estimator's innovation gate) → hard stop; encoder frozen while
  commanded (the frozen-encoder criterion below) → hard stop;
* stroke: inside the margin at either end → soft stop; beyond the end → hard stop;
* slider speed beyond the robot's → soft stop; acceleration beyond it → warn;
* patient ROM per axis with its end cushion: the cushion is the soft stop's own braking curve —
  a soft stop is triggered when the angle plus the angle the soft stop still needs to brake
  (from the measured angular rate) reaches the ROM end, so the stop ends inside the ROM; beyond
  the end by more than the tolerance → hard stop; angular speed beyond the patient's → soft stop;
* tracking error beyond the robot limit → soft stop, beyond three times it → hard stop;
* pulling on the foot: in force control, measured Fz (the platform's push, ``fz_n``) below
  0 N for ``max_pull_s`` → soft stop (the contact is unilateral; the force law never commands
  a pull, so this catches what it cannot prevent); counted stall-aware: one cycle adds at most
  :data:`~rt.safety.supervisor_kernel.PULL_DT_PERIODS` periods (a host stall's long dt is one
  ATI sample, not that long a pull);
* platform force (ATI) above 90 % of the patient/protocol limit → soft stop, beyond it → hard
  stop (only dropping the drive force is fast enough against a stiff contact); saturated or
  implausible → soft stop; stale → soft stop when force control depends on it, else warn;
* consecutive deadline overruns (measured period > 1.5 × nominal) → soft stop;
* sustained drive saturation: an axis' command (the law's force, before the DAC's clamp) at
  the drive's limit (``applied_force_max_n``) for more than ``max_saturated_fraction`` of the
  last ``saturation_window_s`` → soft stop (``drive_saturated_<axis>``): an unstable loop (a
  mis-tuned gain, a force loop's limit cycle against a stuck contact) or an obstruction the
  drives push against in vain; the force may stay under its limit and the foot loaded, so no
  other check names it; so while a soft stop (whatever its cause) has been latched for a
  whole window → hard stop (a soft stop in force control ramps the force down through the
  same law: an unstable one goes on shaking, through the pull and speed checks' soft stops
  too). Counted while the drives are on, in a sliding window of
  :data:`~rt.safety.supervisor_kernel.SAT_BUCKETS` buckets of loop time;
* client heartbeat older than its timeout while a client drives the robot → soft stop;
* both DAC cards failed on a channel → hard stop (a single card's failure is a failover).

The frozen-encoder criterion (issue 15). A still count is judged against physics, per axis:

* **force balance** (any contact): the axis' own load is the force its drive applies less the
  measured contact's share of it, ``load = sat(τ) − s`` with ``s = −J_Sᵀ w_S`` (the ATI's
  wrench through the platform's statics, :func:`rt.safety.supervisor_kernel.contact_share`)
  and ``sat(τ)`` the command saturated at the force of the DAC's command limit
  (``applied_force_max_n`` = ``max_command_v`` × the drives' N/V, set by the supervisor
  block): a law winding up beyond the drives (a pre-flight with the drives limited, a heel
  strike) pushes with what the drive gives, not with what it asks. A still axis is in static
  equilibrium: ``load`` stays within the friction it can hold (``holding_force_n``) of the
  static load that carries it (``carry``: gravity, an unmeasured payload, friction, an
  amplifier's offset). ``carry`` is a running estimate (:data:`CARRY_TAU_S`) of the load less
  the inertia's ``m·q̈`` (``q̈`` the velocity estimator's), learnt while the count moves and
  only while the axis is quasi-static (``|q̈| ≤`` :data:`QUASI_STATIC_ACCEL` for
  :data:`QUASI_STATIC_S`), and it slews by at most ``holding_force_n`` per CARRY_TAU_S: a
  slider braked at the drives' limit (after a pull's soft stop) must not leave the braking's
  kilonewtons in it, which the first still cycles would read as an unbalanced load. The
  estimator's q̈ lags the true one by ~10 ms, hence the hold time (a lagging estimate crosses
  zero between an acceleration and its braking) and the slew (a force step it has not caught
  up with yet). A contact needs no special case: what it holds of the applied force is
  measured and taken out, so a slider stalled by what it presses balances, and a frozen one
  under a runaway command does not, in contact as in free motion.
  **An unmeasured load change** (a payload landing, a patient stepping on beside the ATI)
  makes ``carry`` stale exactly when it stops a moving slider (the 100 kg payload step at
  100 Hz stalls the rising axis 0 at once: no motion left to learn the new load from) or
  makes the sliders sink at the drives' limit (500 kg under a force hold: never quasi-static,
  so never learnt). The still axis is then held by a load the supervisor does not know, but
  one it cannot escape: whatever constant load holds a still axis, its own load stays within
  the friction band of it, so the loads of one still stretch stay within ``holding_force_n``
  of each other. The excess is therefore the *smaller* of the load's distance from ``carry``
  and its distance from the farthest load the axis held since its count stopped (the
  stretch's range, ``M_STILL_LO``/``M_STILL_HI``): the most benign explanation, a constant
  load, must fail too. A frozen encoder fails both: the reference runs away from the stuck
  count and the command with it, beyond the carry and beyond where it stood at the freeze.
  A braking that ends in a stop (kilonewtons at the stop, then the hold) fails only the
  range and is judged by the carry, as before. The excess must accelerate
  the axis' inertia; once ``∫excess dt · T / (2 m)`` reaches ``FROZEN_COUNTS`` counts the
  encoder is frozen. The sensor reads the
  contact ``force_lag_s`` late (its filter and sample age): while the share changes, the true
  one may be ahead by its rate × that lag, which is added to the holding band — at a
  contact's onset a pressing slider is held by a force the ATI has not shown yet.
* **reference speed** (nothing touching): the reference has moved the axis at
  ≥ ``frozen_min_ref_speed_m_s`` for ``frozen_encoder_s`` without a count. It counts only
  while nothing has been measured on the platform (ATI force ≤ ``contact_force_n``) for
  ``contact_release_s`` (contact hysteresis): in contact a slider legitimately stalls against
  what it presses while its reference moves (a shear push's tilt, a foot), and the force
  balance judges it there.

State per axis: last count, carried load, excess impulse and its duration, reference-speed
time, last contact share, quasi-static time, the load's range since the count stopped; and one
contact-release time. Judged only while
the drives are on and the brakes open.

The numeric checks run compiled (:mod:`rt.safety.supervisor_kernel`, one call per cycle that
allocates nothing); this module keeps what users and tests see: cause names, latching, events,
reset tickets, client requests. :class:`InterpretedSupervisor` runs the same checks in Python:
it is the reference the compiled one is tested against (a recorded cycle stream replayed
through both gives the same events and outputs).
"""
from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rt.epoch import bump
from rt.errors import ConfigurationError
from rt.model.description import AMPLIFIER_OFFSET_MAX_V, RobotDescription
from rt.safety import supervisor_kernel as sk
from rt.safety.events import EventLog, Reaction, SafetyEvent
from rt.safety.limits import EffectiveLimits

# The checks' constants live with the compiled checks (one source for both implementations).
JUMP_STATUS = sk.JUMP_STATUS
#: Counts a free axis must have moved under its commanded force before "frozen" is declared.
FROZEN_COUNTS = sk.FROZEN_COUNTS
#: Fraction of the force limit at which a soft stop begins (the force's end cushion).
FORCE_CUSHION = sk.FORCE_CUSHION
#: Margin on the friction band a still axis can hold (the frozen-encoder check must not trip on
#: an axis that legitimately sticks, e.g. at a velocity reversal).
HOLDING_MARGIN = 1.5
#: Time constant (s) of the running estimate of the force that carries an axis while its count
#: moves (the load's share, friction and inertia): long enough to average the controller's
#: cycle-to-cycle ripple, short next to a payload's arrival (the estimate follows it as the
#: axis sinks under the new load) and to a velocity reversal's stick (tens of ms).
CARRY_TAU_S = sk.CARRY_TAU_S
#: The carried load is learnt only while the axis is quasi-static: its estimated acceleration
#: within this (m/s²; the inertia's m·q̈ then ≤ 104 N of the 207 kg axis, under half the 225 N
#: friction band, and m·q̈ is subtracted as well) ...
QUASI_STATIC_ACCEL = sk.QUASI_STATIC_ACCEL
#: ... for this long (s): the velocity estimator's q̈ lags the true one by ~10 ms, so between
#: a drive-limited acceleration and its braking it crosses zero while the axis still
#: accelerates at 10 m/s²; that crossing lasts ~1 ms, a quasi-static stretch tens of ms.
QUASI_STATIC_S = sk.QUASI_STATIC_S
#: Lever ∂q/∂angle of a slider per radian of platform tilt, in platform radii (≈ 1.5 R_p for
#: a 3-PRS with the spheres on a circle: the farthest leg moves R_p·(1 + 1/2) per radian).
LEVER_PER_PLATFORM_RADIUS = 1.5
#: How late the force sensor shows a contact force (s): the ATI's output filter (150 Hz: a
#: 1.1 ms time constant), the age of the latest sample (≤ 1 ms at the 1 kHz RDT stream), with
#: margin. Sizes the frozen-encoder check's allowance while the contact's share changes.
FORCE_LAG_S = 0.003
#: How long the platform stays "touched" for the frozen-encoder reference-speed criterion
#: after the measured force falls below ``contact_force_n`` (s): the sensor's lag plus the
#: contact's and the transmission's springs unloading before the sliders follow again.
CONTACT_RELEASE_S = 0.02


def supervisor_physics(d: RobotDescription) -> dict[str, Any]:
    """The supervisor's physical constants from the robot description (SI):

    * ``axis_mass_kg``: slider mass + rotor inertia reflected through the screw;
    * ``holding_force_n``: how far the command may move from the force that last carried the
      moving axis without moving it: from sliding one way (Coulomb) to breaking away the other
      (static), at most twice the static friction, times :data:`HOLDING_MARGIN`. The load
      (gravity of the links, of the platform and of any payload) is in the carried force
      itself, so it is not part of this band;
    * ``count_m``: one encoder count;
    * ``lever_m_per_rad``: slider travel per radian of tilt (the soft stop's braking cushion);
    * ``sensor_offset_m``: the ATI's origin in the platform frame P (its wrench is carried to P
      for the contact's share of each actuator force);
    * ``amplifier_offset_v``: each axis' believed amplifier input offset (V,
      ``drive.amplifier_offset_v``, from identification), which the outputs compensate.
    """
    b = d.bodies
    return {"axis_mass_kg": b.slider.mass_kg + d.drive.reflected_inertia_kg,
            "holding_force_n": HOLDING_MARGIN * 2.0 * d.friction.static_n,
            "count_m": d.encoder.m_per_count,
            "lever_m_per_rad": LEVER_PER_PLATFORM_RADIUS * d.geometry.platform_radius_m,
            "sensor_offset_m": tuple(float(x) for x in d.sensor.offset_m),
            "amplifier_offset_v": tuple(float(x) for x in d.drive.amplifier_offset_v)}


@dataclass
class ResetTicket:
    """A reset request and, once the cycle has taken it (``done``), its outcome.

    ``acknowledge`` holds the ids of the latched events the requester saw (``status``); only
    those can be cleared, so a fault latched after the request was made stays latched. The
    reset is all or nothing: if an acknowledged cause is still present, nothing is cleared.
    """

    acknowledge: frozenset[int]
    done: bool = False
    cleared: list[dict] = field(default_factory=list)
    refused: list[dict] = field(default_factory=list)
    still_latched: list[dict] = field(default_factory=list)


class _Packed:
    """A supervisor parameter kept in the compiled checks' ``par`` array, so the kernel reads
    whatever Python assigns (e.g. ``force_control``, flipped by the hybrid controller)."""

    def __init__(self, index: int):
        self.index = index

    def __get__(self, obj: Supervisor | None, owner: type | None = None) -> float:
        if obj is None:
            return math.nan
        return float(obj._par[self.index])

    def __set__(self, obj: Supervisor, value: float) -> None:
        obj._par[self.index] = float(value)


class _PackedFlag(_Packed):
    def __get__(self, obj: Supervisor | None, owner: type | None = None) -> bool:
        return obj is not None and bool(obj._par[self.index])

    def __set__(self, obj: Supervisor, value: bool) -> None:  # type: ignore[override]
        obj._par[self.index] = 1.0 if value else 0.0


def _cause_names() -> tuple[str, ...]:
    names = ["estop_hardware", "hand_stop", "drive_channel", "fk_failed", "encoder_jump"]
    for i in range(3):
        names += [f"encoder_frozen_{i}", f"stroke_{i}", f"stroke_margin_{i}", f"speed_{i}",
                  f"accel_{i}", f"tracking_{i}", f"actuator_force_{i}"]
    names += ["rom_roll", "angular_speed_roll", "rom_pitch", "angular_speed_pitch",
              "force_saturated", "force_stale", "force_implausible", "force_limit", "pulling",
              "deadline_overruns"]
    names += [f"drive_saturated_{i}" for i in range(3)]
    names += ["pull_in_stop", "contact_lost"]
    assert len(names) == sk.N_CAUSES
    return tuple(names)


#: The compiled checks' causes by kernel index (the interpreted check's order).
CAUSES = _cause_names()
_INDEX = {name: k for k, name in enumerate(CAUSES)}


def _event_text(c: int, reaction: int, v: np.ndarray) -> tuple[str, dict]:
    """Message and values of kernel cause ``c`` tripped with ``reaction`` and values ``v``,
    word for word those of the interpreted check."""
    if c == sk.C_ESTOP_HW:
        return "hardware e-stop pressed", {}
    if c == sk.C_HAND:
        return "patient's hand-held stop pressed", {}
    if c == sk.C_DRIVE:
        return "an actuator channel failed on both cards", {}
    if c == sk.C_FK:
        return "forward kinematics failed: pose unknown", {}
    if c == sk.C_JUMP:
        return "encoder reading jumped beyond physics", {"q": [float(x) for x in v]}
    if c < sk.C_ROM_ROLL:
        i, slot = divmod(c - sk.C_AXIS, sk.AXIS_SLOTS)
        x = float(v[0])
        if slot == sk.A_FROZEN:
            return (f"encoder {i} frozen while commanded to move",
                    {"frozen_s": x, "expected_m": float(v[1]), "qd_ref": float(v[2])})
        if slot == sk.A_STROKE:
            return f"slider {i} beyond its stroke", {"q": x}
        if slot == sk.A_MARGIN:
            return f"slider {i} inside the stroke-end margin", {"q": x}
        if slot == sk.A_SPEED:
            return f"slider {i} too fast", {"qd": x}
        if slot == sk.A_ACCEL:
            return f"slider {i} acceleration beyond the robot limit", {"qdd": x}
        if slot == sk.A_TRACKING:
            return f"slider {i} tracking error", {"error": x}
        return f"actuator {i} force command beyond the robot limit (saturated)", {"tau": x}
    if c in (sk.C_ROM_ROLL, sk.C_ROM_PITCH):
        name = "roll" if c == sk.C_ROM_ROLL else "pitch"
        if reaction == sk.R_HARD:
            return f"{name} beyond the patient's ROM", {"angle_deg": math.degrees(v[0])}
        return (f"{name} reaching the patient's ROM end",
                {"angle_deg": math.degrees(v[0]), "rate_deg_s": math.degrees(v[1])})
    if c in (sk.C_ANG_ROLL, sk.C_ANG_PITCH):
        name = "roll" if c == sk.C_ANG_ROLL else "pitch"
        return f"{name} rate beyond the patient's limit", {"rate_deg_s": math.degrees(v[0])}
    if c == sk.C_FORCE_SAT:
        return "force sensor saturated (overload)", {}
    if c == sk.C_FORCE_STALE:
        return "force sensor data stale", {}
    if c == sk.C_FORCE_IMPL:
        return "force sensor reading invalid", {}
    if c == sk.C_FORCE_LIMIT:
        if reaction == sk.R_HARD:
            return "platform force beyond the limit", {"force_n": float(v[0])}
        return "platform force reaching the limit", {"force_n": float(v[0])}
    if c == sk.C_PULL:
        return ("the platform is pulling on the foot (measured Fz below 0 N)",
                {"fz_n": float(v[0]), "for_s": float(v[1])})
    if c == sk.C_DEADLINE:
        return "consecutive deadline overruns", {"count": int(v[0]), "dt": float(v[1])}
    if c == sk.C_PULL_STOP:
        return _pull_in_stop_text(float(v[0]), float(v[1]), float(v[2]))
    if c == sk.C_CONTACT_LOST:
        return _contact_lost_text(float(v[0]), float(v[1]), float(v[2]))
    return _saturation_text(c - sk.C_DRIVE_SAT, reaction, float(v[0]), float(v[1]),
                            float(v[2]))


def _pull_in_stop_text(fz_n: float, since_t: float, for_s: float) -> tuple[str, dict]:
    """Message and values of the ``pull_in_stop`` alarm (both supervisors')."""
    when = "in the stop" if math.isnan(for_s) else f"{for_s:.1f} s into the stop"
    message = (f"the foot is still pulled ({fz_n:.0f} N) {when}: the robot cannot lift it; "
               "support the limb or release the strap")
    return (message,
            {"fz_n": fz_n, "since_t": since_t, "for_s": for_s})


def _pull_in_stop_end_text(fz_n: float, since_t: float, how: float,
                           t: float) -> tuple[str, dict]:
    """Message and values of the event that ends the ``pull_in_stop`` alarm at loop time
    ``t``: ``fz_n`` the sample that ended it (or the last pull read), ``since_t`` when the
    pull began, ``how`` the kernel's ``M_PULL_STOP_END`` (1: a sample read no pull, 2: the
    stop was reset)."""
    ended = "pull_ended" if how == 1.0 else "stop_reset"
    message = ("the pull in the stop has ended" if ended == "pull_ended"
               else "the stop was reset while the foot was pulled (pull no longer watched)")
    return message, {"how": ended, "fz_n": fz_n, "since_t": since_t, "lasted_s": t - since_t}


def _contact_lost_text(fz_n: float, rise_m: float, touch_m: float) -> tuple[str, dict]:
    """Message and values of ``contact_lost`` (both supervisors')."""
    message = (f"contact lost in force control: {fz_n:.1f} N with the platform "
               f"{rise_m * 1e3:.1f} mm above where it last touched")
    return (message,
            {"fz_n": fz_n, "rise_m": rise_m, "touch_q_m": touch_m})


def _saturation_text(i: int, reaction: int, saturated_s: float, window_s: float,
                     limit_n: float) -> tuple[str, dict]:
    """Message and values of ``drive_saturated_<i>`` (both supervisors')."""
    values = {"saturated_s": saturated_s, "window_s": window_s, "limit_n": limit_n}
    if reaction == sk.R_HARD:
        message = (f"drive {i} still at its force limit {window_s:g} s into a soft stop "
                   "(sustained saturation the soft stop did not end)")
    else:
        message = (f"drive {i} at its force limit for most of the last {window_s:g} s "
                   "(sustained saturation: an unstable loop or an obstruction)")
    return message, values


class Supervisor:
    """Checks + latch. The owning component fills the inputs and calls ``check`` each cycle
    (the supervisor block calls :meth:`check_block` on its port buffers).

    The numeric checks are compiled (:func:`rt.safety.supervisor_kernel.check`); a cycle in
    which nothing new trips, nobody requested anything and no reset is pending runs no Python
    beyond the call. :class:`InterpretedSupervisor` is the reference."""

    compiled = True

    period_s = _Packed(sk.P_PERIOD)
    alpha_stop = _Packed(sk.P_ALPHA_STOP)
    jerk_time = _Packed(sk.P_JERK_TIME)
    axis_mass_kg = _Packed(sk.P_AXIS_MASS)
    holding_force_n = _Packed(sk.P_HOLDING)
    count_m = _Packed(sk.P_COUNT_M)
    contact_force_n = _Packed(sk.P_CONTACT)
    force_lag_s = _Packed(sk.P_FORCE_LAG)
    contact_release_s = _Packed(sk.P_CONTACT_RELEASE)
    applied_force_max_n = _Packed(sk.P_APPLIED_MAX)
    startup_grace_s = _Packed(sk.P_GRACE)
    force_control = _PackedFlag(sk.P_FORCE_CONTROL)

    def __init__(self, limits: EffectiveLimits, period_s: float, log: EventLog | None = None,
                 soft_stop_accel_m_s2: float = 0.5, soft_stop_jerk_m_s3: float = 5.0,
                 lever_m_per_rad: float = 0.27, axis_mass_kg: float = 207.3,
                 holding_force_n: float = 225.0, count_m: float = 2e-5,
                 sensor_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.08),
                 amplifier_offset_v: Iterable[float] = (0.0, 0.0, 0.0)):
        """The defaults are the nominal robot's (:func:`supervisor_physics`); the loop passes
        the values of the robot it drives."""
        self._par = np.zeros(sk.PAR_SIZE)
        self.limits = limits
        self.period_s = period_s
        self.log = log or EventLog()
        # Braking of the soft stop seen as an angular deceleration of the platform: slider
        # deceleration over the lever ∂q/∂angle (≈ 1.5 R_p for this geometry).
        self.alpha_stop = soft_stop_accel_m_s2 / lever_m_per_rad
        self.jerk_time = soft_stop_accel_m_s2 / soft_stop_jerk_m_s3
        self._heartbeat_age: Callable[[], float] | None = None
        self._heartbeat_required = False
        self.force_control = False
        # Frozen-encoder physics: the axis' inertia (slider + reflected rotor, kg), how far the
        # command may move from the force that carried the moving axis without moving it (the
        # friction band, N), the encoder count (m), and the platform force above which
        # something pushes back (contact).
        self.axis_mass_kg = axis_mass_kg
        self.holding_force_n = holding_force_n
        self.count_m = count_m
        self.contact_force_n = 50.0
        self.force_lag_s = FORCE_LAG_S
        self.contact_release_s = CONTACT_RELEASE_S
        # The force a drive applies at the DAC's command limit (N): the force balance uses the
        # command saturated there. The supervisor block sets it every cycle from the limits'
        # max_command_v and the drives' N/V; inf (no saturation) for direct ``check`` calls.
        self.applied_force_max_n = math.inf
        self.sensor_offset_m = (float(sensor_offset_m[0]), float(sensor_offset_m[1]),
                                float(sensor_offset_m[2]))
        self.amplifier_offset_v = amplifier_offset_v
        # The force sensor's first samples arrive a few cycles after the loop starts.
        self.startup_grace_s = 0.1
        # The motors' spring-applied holding brakes close when the drives are off and open
        # ≈ 30 ms after they are enabled (datasheet order; the twin's RigImperfections): until
        # then an axis cannot move whatever the command, so the frozen-encoder check waits
        # this long (s, with margin) after every enable — at start and after a hard stop's reset.
        self.brake_release_s = 0.05
        self.reset_state()
        sk.warm_up()

    @property
    def sensor_offset_m(self) -> tuple[float, float, float]:
        """The ATI's origin in the platform frame P (m)."""
        p = self._par
        return (float(p[sk.P_SENSOR_X]), float(p[sk.P_SENSOR_Y]), float(p[sk.P_SENSOR_Z]))

    @sensor_offset_m.setter
    def sensor_offset_m(self, offset: tuple[float, float, float]) -> None:
        self._par[sk.P_SENSOR_X:sk.P_SENSOR_Z + 1] = offset

    @property
    def amplifier_offset_v(self) -> tuple[float, float, float]:
        """Each axis' believed amplifier input offset (V): the outputs write τ·k minus it
        while the drives are enabled (:func:`rt.safety.supervisor_kernel.outputs`), so the
        amplifier, which adds its offset, delivers the commanded force."""
        p = self._par
        k = sk.P_AMP_OFFSET
        return (float(p[k]), float(p[k + 1]), float(p[k + 2]))

    @amplifier_offset_v.setter
    def amplifier_offset_v(self, offsets: Iterable[float]) -> None:
        # Checked here as the description checks it (a Supervisor can be built without one):
        # a bad value is refused by name and the compensation in use stays as it was.
        try:
            if isinstance(offsets, str | bytes):     # "123" would iterate as 3 numbers
                raise TypeError
            v = [float(x) for x in offsets]
        except (TypeError, ValueError) as exc:
            raise ConfigurationError(f"amplifier_offset_v must be 3 numbers (V), got "
                                     f"{offsets!r}") from exc
        if len(v) != 3:
            raise ConfigurationError(f"amplifier_offset_v must be one offset per axis (3, V), "
                                     f"got {len(v)}: {v}")
        for i, x in enumerate(v):
            if not (math.isfinite(x) and abs(x) <= AMPLIFIER_OFFSET_MAX_V):
                raise ConfigurationError(
                    f"amplifier_offset_v[{i}] = {x} V is not within ±{AMPLIFIER_OFFSET_MAX_V} V "
                    "(a faulty amplifier or a wrong identification, not an offset to "
                    "compensate)")
        self._par[sk.P_AMP_OFFSET:sk.P_AMP_OFFSET + 3] = v

    def contact_share(self, state_buf: np.ndarray, wrench) -> np.ndarray:
        """The measured contact's share of each actuator force (N) for a model state buffer
        and the ATI's wrench (:func:`rt.safety.supervisor_kernel.contact_share`)."""
        out = np.zeros(3)
        sk.contact_share(state_buf, np.asarray(wrench, dtype=np.float64), self._par, out)
        return out

    @property
    def limits(self) -> EffectiveLimits:
        """The effective limits (assigning new ones takes effect at the next cycle)."""
        return self._limits

    @limits.setter
    def limits(self, lim: EffectiveLimits) -> None:
        p = self._par
        for index, value in (
                (sk.P_STROKE_LO, lim.stroke_lo_m), (sk.P_STROKE_HI, lim.stroke_hi_m),
                (sk.P_STROKE_MARGIN, lim.stroke_margin_m),
                (sk.P_MAX_SPEED, lim.max_slider_speed_m_s),
                (sk.P_MAX_ACCEL, lim.max_slider_accel_m_s2),
                (sk.P_MAX_COMMAND_V, lim.max_command_v),
                (sk.P_MAX_ACTUATOR, lim.max_actuator_force_n),
                (sk.P_MAX_TRACKING, lim.max_tracking_error_m), (sk.P_MAX_FORCE, lim.max_force_n),
                (sk.P_ROLL_MIN, lim.roll_min), (sk.P_ROLL_MAX, lim.roll_max),
                (sk.P_PITCH_MIN, lim.pitch_min), (sk.P_PITCH_MAX, lim.pitch_max),
                (sk.P_MAX_ANGULAR, lim.max_angular_speed), (sk.P_ROM_TOL, lim.rom_tolerance),
                (sk.P_DEADLINE_OVERRUNS, lim.deadline_overruns),
                (sk.P_FROZEN_S, lim.frozen_encoder_s),
                (sk.P_FROZEN_MIN_REF, lim.frozen_min_ref_speed_m_s),
                (sk.P_MAX_PULL_S, lim.max_pull_s),
                (sk.P_SAT_FRACTION, lim.max_saturated_fraction)):
            p[index] = value
        if p[sk.P_SAT_WINDOW] != lim.saturation_window_s:
            # Another window length: its buckets mean other times, the window starts afresh.
            p[sk.P_SAT_WINDOW] = lim.saturation_window_s
            self._restart_saturation_window()
        self._limits = lim

    def _restart_saturation_window(self) -> None:
        mem = getattr(self, "_mem", None)
        if mem is not None:
            mem[sk.M_SAT_K] = math.nan
            mem[sk.M_SAT_PAST:sk.M_SAT_PAST + 3] = 0.0
            mem[sk.M_SAT_BUCKETS:sk.M_SAT_BUCKETS + 3 * sk.SAT_BUCKETS] = 0.0

    @property
    def saturated_peak_s(self) -> list[float]:
        """Per axis, the most saturated time any window held since the last reset of the
        state (s; the sustained-saturation check trips beyond ``max_saturated_fraction`` ×
        ``saturation_window_s``): how close a run came to it."""
        return [float(x) for x in self._mem[sk.M_SAT_PEAK:sk.M_SAT_PEAK + 3]]

    def reset_state(self) -> None:
        self.reaction = Reaction.NONE
        self.causes: dict[str, Reaction] = {}      # latched causes
        self.latched_ids: dict[str, int] = {}      # latched cause -> the event that latched it
        self._latched_wall: dict[str, float] = {}  # ... and its wall-clock time (s)
        self._py_active: set[str] = set()          # Python-side causes true this cycle
        self._estop_request: str | None = None
        self._stop_request = False
        self._failed_components: str | None = None  # the loop's blocks in error (None: none)
        self._reset_tickets: deque[ResetTicket] = deque()
        # The compiled checks' running state: frozen-encoder integrators, last counts, carried
        # forces, overruns, pull time, brakes, per-cause latch/report flags.
        self._mem = sk.new_mem()
        self._mem[sk.M_BRAKES_OPEN_AT] = self.brake_release_s   # drives enabled at t = 0
        bump()                        # new requests and ``_mem``: the fused cycle's plan ends

    @property
    def carry_force_n(self) -> list[float]:
        """Running estimate of the force that carries each axis while its count moves (N; NaN
        until the first cycle)."""
        return [float(x) for x in self._mem[sk.M_CARRY:sk.M_CARRY + 3]]

    def braking_angle(self, rate: float, dt: float) -> float:
        """Angle (rad) the platform still turns at ``rate`` (rad/s) before a soft stop started
        now brings it to rest: one cycle of reaction, the jerk ramp, then constant braking;
        25 % margin for the lever's variation over the workspace."""
        w = abs(rate)
        return 1.25 * (w * (dt + 0.5 * self.jerk_time) + w * w / (2.0 * self.alpha_stop))

    # ------------------------------------------------------------------ requests (any thread)
    def request_estop(self, source: str) -> None:
        """E-stop from a client (``gui``, ``cli``, ``keyboard``); acted on next cycle."""
        self._estop_request = source
        bump()                        # after the request (``rt.epoch``: state, then bump)

    def request_stop(self) -> None:
        """Soft stop from a client."""
        self._stop_request = True
        bump()

    @property
    def heartbeat_required(self) -> bool:
        """Whether a client drives the robot and its heartbeat's age is checked each cycle
        (with :attr:`heartbeat_age`)."""
        return self._heartbeat_required

    @heartbeat_required.setter
    def heartbeat_required(self, on: bool) -> None:
        self._heartbeat_required = on
        bump()                        # the cycle's Python side changes (``rt.epoch``)

    @property
    def heartbeat_age(self) -> Callable[[], float] | None:
        """The client's heartbeat age (s) when called, or None (no client)."""
        return self._heartbeat_age

    @heartbeat_age.setter
    def heartbeat_age(self, age: Callable[[], float] | None) -> None:
        self._heartbeat_age = age
        bump()

    def latched(self) -> list[dict]:
        """The latched faults: ``{"id", "cause", "reaction"}`` each (any thread)."""
        for _ in range(3):   # the cycle may change the dict while another thread copies it
            try:
                items = list(self.latched_ids.items())
                return [{"id": i, "cause": c, "reaction": self.causes.get(c, Reaction.NONE)
                         .name.lower(), "wall": self._latched_wall.get(c)} for c, i in items]
            except RuntimeError:
                continue
        return []

    def request_reset(self, acknowledge: Iterable[int] | None = None) -> ResetTicket:
        """Ask to clear the latched faults whose event ids are in ``acknowledge`` (None: those
        latched now); taken next cycle, refused if an acknowledged cause is still present."""
        ids = frozenset(e["id"] for e in self.latched()) if acknowledge is None \
            else frozenset(int(i) for i in acknowledge)
        ticket = ResetTicket(ids)
        self._reset_tickets.append(ticket)
        bump()
        return ticket

    # ------------------------------------------------------------------ the cycle
    def check(self, t: float, dt: float, q, est_status: int, qd, qdd, fk_ok: bool, roll: float,
              pitch: float, roll_rate: float, pitch_rate: float, q_ref, qd_ref, tau,
              force_n: float, wrench_stale: bool, wrench_saturated: bool, hw_estop: bool,
              hand_stop: bool, drive_failed: bool, fz_n: float = math.nan,
              failed_components: str | None = None, contact_share=None) -> Reaction:
        """Run every check; returns the latched reaction for this cycle. ``force_n`` is the
        magnitude of the sensor's force, ``fz_n`` the platform's push along its z (N);
        ``failed_components`` names the loop's components a fault put in error (None: none);
        ``contact_share`` the measured contact's share of each actuator force (N, None: none;
        :meth:`contact_share`).

        Takes any sequences (copied into arrays: this entry point is for tests and tools; the
        loop's block calls :meth:`check_block`, which copies nothing)."""
        self._failed_components = failed_components

        def a(x) -> np.ndarray:
            return np.array(x, dtype=np.float64).reshape(3)

        new = sk.check(self._par, self._mem, float(t), float(dt), a(q), int(est_status), a(qd),
                       a(qdd), bool(fk_ok), float(roll), float(pitch), float(roll_rate),
                       float(pitch_rate), a(q_ref), a(qd_ref), a(tau), float(force_n),
                       bool(wrench_stale), bool(wrench_saturated), bool(hw_estop),
                       bool(hand_stop), bool(drive_failed), float(fz_n),
                       np.zeros(3) if contact_share is None else a(contact_share))
        if new or self._python_side_pending():
            self._after_checks(t, new)
        return self.reaction

    def check_block(self, t: float, dt: float, q: np.ndarray, est_status: np.ndarray,
                    qd: np.ndarray, qdd: np.ndarray, state_buf: np.ndarray, fk_ok: np.ndarray,
                    filled: bool, q_ref: np.ndarray, qd_ref: np.ndarray, tau: np.ndarray,
                    wrench: np.ndarray, wrench_flags: np.ndarray, inputs: np.ndarray,
                    drive_failed: np.ndarray, volts_per_n: float, volts: np.ndarray,
                    enable: np.ndarray, mode: np.ndarray,
                    failed_components: str | None = None) -> Reaction:
        """The supervisor block's cycle on its port buffers (layouts in ``SupervisorBlock``):
        the checks and the outputs ``volts`` (V), ``enable``, ``mode`` in one compiled call;
        Python runs only when something new tripped or a request or reset is pending, or a
        block of the loop is in error (``failed_components``)."""
        self._failed_components = failed_components
        new = sk.block_cycle(self._par, self._mem, t, dt, q, est_status, qd, qdd, state_buf,
                             fk_ok, filled, q_ref, qd_ref, tau, wrench, wrench_flags, inputs,
                             drive_failed, volts_per_n, volts, enable, mode)
        if new or self._python_side_pending():
            self.finish_block(t, new, tau, volts_per_n, volts, enable, mode)
        return self.reaction

    def finish_block(self, t: float, new: int, tau: np.ndarray, volts_per_n: float,
                     volts: np.ndarray, enable: np.ndarray, mode: np.ndarray) -> None:
        """The Python side of :meth:`check_block` after its kernel (``new``: what
        ``block_cycle`` answered), when something new tripped or a request is pending; also
        run by the graph's fused cycle (``rt.components.fused``) after its supervisor stage."""
        before = self.reaction
        self._after_checks(t, new)
        if self.reaction != before:
            sk.outputs(self._par, int(self.reaction), tau, volts_per_n, volts, enable, mode)

    def python_side_pending(self, failed_components: str | None) -> bool:
        """Whether a cycle needs :meth:`finish_block` though its kernel found nothing new
        (``failed_components`` as :meth:`check_block` takes it; recorded the same way)."""
        self._failed_components = failed_components
        return self._python_side_pending()

    def _python_side_pending(self) -> bool:
        return (self._estop_request is not None or self._stop_request
                or bool(self._reset_tickets) or self._failed_components is not None
                or (self._heartbeat_required and self._heartbeat_age is not None))

    def _trip(self, t: float, cause: str, reaction: Reaction, message: str,
              values: dict) -> None:
        """A Python-side cause (client e-stop or stop, heartbeat): latched as the interpreted
        check latches every cause."""
        self._py_active.add(cause)
        if self.causes.get(cause, Reaction.NONE) < reaction:
            self._latch(t, cause, reaction, message, values)

    def _latch(self, t: float, cause: str, reaction: Reaction, message: str,
               values: dict) -> None:
        self.causes[cause] = reaction
        event = SafetyEvent(t, "fault", cause, reaction, message, values)
        self.log.append(event)
        self.latched_ids[cause] = event.id
        self._latched_wall[cause] = event.wall

    def _after_checks(self, t: float, new: int) -> None:
        """The rare part of a cycle: name and log the kernel's new events in the interpreted
        check's order, with the clients' requests and the heartbeat at their places; take a
        reset ticket; update the latched reaction."""
        mem = self._mem
        self._py_active.clear()
        if self._estop_request is not None:
            src = self._estop_request
            self._estop_request = None
            self._trip(t, f"estop_{src}", Reaction.HARD_STOP, f"e-stop from the {src}", {})
        for c in range(sk.N_CAUSES if new else 0):
            if c == sk.C_DRIVE:
                self._take_stop_request(t)
            if c == sk.C_PULL_STOP and mem[sk.M_PULL_STOP_END] != 0.0:
                k = sk.M_VALS + sk.N_VALUES * c
                self._log_alarm_end(t, *(float(x) for x in mem[k:k + sk.N_VALUES]))
            if mem[sk.M_NEW + c] == 0.0:
                continue
            reaction = Reaction(int(mem[sk.M_REACT + c]))
            k = sk.M_VALS + sk.N_VALUES * c
            message, values = _event_text(c, reaction, mem[k:k + sk.N_VALUES])
            if reaction == Reaction.WARN:
                self.log.append(SafetyEvent(t, "warn", CAUSES[c], reaction, message, values))
            else:
                self._latch(t, CAUSES[c], reaction, message, values)
        self._take_stop_request(t)
        if self._failed_components is not None:
            # A sensor or law that stopped updating leaves stale values on its ports: nothing
            # downstream of it can be trusted.
            self._trip(t, "component_failed", Reaction.HARD_STOP,
                       f"a block of the control loop failed ({self._failed_components})",
                       {"components": self._failed_components})
        if self.heartbeat_required and self.heartbeat_age is not None:
            age = self.heartbeat_age()
            if age > self._limits.heartbeat_timeout_s:
                self._trip(t, "heartbeat_lost", Reaction.SOFT_STOP, "client heartbeat lost",
                           {"age_s": age})
        if self._reset_tickets:
            active = {CAUSES[c] for c in range(sk.N_CAUSES) if mem[sk.M_REACT + c] != 0.0}
            self._take_reset(t, self._reset_tickets.popleft(), active | self._py_active)
        self._relatch(t)

    def _log_alarm_end(self, t: float, fz_n: float, since_t: float, how: float) -> None:
        message, values = _pull_in_stop_end_text(fz_n, since_t, how, t)
        self.log.append(SafetyEvent(t, "alarm_end", "pull_in_stop", Reaction.NONE, message,
                                    values))

    def alarms(self) -> list[dict]:
        """The alarms raised now (any thread): ``pull_in_stop`` while a pull the robot cannot
        end persists in a stop — ``{"cause", "fz_n"`` (the latest pull, N), ``"since_t"``
        (loop time it began, s), ``"message"}``. The RT status carries them (a warning is
        logged once; this says it is still so)."""
        m = self._mem
        if m[sk.M_PULL_STOP_ON] == 0.0:
            return []
        fz, since = float(m[sk.M_PULL_STOP_FZ]), float(m[sk.M_PULL_STOP_SINCE])
        return [{"cause": "pull_in_stop", "fz_n": fz, "since_t": since,
                 "message": _pull_in_stop_text(fz, since, math.nan)[0]}]

    def _take_stop_request(self, t: float) -> None:
        if self._stop_request:
            self._stop_request = False
            self._trip(t, "stop_client", Reaction.SOFT_STOP, "stop requested by a client", {})

    def _relatch(self, t: float) -> None:
        previous = self.reaction
        self.reaction = max(self.causes.values(), default=Reaction.NONE)
        if previous >= Reaction.HARD_STOP and self.reaction < Reaction.HARD_STOP:
            self._release_brakes_at(t + self.brake_release_s)   # drives back on, brakes closed
        self._mem[sk.M_REACTION] = float(self.reaction)

    def _release_brakes_at(self, t: float) -> None:
        self._mem[sk.M_BRAKES_OPEN_AT] = t

    def _forget(self, cleared: list[str]) -> None:
        """Causes a reset cleared: the kernel's latch for them and every warning's report."""
        mem = self._mem
        for c in cleared:
            k = _INDEX.get(c)
            if k is not None:
                mem[sk.M_LATCHED + k] = 0.0
        mem[sk.M_REPORTED:sk.M_REPORTED + sk.N_CAUSES] = 0.0

    def _take_reset(self, t: float, ticket: ResetTicket, active: set[str]) -> None:
        """Clear the acknowledged latched causes unless one of them is still present."""
        acked = sorted(c for c, i in self.latched_ids.items() if i in ticket.acknowledge)
        persisting = [c for c in acked if c in active]
        if persisting:
            self.log.append(SafetyEvent(t, "reset_refused", ",".join(persisting), Reaction.NONE,
                                        "reset refused: cause still present",
                                        {"causes": persisting}))
            ticket.refused = [{"id": self.latched_ids[c], "cause": c} for c in persisting]
        elif acked:
            ticket.cleared = [{"id": self.latched_ids[c], "cause": c} for c in acked]
            for c in acked:
                del self.causes[c]
                del self.latched_ids[c]
            self._forget(acked)
            self.log.append(SafetyEvent(t, "reset", ",".join(acked), Reaction.NONE,
                                        "faults reset", {"cleared": acked,
                                                         "ids": [x["id"] for x in
                                                                 ticket.cleared]}))
        ticket.still_latched = [{"id": i, "cause": c} for c, i in self.latched_ids.items()]
        ticket.done = True


class InterpretedSupervisor(Supervisor):
    """The checks in Python, as they were before they were compiled: the reference the
    compiled :class:`Supervisor` is tested against (same events, same outputs)."""

    compiled = False

    def reset_state(self) -> None:
        super().reset_state()
        self._active: set[str] = set()             # causes true in the last cycle
        self._reported: set[str] = set()           # warn causes already logged
        self._frozen_time = [0.0, 0.0, 0.0]
        self._impulse = [0.0, 0.0, 0.0]
        self._impulse_time = [0.0, 0.0, 0.0]
        self._last_q = [math.nan, math.nan, math.nan]
        # Running estimate of the force that carries each axis while its count moves (N):
        # NaN until the first cycle (then the first command: the loop starts holding still).
        self._carry = [math.nan, math.nan, math.nan]
        self._share = [math.nan, math.nan, math.nan]   # last cycle's contact share (N)
        self._quiet = [0.0, 0.0, 0.0]                  # quasi-static for this long (s)
        # The least and largest load since each count stopped (N; NaN: moving).
        self._still_lo = [math.nan, math.nan, math.nan]
        self._still_hi = [math.nan, math.nan, math.nan]
        self._contact_until = 0.0                      # touched until this loop time (s)
        self._overruns = 0
        self._pull_time = 0.0
        self._brakes_open_at = self.brake_release_s      # drives enabled at t = 0
        self._restart_saturation_window()
        self._sat_peak = [0.0, 0.0, 0.0]
        self._stop_since = math.nan                    # since when a stop is latched (s)
        self._pull_stop_time = 0.0                     # the pull in the stop lasted (s)
        self._pull_stop_since = math.nan               # ... since this loop time (s)
        self._pull_stop_on = False                     # pull_in_stop raised
        self._pull_stop_fz = 0.0                       # the latest pull read while raised (N)
        self._touch_z = math.nan                       # sliders' mean at the last contact (m)

    def _restart_saturation_window(self) -> None:
        self._sat_k = math.nan                         # the window's current bucket
        self._sat_past = [0.0, 0.0, 0.0]               # saturated time in its other buckets
        self._sat_buckets = [[0.0] * sk.SAT_BUCKETS for _ in range(3)]

    @property
    def saturated_peak_s(self) -> list[float]:
        return list(self._sat_peak)

    @property
    def carry_force_n(self) -> list[float]:
        return self._carry

    def _release_brakes_at(self, t: float) -> None:
        self._brakes_open_at = t

    def _forget(self, cleared: list[str]) -> None:
        self._reported.clear()

    def _track_carry_force(self, i: int, load: float, dt: float) -> None:
        """Update axis ``i``'s carried-force estimate with this cycle's static load (the
        applied force less the measured contact's share and the inertia's m·q̈; its count
        moved, or the brakes hold it): first-order, :data:`CARRY_TAU_S`, only once the axis
        has been quasi-static for :data:`QUASI_STATIC_S` (the first cycle seeds it), and by at
        most ``holding_force_n`` per :data:`CARRY_TAU_S`: a change of force the acceleration
        estimate has not caught up with yet (it lags ~10 ms) moves it little."""
        c = self._carry[i]
        if math.isnan(c):
            self._carry[i] = load
        elif self._quiet[i] >= QUASI_STATIC_S:
            step = (load - c) * dt / (CARRY_TAU_S + dt)
            cap = self.holding_force_n * dt / CARRY_TAU_S
            self._carry[i] = c + (cap if step > cap else (-cap if -cap > step else step))  # noqa: FURB136

    def alarms(self) -> list[dict]:
        if not self._pull_stop_on:
            return []
        fz, since = self._pull_stop_fz, self._pull_stop_since
        return [{"cause": "pull_in_stop", "fz_n": fz, "since_t": since,
                 "message": _pull_in_stop_text(fz, since, math.nan)[0]}]

    def _check_pull_in_stop(self, t: float, dt: float, fz_n: float, stale: bool) -> None:
        """``pull_in_stop`` (the compiled ``_pull_in_stop``'s arithmetic, which says why): in
        a latched stop, a pull read for :data:`~rt.safety.supervisor_kernel.PULL_IN_STOP_S`
        raises a warning once and keeps the alarm up until a sample reads no pull or the stop
        is reset (an ``alarm_end`` event)."""
        fz_n = float(fz_n)
        on = self._pull_stop_on
        if self.reaction < Reaction.SOFT_STOP:
            if on:
                self._pull_stop_on = False
                self._log_alarm_end(t, self._pull_stop_fz, self._pull_stop_since, 2.0)
            self._pull_stop_time = 0.0
            self._pull_stop_since = math.nan
            return
        if stale or math.isnan(fz_n):
            if on:
                self._active.add("pull_in_stop")
            return
        if not fz_n < sk.PULL_IN_STOP_FZ_N:
            if on:
                self._pull_stop_on = False
                self._pull_stop_fz = fz_n
                self._log_alarm_end(t, fz_n, self._pull_stop_since, 1.0)
            self._pull_stop_time = 0.0
            self._pull_stop_since = math.nan
            return
        if math.isnan(self._pull_stop_since):
            self._pull_stop_since = t
        cap = sk.PULL_DT_PERIODS * self.period_s
        self._pull_stop_time += dt if dt < cap else cap  # noqa: FURB136
        if on:
            self._active.add("pull_in_stop")
            self._pull_stop_fz = fz_n
            return
        if self._pull_stop_time >= sk.PULL_IN_STOP_S:
            self._active.add("pull_in_stop")
            self._pull_stop_on = True
            self._pull_stop_fz = fz_n
            message, values = _pull_in_stop_text(fz_n, self._pull_stop_since,
                                                 self._pull_stop_time)
            self.log.append(SafetyEvent(t, "warn", "pull_in_stop", Reaction.WARN, message,
                                        values))

    def _check_contact_lost(self, q, fz_n: float, stale: bool, saturated: bool,
                            trip: Callable[..., None]) -> None:
        """``contact_lost`` (the compiled ``_contact_lost``'s arithmetic, which says why)."""
        if not self.force_control:
            self._touch_z = math.nan
            return
        fz_n = float(fz_n)
        if stale or saturated or math.isnan(fz_n):
            return
        h = (float(q[0]) + float(q[1]) + float(q[2])) / 3.0
        if fz_n > sk.CONTACT_HELD_N:
            self._touch_z = h
            return
        rise = h - self._touch_z
        if rise > sk.CONTACT_LOST_RISE_M:
            message, values = _contact_lost_text(fz_n, rise, self._touch_z)
            trip("contact_lost", Reaction.SOFT_STOP, message, **values)

    def _saturated_time(self, t: float, dt: float, tau) -> list[float]:
        """Each axis' time with its command at the drive's limit (``|τ| ≥``
        ``applied_force_max_n``) in the last ``saturation_window_s`` (s), counted while the
        drives are on: the window is ``SAT_BUCKETS`` buckets of loop time, those it left since
        the last cycle emptied (all of them after a gap longer than it, or at the start)."""
        if self.reaction < Reaction.SOFT_STOP:
            self._stop_since = math.nan
        elif math.isnan(self._stop_since):
            self._stop_since = t
        nb = sk.SAT_BUCKETS
        window = self.limits.saturation_window_s
        k = math.floor(t / (window / nb))
        kf = float(k)
        last = self._sat_k
        buckets = self._sat_buckets
        if kf != last:
            if kf > last and kf - last < nb:
                for j in range(int(last) + 1, k + 1):
                    for i in range(3):
                        buckets[i][j % nb] = 0.0
            else:
                for i in range(3):
                    buckets[i][:] = [0.0] * nb
            self._sat_k = kf
            cur = k % nb
            for i in range(3):
                past = 0.0
                for s in range(nb):
                    if s != cur:
                        past += buckets[i][s]
                self._sat_past[i] = past
        cur = k % nb
        limit = self.applied_force_max_n
        drives_on = self.reaction < Reaction.HARD_STOP
        out = []
        for i in range(3):
            if drives_on and abs(tau[i]) >= limit:
                buckets[i][cur] += dt
            saturated = self._sat_past[i] + buckets[i][cur]
            self._sat_peak[i] = max(self._sat_peak[i], saturated)
            out.append(saturated)
        return out

    def _frozen_net_force(self, i: int, load: float, lag_allowance: float) -> float:
        """The part of axis ``i``'s command that must accelerate it although its count has not
        moved (N; ≤ 0: none).

        A still axis is in static equilibrium: its command balances the load it carries (the
        links', the platform's and any payload's weight — unknown to the supervisor, a
        patient may stand on the platform) within the friction it can hold. The load is
        estimated as the force that carried the axis while its count last moved
        (``carry_force_n``), so a heavy payload is not read as a frozen encoder; a truly
        frozen encoder makes the controller push ever further from that force (the reference
        runs away from a count that does not move), and the excess beyond the friction band
        (``holding_force_n``) must move the axis. A load that changed unmeasured as the count
        stopped (a payload landing) is not in the carry, but it is constant: whatever it is,
        the still axis's loads stay within the friction band of each other. The distance
        taken is the smaller of the two (``_still_range``): a frozen encoder's runaway
        command leaves both. ``load`` is the command less the measured
        contact's share (what presses the platform holds that much of it); ``lag_allowance``
        what the sensor's lag may hide of that share (N).
        """
        carry = self._carry[i]
        if math.isnan(carry):
            carry = 0.0
        off = abs(load - carry)
        spread = self._still_range(i, load)
        off = off if off < spread else spread  # noqa: FURB136
        return off - self.holding_force_n - lag_allowance

    def _still_range(self, i: int, load: float) -> float:
        """How far axis ``i``'s ``load`` is from the farthest load it held since its count
        stopped (N), the stretch's range updated with it."""
        lo = self._still_lo[i]
        hi = self._still_hi[i]
        if math.isnan(lo):
            lo = load
            hi = load
        else:
            lo = load if load < lo else lo  # noqa: FURB136
            hi = load if load > hi else hi  # noqa: FURB136
        self._still_lo[i] = lo
        self._still_hi[i] = hi
        return hi - load if hi - load > load - lo else load - lo  # noqa: FURB136

    def check(self, t: float, dt: float, q, est_status: int, qd, qdd, fk_ok: bool, roll: float,
              pitch: float, roll_rate: float, pitch_rate: float, q_ref, qd_ref, tau,
              force_n: float, wrench_stale: bool, wrench_saturated: bool, hw_estop: bool,
              hand_stop: bool, drive_failed: bool, fz_n: float = math.nan,
              failed_components: str | None = None, contact_share=None) -> Reaction:
        """Run every check; returns the latched reaction for this cycle. ``force_n`` is the
        magnitude of the sensor's force, ``fz_n`` the platform's push along its z (N);
        ``failed_components`` names the loop's components a fault put in error (None: none);
        ``contact_share`` the measured contact's share of each actuator force (N; None:
        none)."""
        share = (0.0, 0.0, 0.0) if contact_share is None else \
            tuple(float(x) for x in contact_share)
        lim = self.limits
        active = self._active
        active.clear()

        def trip(cause: str, reaction: Reaction, message: str, **values) -> None:
            active.add(cause)
            if reaction == Reaction.WARN:
                if cause not in self._reported:
                    self._reported.add(cause)
                    self.log.append(SafetyEvent(t, "warn", cause, reaction, message, values))
                return
            if self.causes.get(cause, Reaction.NONE) < reaction:
                self.causes[cause] = reaction
                event = SafetyEvent(t, "fault", cause, reaction, message, values)
                self.log.append(event)
                self.latched_ids[cause] = event.id
                self._latched_wall[cause] = event.wall

        # -- stop inputs
        if self._estop_request is not None:
            src = self._estop_request
            self._estop_request = None
            trip(f"estop_{src}", Reaction.HARD_STOP, f"e-stop from the {src}")
        if hw_estop:
            trip("estop_hardware", Reaction.HARD_STOP, "hardware e-stop pressed")
        if hand_stop:
            trip("hand_stop", Reaction.SOFT_STOP, "patient's hand-held stop pressed")
        if self._stop_request:
            self._stop_request = False
            trip("stop_client", Reaction.SOFT_STOP, "stop requested by a client")
        if drive_failed:
            trip("drive_channel", Reaction.HARD_STOP, "an actuator channel failed on both cards")
        if failed_components is not None:
            # A sensor or law that stopped updating leaves stale values on its ports: nothing
            # downstream of it can be trusted.
            trip("component_failed", Reaction.HARD_STOP,
                 f"a block of the control loop failed ({failed_components})",
                 components=failed_components)
        # -- sensors and kinematics
        if not fk_ok:
            trip("fk_failed", Reaction.HARD_STOP, "forward kinematics failed: pose unknown")
        if est_status == JUMP_STATUS:
            trip("encoder_jump", Reaction.HARD_STOP, "encoder reading jumped beyond physics",
                 q=list(q))
        free = not (force_n > self.contact_force_n)         # NaN (no sensor) counts as free
        if not free:
            self._contact_until = t + self.contact_release_s
        # Free for the reference-speed criterion: nothing measured for the release time.
        untouched = free and t >= self._contact_until
        # In a hard stop the drives are off and the brakes hold: a still count is expected, and
        # judging it against the law's (unapplied) force would latch a cause no reset clears.
        brakes_open = t >= self._brakes_open_at and self.reaction < Reaction.HARD_STOP
        for i in range(3):
            qi = q[i]
            # The axis' own load: the force its drive applies (the command saturated at the
            # DAC's limit) less what the measured contact takes of it.
            ta = float(tau[i])
            cap = self.applied_force_max_n
            applied = cap if ta > cap else (-cap if -cap > ta else ta)  # noqa: FURB136
            load = applied - share[i]
            # Quasi-static: the estimated acceleration small for QUASI_STATIC_S.
            if abs(qdd[i]) <= QUASI_STATIC_ACCEL:
                self._quiet[i] += dt
            else:
                self._quiet[i] = 0.0
            last_share = self._share[i]
            if math.isnan(last_share):
                last_share = share[i]
            # The sensor shows the contact late: the true share may be ahead of the measured
            # one by its rate times the sensor's lag (a contact's onset), held unseen.
            lag_allowance = abs(share[i] - last_share) / dt * self.force_lag_s
            self._share[i] = share[i]
            if qi == self._last_q[i] and brakes_open:
                # Two ways to know the slider must have moved although its count did not:
                # the reference has been moving it for ``frozen_encoder_s`` while nothing
                # touched the platform, or its load beyond what friction holds must have
                # carried the axis' inertia over ``FROZEN_COUNTS`` counts: x = J T / (2 m),
                # J = ∫F dt.
                if abs(qd_ref[i]) >= lim.frozen_min_ref_speed_m_s and untouched:
                    self._frozen_time[i] += dt
                else:
                    self._frozen_time[i] = 0.0
                net = self._frozen_net_force(i, load, lag_allowance)
                if net > 0.0:
                    self._impulse[i] += net * dt
                    self._impulse_time[i] += dt
                else:
                    self._impulse[i] = 0.0
                    self._impulse_time[i] = 0.0
                moved = self._impulse[i] * self._impulse_time[i] / (2.0 * self.axis_mass_kg)
                if moved >= FROZEN_COUNTS * self.count_m or \
                        self._frozen_time[i] >= lim.frozen_encoder_s:
                    trip(f"encoder_frozen_{i}", Reaction.HARD_STOP,
                         f"encoder {i} frozen while commanded to move",
                         frozen_s=self._frozen_time[i], expected_m=moved,
                         qd_ref=float(qd_ref[i]))
            else:
                self._frozen_time[i] = 0.0
                self._impulse[i] = 0.0
                self._impulse_time[i] = 0.0
                self._still_lo[i] = math.nan
                self._still_hi[i] = math.nan
                # The static load (what holds the axis once it stops): the inertia taken out.
                self._track_carry_force(i, load - self.axis_mass_kg * float(qdd[i]), dt)
            self._last_q[i] = qi
            # -- stroke, speed, acceleration, tracking, actuator force
            if qi < lim.stroke_lo_m or qi > lim.stroke_hi_m:
                trip(f"stroke_{i}", Reaction.HARD_STOP, f"slider {i} beyond its stroke",
                     q=qi)
            elif qi < lim.stroke_lo_m + lim.stroke_margin_m or \
                    qi > lim.stroke_hi_m - lim.stroke_margin_m:
                trip(f"stroke_margin_{i}", Reaction.SOFT_STOP,
                     f"slider {i} inside the stroke-end margin", q=qi)
            if abs(qd[i]) > lim.max_slider_speed_m_s:
                trip(f"speed_{i}", Reaction.SOFT_STOP, f"slider {i} too fast", qd=float(qd[i]))
            if abs(qdd[i]) > lim.max_slider_accel_m_s2:
                trip(f"accel_{i}", Reaction.WARN, f"slider {i} acceleration beyond the robot "
                     "limit", qdd=float(qdd[i]))
            # In force control the position reference is only the contact's starting pose.
            err = 0.0 if self.force_control else abs(qi - q_ref[i])
            if err > 3.0 * lim.max_tracking_error_m:
                trip(f"tracking_{i}", Reaction.HARD_STOP, f"slider {i} tracking error", error=err)
            elif err > lim.max_tracking_error_m:
                trip(f"tracking_{i}", Reaction.SOFT_STOP, f"slider {i} tracking error", error=err)
            if abs(tau[i]) > lim.max_actuator_force_n:
                trip(f"actuator_force_{i}", Reaction.WARN, f"actuator {i} force command beyond "
                     "the robot limit (saturated)", tau=float(tau[i]))
        # -- patient ROM with the braking cushion, angular speed
        if fk_ok:
            for name, angle, rate, lo, hi in (("roll", roll, roll_rate, lim.roll_min,
                                               lim.roll_max),
                                              ("pitch", pitch, pitch_rate, lim.pitch_min,
                                               lim.pitch_max)):
                w = abs(rate)
                braking = self.braking_angle(w, dt)
                if angle > hi + lim.rom_tolerance or angle < lo - lim.rom_tolerance:
                    trip(f"rom_{name}", Reaction.HARD_STOP, f"{name} beyond the patient's ROM",
                         angle_deg=math.degrees(angle))
                elif (rate >= 0.0 and angle + braking >= hi) or \
                        (rate <= 0.0 and angle - braking <= lo):
                    trip(f"rom_{name}", Reaction.SOFT_STOP,
                         f"{name} reaching the patient's ROM end", angle_deg=math.degrees(angle),
                         rate_deg_s=math.degrees(rate))
                if w > lim.max_angular_speed:
                    trip(f"angular_speed_{name}", Reaction.SOFT_STOP,
                         f"{name} rate beyond the patient's limit", rate_deg_s=math.degrees(rate))
        # -- force sensor
        if wrench_saturated:
            trip("force_saturated", Reaction.SOFT_STOP, "force sensor saturated (overload)")
        if wrench_stale and t >= self.startup_grace_s:
            trip("force_stale", Reaction.SOFT_STOP if self.force_control else Reaction.WARN,
                 "force sensor data stale")
        elif not wrench_saturated:
            if math.isnan(force_n) and self.force_control:
                trip("force_implausible", Reaction.SOFT_STOP, "force sensor reading invalid")
            elif force_n > lim.max_force_n:
                # Beyond the limit: drop the drive force at once, the only reaction fast enough
                # against a stiff contact (2e6 N/m: 5 % of 800 N is 20 µm of travel).
                trip("force_limit", Reaction.HARD_STOP, "platform force beyond the limit",
                     force_n=force_n)
            elif force_n > FORCE_CUSHION * lim.max_force_n:
                trip("force_limit", Reaction.SOFT_STOP, "platform force reaching the limit",
                     force_n=force_n)
        if self.force_control and fz_n < sk.PULL_FZ_N:
            # Stall-aware: a cycle adds at most PULL_DT_PERIODS periods (a stall is one sample).
            cap = sk.PULL_DT_PERIODS * self.period_s
            self._pull_time += dt if dt < cap else cap  # noqa: FURB136
            if self._pull_time >= lim.max_pull_s:
                trip("pulling", Reaction.SOFT_STOP, "the platform is pulling on the foot "
                     "(measured Fz below 0 N)", fz_n=fz_n, for_s=self._pull_time)
        else:
            self._pull_time = 0.0
        # -- timing and clients
        if dt > 1.5 * self.period_s:
            self._overruns += 1
            if self._overruns >= lim.deadline_overruns:
                trip("deadline_overruns", Reaction.SOFT_STOP, "consecutive deadline overruns",
                     count=self._overruns, dt=dt)
        else:
            self._overruns = 0
        # -- sustained drive saturation
        for i, saturated in enumerate(self._saturated_time(t, dt, tau)):
            window = lim.saturation_window_s
            if saturated > lim.max_saturated_fraction * window:
                # A whole window into a soft stop and still saturated: the stop (an unstable
                # force law ramping its force down) does not end it.
                reaction = Reaction.HARD_STOP if t - self._stop_since >= window \
                    else Reaction.SOFT_STOP
                message, values = _saturation_text(i, reaction, saturated, window,
                                                   self.applied_force_max_n)
                trip(f"drive_saturated_{i}", reaction, message, **values)
        self._check_pull_in_stop(t, dt, fz_n, wrench_stale)
        self._check_contact_lost(q, fz_n, wrench_stale, wrench_saturated, trip)
        if self.heartbeat_required and self.heartbeat_age is not None:
            age = self.heartbeat_age()
            if age > lim.heartbeat_timeout_s:
                trip("heartbeat_lost", Reaction.SOFT_STOP, "client heartbeat lost", age_s=age)
        # -- latch and reset
        if self._reset_tickets:
            self._take_reset(t, self._reset_tickets.popleft(), active)
        self._relatch(t)
        return self.reaction
