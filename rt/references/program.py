"""What the loop plays: the program interface, its per-cycle output and input.

A *program* is anything that streams references into the loop, one sample per cycle: a therapy
protocol's generator (implemented in ``protocols/``), a benchmark trajectory, a hold. The loop's
one sequencer (:class:`rt.references.sequencer.ProgramReference`) brings the robot to the
program's first sample, plays it, and brings it back to rest. ``rt`` defines the interface;
``protocols`` implements it; which programs the RT process offers is decided at the entry point
(``talus.composition``), so ``rt`` never imports ``protocols``.

A program writes one :class:`ReferenceOutput` per cycle (CONVENTIONS 6: allocated once by the
caller, filled in place, a status returned instead of an exception). Every reference lives in one
float64 buffer so a cycle is one or two block copies; the named fields are views into it:

========================  =========  ==============================================================
field                     unit       meaning
========================  =========  ==============================================================
``q_ref``                 m          slider positions (3,), from ``kinematics.ik`` of ``pose_ref``
``qd_ref``                m/s        slider velocities (3,)
``qdd_ref``               m/s²       slider accelerations (3,)
``pose_ref``              m, rad     platform pose (z, roll, pitch)
``pose_dot_ref``          m/s, rad/s its time derivative
``fz_ref``                N          force in Z on the platform, positive pushing up into what it
                                     touches (force modes); in position modes the isometric target
                                     shown to the patient, NaN when there is none
``fz_ref_dot``            N/s        its time derivative (NaN with it)
``shear_ref``             N          (fx, fy) of a gait record when ``include_shear``; carried for
                                     recording and comparison only — a 3-PRS cannot apply shear
========================  =========  ==============================================================

``mode`` says which references the loop must track: :attr:`Mode.POSITION` (the q references;
the force fields are informative) or :attr:`Mode.FORCE` (``fz_ref`` in Z, the angles of
``pose_ref`` held, ``q_ref`` is the pose where the contact starts). ``done`` is True from the
cycle that emits the last sample on.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from enum import IntEnum
from typing import Protocol, runtime_checkable

import numpy as np

from rt.control.base import Reference

# Column layout of ReferenceOutput.buf (and of the generators' precomputed tables).
Q, QD, QDD = slice(0, 3), slice(3, 6), slice(6, 9)
POSE, POSE_DOT = slice(9, 12), slice(12, 15)
FZ, FZ_DOT = 15, 16
SHEAR = slice(17, 19)
N_FIELDS = 19
#: Block written per cycle by position generators: motion + force target (columns 0..16).
POSITION_BLOCK = slice(0, 17)
#: Block written per cycle by force generators: fz, fz_dot, fx, fy (columns 15..18).
FORCE_BLOCK = slice(15, 19)


class Mode(IntEnum):
    """Which references the loop tracks."""

    POSITION = 0
    FORCE = 1


class ProgramStatus(IntEnum):
    """Per-cycle result of ``Program.update``; negative values are errors (outputs unchanged)."""

    RUNNING = 0  # a sample inside the program was written
    FINISHED = 1  # the last sample was written (and is written again on later calls)
    ERROR_NOT_VALIDATED = -1  # validate() was not called, or reported violations
    ERROR_INPUT = -2  # active assist: a non-finite measured torque; the state was not advanced
    ERROR_KINEMATICS = -3  # active assist: the pose could not be converted to slider positions


class ReferenceOutput:
    """Preallocated per-cycle references (module docstring for the fields and units)."""

    __slots__ = (
        "blocks",
        "buf",
        "done",
        "index",
        "mode",
        "pose_dot_ref",
        "pose_ref",
        "q_ref",
        "qd_ref",
        "qdd_ref",
        "shear_ref",
    )

    def __init__(self) -> None:
        self.buf = np.zeros(N_FIELDS)
        self.buf[FZ] = self.buf[FZ_DOT] = math.nan
        self.q_ref = self.buf[Q]
        self.qd_ref = self.buf[QD]
        self.qdd_ref = self.buf[QDD]
        self.pose_ref = self.buf[POSE]
        self.pose_dot_ref = self.buf[POSE_DOT]
        self.shear_ref = self.buf[SHEAR]
        # Prebuilt views so a cycle copies a table row without creating a slice view.
        self.blocks = (self.buf[POSITION_BLOCK], self.buf[FORCE_BLOCK])
        self.mode: Mode = Mode.POSITION
        self.done = False
        self.index = 0  # the sample written by the last update

    @property
    def fz_ref(self) -> float:
        """Force reference in Z (N), positive pushing up; NaN when there is none."""
        return float(self.buf[FZ])

    @property
    def fz_ref_dot(self) -> float:
        """Its time derivative (N/s)."""
        return float(self.buf[FZ_DOT])


class ProgramInput:
    """Measurements an interactive program (active assist) reads each cycle.

    The loop writes plain floats before ``update``: the patient's torque on the platform about
    the roll (x) and pitch (y) axes through the sensor origin (N·m, platform frame, from the
    force/torque sensor with the platform's own weight removed), and the force (N, sensor
    frame) so a program can move the torque to the patient's ankle centre
    (``rt.model.ankle.transfer_wrench``).
    """

    __slots__ = ("force_x_n", "force_y_n", "force_z_n", "tau_pitch_nm", "tau_roll_nm")

    def __init__(self) -> None:
        self.tau_roll_nm = 0.0
        self.tau_pitch_nm = 0.0
        self.force_x_n = 0.0
        self.force_y_n = 0.0
        self.force_z_n = 0.0


#: Longest table a program hands the sequencer (samples): 20 min at 1 kHz, ≤ 163 MB.
MAX_TABLE_SAMPLES = 1_200_000
#: Longest trajectory tabulated by calling it sample by sample (2 min at 1 kHz: ≈ 0.3 s of
#: Python on the requesting thread, which shares the interpreter with the loop).
MAX_CALLED_SAMPLES = 120_000


@dataclass(frozen=True)
class ProgramTable:
    """A program's whole reference as one table, for the sequencer's compiled cycle
    (``rt.references.sequencer_kernel``): the j-th ``update`` would write row min(j, n − 1)
    of ``table`` (n, w) into columns ``col0 … col0 + w − 1`` of ``ReferenceOutput.buf`` over
    ``const`` (the other columns, N_FIELDS), in ``mode``, done from row n − 1 on. A program
    offers one (``table_view()``) only when its ``update`` does exactly that and nothing else;
    the sequencer then samples the table without calling ``update`` (the program's own
    sample counter is not advanced)."""

    table: np.ndarray
    col0: int
    const: np.ndarray
    mode: Mode

    def __post_init__(self) -> None:
        t = self.table
        if not (isinstance(t, np.ndarray) and t.dtype == np.float64 and t.ndim == 2
                and t.shape[0] >= 1 and t.flags.c_contiguous
                and 0 <= self.col0 and self.col0 + t.shape[1] <= N_FIELDS):
            raise ValueError(f"a program table must be a C-contiguous float64 (n ≥ 1, w) "
                             f"array fitting columns {self.col0}… of {N_FIELDS}")
        if self.const.shape != (N_FIELDS,):
            raise ValueError(f"a program table's constant row must have {N_FIELDS} columns")


class Program(Protocol):
    """What the sequencer plays. ``validate()`` has been called (and passed) before a program
    is handed to the loop; ``update`` then never raises and never allocates.

    A program may also offer ``table_view() -> ProgramTable | None`` (:class:`ProgramTable`):
    the sequencer then plays it compiled."""

    duration_s: float

    def new_output(self) -> ReferenceOutput: ...

    def reset(self) -> None: ...

    def update(self, out: ReferenceOutput, inp: ProgramInput | None = None) -> int: ...


@runtime_checkable
class ForcePreview(Protocol):
    """A force program whose whole reference is known before it plays (a precomputed table:
    sine Fz, gait replay) and can be read ahead of the sample being played: the force law's
    preview (``rt.references.sequencer``, ``ProgramReference.preview_steps``)."""

    def force_at(self, index: int, out: np.ndarray) -> None:
        """Write F_d (N) and Ḟ_d (N/s) of sample ``index`` into ``out[0:2]``; an index past the
        last sample reads the last one, before the first the first. Never allocates."""
        ...


#: A slider trajectory: fills ``out`` (q, q̇, q̈ in m, m/s, m/s²) at time ``t`` (s) from its start.
TrajectoryFn = Callable[[float, Reference], None]


class TrajectoryProgram:
    """A slider trajectory ``f(t, out)`` of ``duration_s`` seconds as a position program sampled
    every ``dt`` seconds (benchmarks, the RT process's ``move`` and identification programs)."""

    def __init__(self, trajectory: TrajectoryFn, duration_s: float, dt: float):
        if not (math.isfinite(duration_s) and duration_s >= 0.0 and dt > 0.0):
            raise ValueError(f"duration_s must be >= 0 and dt > 0, got {duration_s}, {dt}")
        self.trajectory = trajectory
        self.duration_s = float(duration_s)
        self.dt = float(dt)
        self.n_samples = round(duration_s / dt) + 1
        self.index = 0
        self._ref = Reference()
        self._table: ProgramTable | None = None

    @staticmethod
    def new_output() -> ReferenceOutput:
        return ReferenceOutput()

    def reset(self) -> None:
        self.index = 0

    def table_view(self) -> ProgramTable | None:
        """The trajectory sampled at every cycle, once (a trajectory is a function of ``t``
        alone), for the compiled sequencer: the same samples ``update`` writes — by the
        trajectory's own ``tabulate(dt, n)`` when it has one (the benchmark's: one compiled
        call), else by the same calls at the same times (on the requesting thread: up to
        :data:`MAX_CALLED_SAMPLES`). None beyond that, or beyond :data:`MAX_TABLE_SAMPLES`:
        the program is then called each cycle."""
        if self._table is None:
            tabulate = getattr(self.trajectory, "tabulate", None)
            n = self.n_samples
            if n > MAX_TABLE_SAMPLES or (tabulate is None and n > MAX_CALLED_SAMPLES):
                return None
            if tabulate is not None:
                table = np.ascontiguousarray(tabulate(self.dt, n), dtype=np.float64)
            else:
                table = np.empty((n, 9))
                out = ReferenceOutput()      # the fields persist from one call to the next,
                r = Reference(out.q_ref, out.qd_ref, out.qdd_ref)     # as in update's buffer
                for k in range(n):
                    self.trajectory(k * self.dt, r)
                    table[k] = out.buf[0:9]
            self._table = ProgramTable(table, 0, ReferenceOutput().buf, Mode.POSITION)
        return self._table

    def update(self, out: ReferenceOutput, inp: ProgramInput | None = None) -> int:
        k = self.index if self.index < self.n_samples else self.n_samples - 1
        r = self._ref
        r.q, r.qd, r.qdd = out.q_ref, out.qd_ref, out.qdd_ref
        self.trajectory(k * self.dt, r)
        out.mode = Mode.POSITION
        out.index = k
        out.done = k >= self.n_samples - 1
        if self.index < self.n_samples:
            self.index += 1
        return ProgramStatus.FINISHED if out.done else ProgramStatus.RUNNING
