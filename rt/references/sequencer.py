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
  faults are reset; in force control the position law holds where the robot is at once, and
  that hold yields upward while the foot is pulled: ``ProgramReference._yield_step``) or
  hard-stopped (the reference follows the measured position so nothing jumps when the drives
  come back). After a reset it holds where the robot is (REST).
* REST: holding where the robot is, no program.

Programs are requested from any thread (:meth:`ProgramReference.request`) and taken at the next
cycle boundary; so is :meth:`ProgramReference.request_abort` (session abort: soft stop then
return to rest, without latching a fault).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum
from typing import Any

import numpy as np

from rt.components.tare import refusal_message
from rt.engine import Array, Component
from rt.epoch import bump
from rt.errors import ConfigurationError
from rt.references import approach_kernel as ak
from rt.references import sequencer_kernel as sk
from rt.references.approach import Approach, ApproachStatus
from rt.references.program import (
    FZ,
    ForcePreview,
    Mode,
    Program,
    ProgramInput,
    ProgramTable,
    ReferenceOutput,
)
from rt.references.sequencer_kernel import F_DDOT_SMOOTHING, PREVIEW_F_DDOT_HALF_WIDTH
from rt.safety.events import SupervisorMode

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


#: The compliant hold after a force-control soft stop (``ProgramReference._yield_step``):
#: defaults and validated ranges of its speed (m/s) and distance (m; 0: no yield). 20 mm/s unloads the twin's strapped
#: foot (1e5 N/m) pulled with 0.5 kN (5 mm) in ≈ 0.25 s plus the position law's lag; 20 mm
#: covers a 0.5 kN pull on a foot four times softer. The robot limits carry the values in use
#: (``RobotLimits.pull_yield_speed_m_s``, ``pull_yield_max_m``).
YIELD_SPEED_M_S = 0.02
YIELD_SPEED_RANGE_M_S = (0.001, 0.05)
YIELD_MAX_M = 0.02
YIELD_MAX_RANGE_M = (0.0, 0.05)
#: How far the rising hold may lead a measured slider, in tracking limits: below the
#: supervisor's tracking hard stop (3 ×) with room for the law's sag under the load (5.6-5.8 mm
#: at 565-580 kg on the twin, where the tracking limit is 3 mm).
YIELD_LEAD_TRACKING = 2.5

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
    table: ProgramTable | None = None


@dataclass
class _State:
    phase: Phase = Phase.REST
    mode: SupervisorMode = SupervisorMode.RUN
    started: bool = False
    k: int = 0                       # samples played of the current program
    taring: bool = False             # holding at the first sample while the sensor is tared
    tare_measuring: bool = False     # the force reader has started this tare
    tares_before: float = 0.0        # the force reader's tare count when the tare began
    yielding: bool = False           # a force-control soft stop's hold yields to a pull


class _Field:
    """An attribute kept in a state array the compiled cycle reads and writes: a ``_State``
    field in the sequencer's (``_SeqState.seq``, ``sk.S_*``), or a setting or state of
    :class:`ProgramReference`'s compliant hold in its part of it (``_ys``, ``sk.Y_*``)."""

    def __init__(self, index: int, kind: type, array: str = "seq") -> None:
        self.index = index
        self.kind = kind
        self.array = array

    def __get__(self, obj: Any, owner: type | None = None) -> Any:
        value = getattr(obj, self.array)[self.index]
        if self.kind is float:
            return float(value)
        return self.kind(int(value))

    def __set__(self, obj: Any, value: object) -> None:
        getattr(obj, self.array)[self.index] = float(value)  # type: ignore[arg-type]


