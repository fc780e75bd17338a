"""The loop's one reference sequencer: approach → play → return → rest, for every program.

    REST ──request(program)──▶ APPROACH ──first sample reached──▶ PLAY ──done──▶ RETURN ──▶ REST
                                   │                              │   ▲abort        │
                                   └────── supervisor soft/hard stop ─┴─────▶ STOPPED ──reset──▶ REST

* APPROACH: a ruckig (jerk-limited) move from where the reference is to the program's first
  sample; position limits are checked by our approach generator, never assumed from ruckig.
  A program that starts in force mode then holds there while the force reader tares the
  sensor on the still unloaded platform (:mod:`rt.components.tare`); a refused tare (the
  platform is loaded) ends the program before it plays (RETURN, ``last_error`` says why,
  ``tare_refused`` counts it), without latching a fault.
* PLAY: the program writes one sample per cycle (:mod:`rt.references.program`); in force mode
  the hybrid controller tracks ``force`` in z with the angles of ``pose`` held.
* RETURN: the jerk-limited stop brings the reference to rest from the program's last state (or
  from where an abort caught it); a force reference decays to zero (time constant
  ``force_ramp_s``, zero below 1 N), then the position law holds where the robot is.
* STOPPED: the supervisor soft-stopped (same braking and ramp as RETURN, but latched until the
  faults are reset) or hard-stopped (the reference follows the measured position so nothing
  jumps when the drives come back). After a reset it holds where the robot is (REST).
* REST: holding where the robot is, no program.

Programs are requested from any thread (:meth:`ProgramReference.request`) and taken at the next
cycle boundary; so is :meth:`ProgramReference.request_abort` (session abort: soft stop then
return to rest, without latching a fault).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from rt.components.tare import TareState, refusal_message
from rt.engine import Array, Component
from rt.references.approach import Approach, ApproachStatus
from rt.references.program import ForcePreview, Mode, Program, ProgramInput, ReferenceOutput
from rt.safety.events import SupervisorMode

#: First-order smoothing of F̈_d per cycle (≈ 35 Hz at 1 kHz).
F_DDOT_SMOOTHING = 0.2
#: Half-width (samples) of the centred difference that gives the previewed F̈_d: the table is
#: known on both sides of the sample read ahead, so the derivative is smoothed without lag
#: (a recorded gait force's 1 kHz noise through a one-sample difference asks metres per
#: second squared of the platform; ±5 samples at 1 kHz: first zero at 100 Hz).
PREVIEW_F_DDOT_HALF_WIDTH = 5
#: Component status codes (non-zero = the cycle's block failed).
STATUS_APPROACH_FAILED = 20
STATUS_PROGRAM_FAILED = 21


class Phase(IntEnum):
    """The sequencer's phase, carried on its ``phase`` port."""

    APPROACH = 0
    PLAY = 1
    RETURN = 2
    STOPPED = 3
    REST = 4

    @property
    def moving(self) -> bool:
        """True while a program owns the motion (a client must keep heartbeating)."""
        return self in (Phase.APPROACH, Phase.PLAY, Phase.RETURN)


#: How long a program's watcher waits after seeing the sequencer stopped, so the stop's events
#: reach the loop's event log before it records them (s).
STOP_EVENTS_SETTLE_S = 0.3


def program_outcome(phases, seen_motion: bool) -> tuple[bool, str | None]:
    """What a block of the session tap's phase column says of a program watched from outside
    the loop (a recording thread): whether it has moved yet (any phase up to RETURN, carried
    over from earlier blocks in ``seen_motion``), and its outcome once decided: "completed"
    when the sequencer is back at rest after moving, "stopped" when it stopped, else None."""
    seen_motion = seen_motion or bool((phases <= Phase.RETURN).any())
    last = Phase(int(phases[-1]))
    if seen_motion and last == Phase.REST:
        return seen_motion, "completed"
    if last == Phase.STOPPED:
        return seen_motion, "stopped"
    return seen_motion, None