class _SeqState:
    """``_State`` over the array the compiled cycle reads and writes (same fields)."""

    phase = _Field(sk.S_PHASE, Phase)
    mode = _Field(sk.S_MODE, SupervisorMode)
    started = _Field(sk.S_STARTED, bool)
    k = _Field(sk.S_K, int)
    taring = _Field(sk.S_TARING, bool)
    tare_measuring = _Field(sk.S_TARE_MEASURING, bool)
    tares_before = _Field(sk.S_TARES_BEFORE, float)
    yielding = _Field(sk.S_YIELD, bool)

    def __init__(self, seq: np.ndarray) -> None:
        seq[:sk.S_PLAN] = 0.0         # not the approach's plan (its own state: it carries on)
        seq[sk.S_PHASE] = float(Phase.REST)
        seq[sk.S_MODE] = float(SupervisorMode.RUN)
        seq[sk.S_N] = 1.0
        self.seq = seq


class ProgramReference(Component):
    """Ports: in ``q_meas``: float64[3] m; in ``mode``: float64[1] (the supervisor's
    :class:`SupervisorMode`, one cycle late); in ``wrench``: float64[6] (sensor frame: the
    patient's torques for interactive programs, the pull a force stop's hold yields to); in
    ``wrench_flags``: float64[2] (the force reader's [stale, saturated]). Out ``q_ref``, ``qd_ref``, ``qdd_ref``:
    float64[3] (m, m/s, m/s²); ``force``: float64[3] (F_d N, Ḟ_d N/s, F̈_d N/s²); ``force_preview``: float64[3] (the same read
    ``preview_steps`` samples ahead for a :class:`ForcePreview` program, else ``force``); ``pose``:
    float64[3] (z m, roll, pitch rad); ``ctrl_mode``: float64[1] (:class:`Mode`); ``phase``:
    float64[1] (:class:`Phase`); ``progress``: float64[1] (0..1 of the program played);
    ``tare_request``: float64[1] (1 while a tare is wanted; to the force reader, one cycle
    late); in ``tare``: the force reader's tare port (state, count, refusal, mean force).

    Attributes readable from other threads: ``epoch`` (programs started so far), ``refused``
    (requests whose approach was refused) and ``last_error`` (why), ``busy``.

    The cycle runs compiled (``rt.references.sequencer_kernel``: one call per steady cycle;
    events — a mode change, a request, an abort, a move planned or arriving (the approach, the
    return, a brake: their samples are compiled), a tare asked for, granted or refused (its
    wait is compiled), a force ramp's end, a compliant hold's exhaustion, the end of a program —
    run here, in Python, on their exact cycle); ``compiled=False`` runs the interpreted
    cycle throughout, the reference it is tested against. Programs that offer a table
    (``ProgramTable``: the protocols' table generators, the identification excitation,
    trajectories) play from it; others are called each cycle.
    """

    def __init__(self, name: str, stroke: tuple[float, float], dt: float,
                 program: Program | None = None, force_ramp_s: float = 0.3,
                 compiled: bool = True):
        super().__init__(name)
        self.compiled = compiled
        # Both paths call the kernel's functions (the interpreted one its tare wait, ramp and
        # hold): compiled, or loaded from numba's cache, here, never in a cycle.
        sk.warm_up()
        # Every output is a view of one arena, the state one array (the approach's and the
        # compliant hold's in it): the kernel's arguments.
        self._io = io = np.zeros(sk.IO_SIZE)
        self._seq = np.zeros(sk.SEQ_SIZE)
        self._ys = self._seq[sk.S_Y:sk.S_Y + sk.YIELD_SIZE]
        self.force_ramp_s = force_ramp_s
        self.approach = Approach(dt=dt, stroke=stroke,
                                 plan=self._seq[sk.S_PLAN:sk.S_PLAN + ak.PLAN_SIZE])
        self._no_table = np.zeros((1, 1))
        self._table: np.ndarray = self._no_table
        self.q_meas = self.declare_input("q_meas", Array(3))
        self.mode = self.declare_input("mode", Array(1))
        self.wrench = self.declare_input("wrench", Array(6))
        # The force reader's [stale, saturated]: the compliant hold moves only on a valid
        # sample (a harness that leaves it unbound: always valid).
        self.wrench_flags = self.declare_input("wrench_flags", Array(2))
        self.q_ref = self.declare_output("q_ref", Array(3), buffer=io[sk.IO_Q:sk.IO_Q + 3])
        self.qd_ref = self.declare_output("qd_ref", Array(3), buffer=io[sk.IO_QD:sk.IO_QD + 3])
        self.qdd_ref = self.declare_output("qdd_ref", Array(3),
                                           buffer=io[sk.IO_QDD:sk.IO_QDD + 3])
        self.force = self.declare_output("force", Array(3),
                                         buffer=io[sk.IO_FORCE:sk.IO_FORCE + 3])
        self.force_preview = self.declare_output(
            "force_preview", Array(3), buffer=io[sk.IO_FORCE_PREVIEW:sk.IO_FORCE_PREVIEW + 3])
        #: How far ahead ``force_preview`` reads a previewable force program (samples; 0: no
        #: preview). Set by the loop's builder from the force law's ``preview_s``.
        self._preview_steps = 0
        self._preview: ForcePreview | None = None
        self._ahead = np.zeros(2)
        self._ahead_next = np.zeros(2)
        self._ahead_read = False
        self.pose = self.declare_output("pose", Array(3), buffer=io[sk.IO_POSE:sk.IO_POSE + 3])
        self.ctrl_mode = self.declare_output("ctrl_mode", Array(1),
                                             buffer=io[sk.IO_CTRL_MODE:sk.IO_CTRL_MODE + 1])
        self.phase = self.declare_output("phase", Array(1), initial=np.full(1, float(Phase.REST)),
                                         buffer=io[sk.IO_PHASE:sk.IO_PHASE + 1])
        self.progress = self.declare_output("progress", Array(1),
                                            buffer=io[sk.IO_PROGRESS:sk.IO_PROGRESS + 1])
        self.tare_request = self.declare_output(
            "tare_request", Array(1), buffer=io[sk.IO_TARE_REQUEST:sk.IO_TARE_REQUEST + 1])
        self.tare = self.declare_input("tare", Array(10))
        self.tare_refused = 0
        self._initial = None if program is None else self._new_request(program)
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
        # The compliant hold after a force-control soft stop (``configure_yield``): the loop's
        # builder sets the robot limits' values; until then the defaults, with no stroke top
        # known beyond the stroke itself.
        # (In ``_seq``, ``sk.S_Y``: the compiled cycle runs the hold; ``yielded_m``
        # and ``yield_exhausted`` say how far the current or last stop's hold has yielded (m),
        # and whether it ended with the pull still there: its distance or the stroke used up.)
        self.yield_speed_m_s = YIELD_SPEED_M_S
        self.yield_max_m = YIELD_MAX_M
        self.yield_top_m = float(stroke[1])
        self.yield_lead_m = math.inf
        self._empty = np.zeros(0)               # an unbound wrench_flags/tare port's array
        self._empty.flags.writeable = False

    force_ramp_s = _Field(sk.Y_RAMP_S, float, "_ys")
    yield_speed_m_s = _Field(sk.Y_SPEED, float, "_ys")
    yield_max_m = _Field(sk.Y_MAX, float, "_ys")
    yield_top_m = _Field(sk.Y_TOP, float, "_ys")
    yield_lead_m = _Field(sk.Y_LEAD, float, "_ys")
    yielded_m = _Field(sk.Y_YIELDED, float, "_ys")
    yield_exhausted = _Field(sk.Y_EXHAUSTED, bool, "_ys")
    _stepped = _Field(sk.Y_STEPPED, bool, "_ys")       # the hold's reference rose last cycle
    _pulled = _Field(sk.Y_PULLED, bool, "_ys")         # a pull beyond sk.YIELD_START_PULL_N seen

    #: False (on the class or a block): a previewed program's PLAY reads ahead in Python even
    #: where the compiled cycle could (the reference, for tests and before/after benchmarks;
    #: takes effect at the next program or ``preview_steps``).
    compiled_read_ahead = True

    @property
    def preview_steps(self) -> int:
        """How far ahead ``force_preview`` reads a previewable force program (samples; 0: no
        preview). Set by the loop's builder from the force law's ``preview_s``."""
        return self._preview_steps

    @preview_steps.setter
    def preview_steps(self, steps: int) -> None:
        if steps < 0:
            raise ValueError(f"preview_steps must be >= 0 samples, got {steps}")
        self._preview_steps = int(steps)
        self._sync_preview()

    def _sync_preview(self) -> None:
        """Tell the compiled cycle whether the current program is read ahead, and whether it
        reads ahead itself: when the program's ``force_at`` is its table's F_d, Ḟ_d columns
        (``force_at_reads_table()``: a ``protocols`` force table) the kernel reads them
        (``sequencer_kernel.read_ahead``), else its PLAY cycles are the interpreted ones."""
        seq = self._seq
        previewing = self._preview is not None and self._preview_steps > 0
        seq[sk.S_PREVIEW] = float(previewing)
        reads_table = getattr(self._preview, "force_at_reads_table", None)
        c = FZ - int(seq[sk.S_COL0])
        seq[sk.S_AHEAD] = float(
            previewing and self.compiled_read_ahead and self._table is not self._no_table
            and callable(reads_table)
            and bool(reads_table()) and 0 <= c and c + 1 < self._table.shape[1])
        seq[sk.S_AHEAD_STEPS] = float(self._preview_steps)

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
        # The output (and the table) is built here, on the caller's thread, not in the cycle.
        self._pending = self._new_request(program, approach_min_s, rest_q, return_min_s)
        bump()                        # after the request (``rt.epoch``): its cycle is Python's

    def _new_request(self, program: Program, approach_min_s: float | None = None,
                     rest_q: tuple[float, float, float] | None = None,
                     return_min_s: float | None = None) -> _Request:
        view = getattr(program, "table_view", None)
        table = view() if (self.compiled and view is not None) else None
        return _Request(program, program.new_output(), approach_min_s, rest_q, return_min_s,
                        table)

    def request_abort(self) -> None:
        """Soft stop of the program without a fault: brake, ramp force down, then rest."""
        self._abort = True
        bump()

    @property
    def busy(self) -> bool:
        """True while a program is pending, approaching, playing or returning."""
        return self._pending is not None or (
            self.state is not None and self.state.phase.moving)

    @property
    def current_phase(self) -> Phase:
        return Phase.REST if self.state is None else self.state.phase

    # ------------------------------------------------------------------ lifecycle
    def make_state(self) -> _State | _SeqState:
        return _SeqState(self._seq) if self.compiled else _State()

    def on_start(self) -> None:
        if not np.shares_memory(self.approach.plan, self._seq):
            # The compiled cycle plays the move it finds in ``_seq`` (``sk.S_PLAN``).
            raise ConfigurationError("the sequencer's approach must keep its plan in the "
                                     "sequencer's state (a view of _seq): build another "
                                     "ProgramReference rather than replace its approach")
        self.state = self.make_state()
        self._table = self._no_table
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
        self._set_table(req.table)
        self._sync_preview()
        st.k = 0
        st.taring = False
        st.phase = Phase.APPROACH
        self._needs_tare = out.mode == Mode.FORCE
        self.epoch += 1

    def _set_table(self, view: ProgramTable | None) -> None:
        """The compiled cycle's copy of the program's length and table (or none)."""
        seq = self._seq
        seq[sk.S_N] = float(self._n)
        if view is None:
            self._table = self._no_table
            seq[sk.S_TABLE] = 0.0
            return
        self._table = view.table
        bump()
        seq[sk.S_TABLE] = 1.0
        seq[sk.S_COL0] = float(view.col0)
        seq[sk.S_PROGRAM_MODE] = float(view.mode)
        seq[sk.S_LAST] = float(view.table.shape[0] - 1)
        seq[sk.S_CONST:sk.S_CONST + len(view.const)] = view.const

    def _brake(self) -> None:
        """Jerk-limited stop from the current reference; the force ramps down in the cycle."""
        self.approach.reset(self.q_ref.data, self.qd_ref.data, self.qdd_ref.data)
        self.approach.soft_stop()

    def _ramp_force(self, dt: float) -> None:
        """Ramp a force reference down; at zero the position law holds where the robot is
        (not where the contact started: under load the platform had moved into it)."""
        if self.ctrl_mode.data[0] > 0.5 and sk.ramp_force(self._io, self.force_ramp_s, dt):
            self._hold_here()          # (the compiled cycle ramps; this end is Python's)

    def _hold_here(self) -> None:
        """Leave force control: the position law holds where the robot is (not where the
        contact started: under load the platform had moved into it)."""
        self.ctrl_mode.data[0] = float(Mode.POSITION)
        self.force.data[:] = 0.0
        self.q_ref.data[:] = self.q_meas.data
        self.qd_ref.data[:] = 0.0
        self.qdd_ref.data[:] = 0.0
        self.approach.reset(self.q_meas.data)

    def configure_yield(self, speed_m_s: float, max_m: float, top_m: float,
                        lead_m: float = math.inf) -> None:
        """The compliant hold after a force-control soft stop (``_yield_step``): the hold's
        reference rises at ``speed_m_s`` (m/s) while the foot is pulled, by at most ``max_m``
        (m; 0: no yield), never past ``top_m`` (a slider position, m: the stroke's top less
        its margin) and never more than ``lead_m`` (m) ahead of a measured slider (the loop's
        builder: 2.5 × the tracking limit, below the supervisor's hard stop at 3 ×). Refused
        by name out of range, nothing changed."""
        checks = (("pull_yield_speed_m_s", speed_m_s, YIELD_SPEED_RANGE_M_S),
                  ("pull_yield_max_m", max_m, YIELD_MAX_RANGE_M))
        for name, value, (lo, hi) in checks:
            if not (isinstance(value, int | float) and lo <= value <= hi):
                raise ConfigurationError(f"{name} = {value!r} is not within [{lo:g}, {hi:g}]")
        lo_q, hi_q = self.approach.lo, self.approach.hi
        if not (isinstance(top_m, int | float) and lo_q < top_m <= hi_q):
            raise ConfigurationError(f"pull yield top_m = {top_m!r} m is not inside the "
                                     f"stroke ({lo_q:g}, {hi_q:g}] m")
        if not (isinstance(lead_m, int | float) and lead_m > 0.0):
            raise ConfigurationError(f"pull yield lead_m = {lead_m!r} m must be > 0")
        self.yield_lead_m = float(lead_m)
        self.yield_speed_m_s = float(speed_m_s)
        self.yield_max_m = float(max_m)
        self.yield_top_m = float(top_m)

    def _start_yield(self) -> None:
        """A force-control soft stop's hold starts: it yields to a pull from here on."""
        self.yielded_m = 0.0
        self.yield_exhausted = False
        self._stepped = False
        self._pulled = False
        self.state.yielding = self.yield_max_m > 0.0

    def _yield_step(self, dt: float) -> None:
        """The compliant hold (issue 15). A soft stop in force control holds where the robot
        is with the position law (``_hold_here``); under an unmeasured load the law (no
        integral) then holds the platform below the strapped foot and pulls it indefinitely
        (565 kg on the twin: −507 N with the drives at 1.74 of 2.04 kN). A hard stop does
        not end that pull: the drives let go, the platform drops until the brakes engage and
        the brakes then hold the deeper pull (−507 → −722 N, twin). So while the measured
        push (−wrench z) is below 0 N (once a pull beyond ``sk.YIELD_START_PULL_N`` started it:
        not an offset sensor's few N with nothing on the platform), the hold's reference
        rises (all three sliders alike: a pure heave, the direction that unloads a foot above
        the platform) at
        ``yield_speed_m_s``, by at most ``yield_max_m`` and not past ``yield_top_m``, and
        holds where it got to otherwise. It stays compliant for the whole stop: a load the
        drives carry less well as they warm (580 kg, twin: the platform creeps down ≈ 20 µm/s
        once unloaded) is followed, step by step. The sensor's noise about 0 N moves it by
        one step (``yield_speed_m_s`` × dt, 20 µm at 1 kHz: ≈ 2 N on the twin's foot) per
        negative sample, so it settles with the foot unpulled, pressed by about the noise.
        It never leads a measured slider by more than ``yield_lead_m``: a load the drives
        cannot lift is waited for, not run into the supervisor's tracking hard stop (whose
        brakes would hold the pull). Once the yield is exhausted with the pull still there
        (``yield_exhausted``: its distance or the stroke used up) it holds as any stop does
        (the compiled cycle again). A NaN force (no sample) or a stale or saturated
        one (``wrench_flags``: a stale stream repeats its last value) moves nothing."""
        # The arithmetic is ``sk.yield_step``, which the compiled cycle runs too; its end
        # (exhausted: the approach re-planned to hold here) is Python's.
        if sk.yield_step(self._io, self._ys, self.q_meas.data, self.wrench.data, self._flags(),
                         dt) == sk.YIELD_DONE:
            return
        q = self.q_ref.data
        self.qdd_ref.data[:] = 0.0
        self.qd_ref.data[:] = 0.0
        self._stepped = False
        self._pulled = True
        self.yield_exhausted = True
        self.state.yielding = False
        self.approach.reset(q)                  # hold here (the compiled cycle's hold)

    def update(self, t: float, dt: float) -> int:
        if not self.compiled:
            return self._update(dt)
        if self._pending is None and not self._abort:
            result = sk.cycle(self._io, self._seq, self.q_meas.data, self.mode.data,
                              self._table, dt, self.wrench.data, self._flags(),
                              self._tare_port())
            if result == sk.DONE:
                return 0
            if result == sk.PLAY_DONE:          # the program's last sample: plan the return
                return self.play_done()
        status = self._update(dt)
        self._sync_hold()
        return status

    def steady_kind(self) -> str:
        """Which of the force programs' steady cycles the next one is, from the state: a force
        stop's compliant hold ("yield"), a force program's tare wait ("tare"), a force
        reference's ramp-down ("ramp"), or "other" (benchmarks and tests count cycles by it;
        an event first, a request or a mode change, is the caller's to tell)."""
        seq, io = self._seq, self._io
        if seq[sk.S_YIELD] != 0.0:
            return "yield"
        if seq[sk.S_PHASE] == sk.APPROACH and seq[sk.S_TARING] != 0.0:
            return "tare"
        if seq[sk.S_PHASE] in (sk.RETURN, sk.STOPPED, sk.REST) and io[sk.IO_CTRL_MODE] > 0.5:
            return "ramp"
        return "other"

    def _flags(self) -> np.ndarray:
        """The wrench flags' port, or an empty array when unbound (always valid)."""
        flags = self.wrench_flags.data
        return self._empty if flags is None else flags

    def _tare_port(self) -> np.ndarray:
        """The tare port, or an empty array when unbound (a tare wait is then Python's)."""
        tare = self.tare.data
        return self._empty if tare is None else tare

    def play_done(self) -> int:
        """The end of a compiled cycle that answered ``PLAY_DONE`` (the program's last sample
        written): plan the return. Also run by the graph's fused cycle (``rt.components.
        fused``) after its kernel's reference stage answered it."""
        self._end_play(self._seq[sk.S_PROGRAM_MODE] == 1.0)
        # The kernel copied the force before _end_play zeroed it (as the interpreted cycle's
        # last step does after it).
        self.force_preview.data[:] = self.force.data
        self._sync_hold()
        return 0

    def _sync_hold(self) -> None:
        """Tell the compiled cycle whether the approach now holds still, and where."""
        seq = self._seq
        seq[sk.S_HOLDING] = float(self.approach.still_hold(seq[sk.S_HOLD:sk.S_HOLD + 3]))

    def _update(self, dt: float) -> int:
        """The cycle, interpreted (every cycle with ``compiled=False``; the events' cycles
        otherwise)."""
        st = self.state
        mode = SupervisorMode.from_port(self.mode.data[0])
        if not st.started and self._pending is None:
            self.approach.reset(self.q_meas.data)       # nothing to play: hold where it is
            self.q_ref.data[:] = self.q_meas.data
            st.started = True
        if mode != st.mode:
            if mode == SupervisorMode.SOFT_STOP and st.phase in (Phase.APPROACH, Phase.PLAY,
                                                                 Phase.RETURN):
                if self.ctrl_mode.data[0] > 0.5:
                    # In force control: the position law holds where the robot is, at once.
                    # Ramping the force down instead would run the force law on, and a soft
                    # stop may be the sign that it is unstable (a lagging sensor, a contact it
                    # does not suit): the hold needs neither the sensor nor the contact. It
                    # yields to a pull on the foot, though (``_yield_step``).
                    self._hold_here()
                    self._start_yield()
                else:
                    self._brake()
                st.phase = Phase.STOPPED
            elif mode == SupervisorMode.HARD_STOP:
                st.phase = Phase.STOPPED
            elif mode == SupervisorMode.RUN:              # reset: hold where the robot is
                self.approach.reset(self.q_meas.data)
                st.phase = Phase.REST
            if mode != SupervisorMode.SOFT_STOP:
                st.yielding = False           # the drives off, or reset: no hold to yield
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
        elif st.yielding:
            self._yield_step(dt)
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
        # The wait's arithmetic is the compiled cycle's (``sk.tare_progress``): it runs the
        # waiting cycles itself; the request, the grant and the refusal are Python's.
        answer, st.tare_measuring = sk.tare_progress(tare, st.tare_measuring, st.tares_before)
        if answer == sk.TARE_GRANTED:
            self.tare_request.data[0] = 0.0
            self._needs_tare = False
            return ApproachStatus.FINISHED
        if answer == sk.TARE_DENIED:
            self.tare_request.data[0] = 0.0
            self.last_error = "ATI tare refused: " + refusal_message(int(tare[2]),
                                                                     float(tare[3]))
            self.tare_refused += 1
            self._brake()
            st.phase = Phase.RETURN
        return ApproachStatus.WORKING

    def _play(self, dt: float) -> int:
        if self.compiled and self._table is not self._no_table:
            seq = self._seq
            if sk.play_table(self._io, seq, self._table, dt):
                self._end_play(seq[sk.S_PROGRAM_MODE] == 1.0)
            elif self._previewing() and not math.isnan(seq[sk.S_ROW + FZ]):
                # The sample just played: k counts the samples played, and sample 0 was
                # consumed at the approach's end (the program's own index, interpreted).
                self._read_ahead(int(seq[sk.S_K]) - 1, dt)
            return 0
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
        if self.compiled:
            sk.emit(self._io, self._seq, o.buf, float(o.mode), dt)
            if o.done:
                self._end_play(o.mode == Mode.FORCE)
            elif self._previewing() and not math.isnan(o.fz_ref):
                self._read_ahead(o.index, dt)
            return 0
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
            self._end_play(force_mode)
        return 0

    def _end_play(self, force_mode: bool) -> None:
        """The program wrote its last sample (this cycle's reference): return to rest."""
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
        self.force.data[:] = 0.0
        self.state.phase = Phase.RETURN