@dataclass(frozen=True)
class _Request:
    program: Program
    out: ReferenceOutput
    approach_min_s: float | None = None
    rest_q: tuple[float, float, float] | None = None
    return_min_s: float | None = None


@dataclass
class _State:
    phase: Phase = Phase.REST
    mode: SupervisorMode = SupervisorMode.RUN
    started: bool = False
    k: int = 0                       # samples played of the current program
    taring: bool = False             # holding at the first sample while the sensor is tared
    tare_measuring: bool = False     # the force reader has started this tare
    tares_before: float = 0.0        # the force reader's tare count when the tare began


class ProgramReference(Component):
    """Ports: in ``q_meas``: float64[3] m; in ``mode``: float64[1] (the supervisor's
    :class:`SupervisorMode`, one cycle late); in ``wrench``: float64[6] (sensor frame: the
    patient's torques for interactive programs). Out ``q_ref``, ``qd_ref``, ``qdd_ref``:
    float64[3] (m, m/s, m/s²); ``force``: float64[3] (F_d N, Ḟ_d N/s, F̈_d N/s²); ``pose``:
    float64[3] (z m, roll, pitch rad); ``ctrl_mode``: float64[1] (:class:`Mode`); ``phase``:
    float64[1] (:class:`Phase`); ``progress``: float64[1] (0..1 of the program played);
    ``tare_request``: float64[1] (1 while a tare is wanted; to the force reader, one cycle
    late); in ``tare``: the force reader's tare port (state, count, refusal, mean force).

    Attributes readable from other threads: ``epoch`` (programs started so far), ``refused``
    (requests whose approach was refused) and ``last_error`` (why), ``busy``.
    """

    def __init__(self, name: str, stroke: tuple[float, float], dt: float,
                 program: Program | None = None, force_ramp_s: float = 0.3):
        super().__init__(name)
        self.approach = Approach(dt=dt, stroke=stroke)
        self.force_ramp_s = force_ramp_s
        self.q_meas = self.declare_input("q_meas", Array(3))
        self.mode = self.declare_input("mode", Array(1))
        self.wrench = self.declare_input("wrench", Array(6))
        self.q_ref = self.declare_output("q_ref", Array(3))
        self.qd_ref = self.declare_output("qd_ref", Array(3))
        self.qdd_ref = self.declare_output("qdd_ref", Array(3))
        self.force = self.declare_output("force", Array(3))
        self.force_preview = self.declare_output("force_preview", Array(3))
        #: How far ahead ``force_preview`` reads a previewable force program (samples; 0: no
        #: preview). Set by the loop's builder from the force law's ``preview_s``.
        self.preview_steps = 0
        self._preview: ForcePreview | None = None
        self._ahead = np.zeros(2)
        self._ahead_next = np.zeros(2)
        self._ahead_read = False
        self.pose = self.declare_output("pose", Array(3))
        self.ctrl_mode = self.declare_output("ctrl_mode", Array(1))
        self.phase = self.declare_output("phase", Array(1), initial=np.full(1, float(Phase.REST)))
        self.progress = self.declare_output("progress", Array(1))
        self.tare_request = self.declare_output("tare_request", Array(1))
        self.tare = self.declare_input("tare", Array(10))
        self.tare_refused = 0
        self._initial = None if program is None else _Request(program, program.new_output())
        self._pending: _Request | None = None
        self._abort = False
        self.program: Program | None = None
        self._out: ReferenceOutput | None = None
        self._n = 1
        self._req: _Request | None = None
        self._inp = ProgramInput()
        self._needs_tare = False
        self.epoch = 0
        self.refused = 0
        self.last_error = ""

    # ------------------------------------------------------------------ any thread
    def request(self, program: Program, *, approach_min_s: float | None = None,
                rest_q: tuple[float, float, float] | None = None,
                return_min_s: float | None = None) -> None:
        """Play ``program`` from the next cycle boundary. Refused at that boundary
        (``refused`` += 1, ``last_error``) when the supervisor is stopped, a program is
        running, or the approach cannot be planned.

        Args:
            program: what to play (validated).
            approach_min_s: the approach takes at least this long (s; the thesis used 8 s
                splines); None = time-optimal within the approach's limits.
            rest_q: where RETURN ends (slider positions, m); None = brake to rest from the
                program's last state.
            return_min_s: the return to ``rest_q`` takes at least this long (s).
        """
        # The output is allocated here, on the caller's thread, not in the cycle.
        self._pending = _Request(program, program.new_output(), approach_min_s, rest_q,
                                 return_min_s)

    def request_abort(self) -> None:
        """Soft stop of the program without a fault: brake, ramp force down, then rest."""
        self._abort = True

    @property
    def busy(self) -> bool:
        """True while a program is pending, approaching, playing or returning."""
        return self._pending is not None or (
            self.state is not None and self.state.phase.moving)

    @property
    def current_phase(self) -> Phase:
        return Phase.REST if self.state is None else self.state.phase

    # ------------------------------------------------------------------ lifecycle
    def make_state(self) -> _State:
        return _State()

    def on_start(self) -> None:
        self.state = _State()
        self._pending = self._initial

    # ------------------------------------------------------------------ the cycle
    def _begin(self, req: _Request) -> None:
        st = self.state
        program = req.program
        out = req.out
        program.reset()
        program.update(out, self._inp)
        program.reset()
        if st.phase == Phase.REST or not st.started:
            self.approach.reset(self.q_meas.data if not st.started else self.q_ref.data)
        else:
            self.approach.reset(self.q_ref.data, self.qd_ref.data, self.qdd_ref.data)
        status = self.approach.set_target(out.q_ref, out.qd_ref, out.qdd_ref,
                                          minimum_duration=req.approach_min_s)
        st.started = True
        if status != ApproachStatus.WORKING:
            self.last_error = f"approach to the program refused: {status.name}"
            self.refused += 1
            self.approach.reset(self.q_ref.data)
            st.phase = Phase.REST
            return
        self.program, self._out, self._req = program, out, req
        self._preview = program if isinstance(program, ForcePreview) else None
        self._n = max(1, round(program.duration_s / self.approach.dt))
        st.k = 0
        st.taring = False
        st.phase = Phase.APPROACH
        self._needs_tare = out.mode == Mode.FORCE
        self.epoch += 1

    def _brake(self) -> None:
        """Jerk-limited stop from the current reference; the force ramps down in the cycle."""
        self.approach.reset(self.q_ref.data, self.qd_ref.data, self.qdd_ref.data)
        self.approach.soft_stop()

    def _ramp_force(self, dt: float) -> None:
        """Ramp a force reference down; at zero the position law holds where the robot is
        (not where the contact started: under load the platform had moved into it)."""
        f = self.force.data
        if self.ctrl_mode.data[0] > 0.5:
            f[0] = max(0.0, f[0] - (abs(f[0]) + 1.0) * dt / self.force_ramp_s) \
                if f[0] > 1.0 else 0.0
            f[1] = f[2] = 0.0
            if f[0] == 0.0:
                self.ctrl_mode.data[0] = float(Mode.POSITION)
                self.q_ref.data[:] = self.q_meas.data
                self.qd_ref.data[:] = 0.0
                self.qdd_ref.data[:] = 0.0
                self.approach.reset(self.q_meas.data)

    def update(self, t: float, dt: float) -> int:
        st = self.state
        mode = SupervisorMode.from_port(self.mode.data[0])
        if not st.started and self._pending is None:
            self.approach.reset(self.q_meas.data)       # nothing to play: hold where it is
            self.q_ref.data[:] = self.q_meas.data
            st.started = True
        if mode != st.mode:
            if mode == SupervisorMode.SOFT_STOP and st.phase in (Phase.APPROACH, Phase.PLAY,
                                                                 Phase.RETURN):
                self._brake()
                st.phase = Phase.STOPPED
            elif mode == SupervisorMode.HARD_STOP:
                st.phase = Phase.STOPPED
            elif mode == SupervisorMode.RUN:              # reset: hold where the robot is
                self.approach.reset(self.q_meas.data)
                st.phase = Phase.REST
            st.mode = mode
        if self._pending is not None:
            req, self._pending = self._pending, None
            if mode == SupervisorMode.RUN and not st.phase.moving:
                self._begin(req)
            else:
                self.last_error = ("the robot is stopped: reset the faults first"
                                   if mode != SupervisorMode.RUN else "a program is running")
                self.refused += 1
        if self._abort:
            self._abort = False
            if st.phase in (Phase.APPROACH, Phase.PLAY):
                self._brake()                  # a force reference ramps down in RETURN
                st.phase = Phase.RETURN
        f = self.force.data
        emitted = st.phase            # the phase that produced this cycle's reference
        if mode == SupervisorMode.HARD_STOP:
            self.q_ref.data[:] = self.q_meas.data
            self.qd_ref.data[:] = 0.0
            self.qdd_ref.data[:] = 0.0
            f[:] = 0.0
            self.ctrl_mode.data[0] = float(Mode.POSITION)
        elif st.phase == Phase.STOPPED or st.phase == Phase.REST:
            self.approach.update(self.q_ref.data, self.qd_ref.data, self.qdd_ref.data)
            self._ramp_force(dt)
        elif st.phase == Phase.APPROACH:
            status = self.approach.update(self.q_ref.data, self.qd_ref.data, self.qdd_ref.data)
            if status < 0:
                return STATUS_APPROACH_FAILED
            if status == ApproachStatus.FINISHED and self._needs_tare:
                status = self._tare_step()
            if status == ApproachStatus.FINISHED:
                # This cycle emitted the first sample's state exactly: consume sample 0 so the
                # next cycle plays sample 1 (no repeated sample at the seam).
                assert self.program is not None and self._out is not None
                self.program.update(self._out, self._inp)
                st.k = 1
                st.phase = Phase.PLAY
        elif st.phase == Phase.PLAY:
            if self._play(dt) < 0:
                return STATUS_PROGRAM_FAILED
        elif st.phase == Phase.RETURN:
            status = self.approach.update(self.q_ref.data, self.qd_ref.data, self.qdd_ref.data)
            self._ramp_force(dt)
            if status == ApproachStatus.FINISHED and self.ctrl_mode.data[0] < 0.5:
                st.phase = Phase.REST
        if st.phase != Phase.APPROACH:
            self.tare_request.data[0] = 0.0      # a stop or an abort ends a tare in progress
        if self._ahead_read:
            self._ahead_read = False
        else:
            # No preview this cycle (not playing, a ramp down, a program without one): the
            # law tracks the force reference itself.
            self.force_preview.data[:] = f
        self.phase.data[0] = float(emitted if emitted in (Phase.APPROACH, Phase.PLAY) else st.phase)
        self.progress.data[0] = min(1.0, st.k / self._n)
        return 0

    def _previewing(self) -> bool:
        return (self._preview is not None and self.preview_steps > 0
                and self.ctrl_mode.data[0] > 0.5)

    def _read_ahead(self, index: int, dt: float) -> None:
        """``force_preview`` = the program's force ``preview_steps`` samples after ``index``
        (the sample just played)."""
        pv = self._preview
        assert pv is not None
        ahead, nxt = self._ahead, self._ahead_next
        k = index + self.preview_steps
        h = PREVIEW_F_DDOT_HALF_WIDTH
        pv.force_at(k + h, nxt)
        f_dot_next = float(nxt[1])
        pv.force_at(k - h, nxt)
        pv.force_at(k, ahead)
        out = self.force_preview.data
        out[0] = ahead[0]
        out[1] = ahead[1]
        out[2] = (f_dot_next - nxt[1]) / (2.0 * h * dt)
        self._ahead_read = True

    def _tare_step(self) -> ApproachStatus:
        """At the first sample of a force program: ask for a tare and hold until the force
        reader has one (then FINISHED: play) or refused it (then RETURN, nothing played)."""
        st = self.state
        tare = self.tare.data
        if not st.taring:
            st.taring = True
            st.tare_measuring = False
            st.tares_before = float(tare[1])
            self.tare_request.data[0] = 1.0
            return ApproachStatus.WORKING
        state = int(tare[0])
        if state == TareState.MEASURING:
            st.tare_measuring = True
        if not st.tare_measuring:          # the port still shows an earlier tare's outcome
            return ApproachStatus.WORKING
        if state == TareState.DONE and tare[1] > st.tares_before:
            self.tare_request.data[0] = 0.0
            self._needs_tare = False
            return ApproachStatus.FINISHED
        if state == TareState.REFUSED:
            self.tare_request.data[0] = 0.0
            self.last_error = "ATI tare refused: " + refusal_message(int(tare[2]),
                                                                     float(tare[3]))
            self.tare_refused += 1
            self._brake()
            st.phase = Phase.RETURN
        return ApproachStatus.WORKING

    def _play(self, dt: float) -> int:
        st = self.state
        o = self._out
        assert o is not None and self.program is not None
        w = self.wrench.data
        inp = self._inp
        # The patient's torques on the platform about roll (x) and pitch (y), N·m.
        inp.tau_roll_nm = 0.0 if math.isnan(w[3]) else float(w[3])
        inp.tau_pitch_nm = 0.0 if math.isnan(w[4]) else float(w[4])
        inp.force_x_n = 0.0 if math.isnan(w[0]) else float(w[0])
        inp.force_y_n = 0.0 if math.isnan(w[1]) else float(w[1])
        inp.force_z_n = 0.0 if math.isnan(w[2]) else float(w[2])
        status = self.program.update(o, inp)
        if status < 0:
            return status
        st.k += 1
        self.q_ref.data[:] = o.q_ref
        self.qd_ref.data[:] = o.qd_ref
        self.qdd_ref.data[:] = o.qdd_ref
        self.pose.data[:] = o.pose_ref
        force_mode = o.mode == Mode.FORCE
        self.ctrl_mode.data[0] = float(o.mode)
        f = self.force.data
        fz = o.fz_ref
        if force_mode and not math.isnan(fz):
            f_dot = o.fz_ref_dot
            # F̈_d by a low-passed first difference of Ḟ_d (only the small inertia feedforward
            # uses it; recorded gait forces are not smooth to second order).
            raw = (f_dot - f[1]) / dt if st.k > 1 else 0.0
            f[2] += F_DDOT_SMOOTHING * (raw - f[2])
            f[0], f[1] = fz, f_dot
            if self._previewing() and not o.done:
                self._read_ahead(o.index, dt)
        else:
            f[:] = 0.0
        if o.done:
            if force_mode:
                # Leaving force control: the position law takes over where the robot is.
                self.q_ref.data[:] = self.q_meas.data
                self.qd_ref.data[:] = 0.0
                self.qdd_ref.data[:] = 0.0
            req = self._req
            if req is not None and req.rest_q is not None:
                self.approach.reset(self.q_ref.data, self.qd_ref.data, self.qdd_ref.data)
                if self.approach.set_target(req.rest_q, minimum_duration=req.return_min_s) \
                        != ApproachStatus.WORKING:
                    self._brake()            # rest unreachable: brake where it is instead
            else:
                self._brake()
            self.ctrl_mode.data[0] = float(Mode.POSITION)
            f[:] = 0.0
            st.phase = Phase.RETURN
        return 0
