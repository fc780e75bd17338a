"""The digital twin: the plant plus the rig's sensors and drives, speaking their real formats.

* Encoders: a byte-level PCL-833 (``FakePcl833Port``) counts pulses from the simulated slider
  positions, so the real driver (``Pcl833Encoders``: latch, 24-bit read, midpoint decode) runs.
* Drives: two PCI-1720 cards behind a comedilib double (``FakeComedi``); the real driver turns
  volts into 12-bit codes on ±10 V and the twin turns the codes back into amplifier input. The
  amplifier input follows the card that is enabled (card 0 first): the thesis's redundant card
  takes over when the first is disabled. The amplifier clamps at ±command_limit_v (6 V).
* ATI sensor: ``TwinAtiSensorModel`` (noise, bias, drift, overload) under the true wrench that
  the environment applies to the platform at the sensor.
* Digital inputs: hardware e-stop chain and the patient's hand-held stop.

Truth and imperfections: by default the twin is "the real rig" — its own description
(``rt.twin.realism.default_truth()``, the nominal one perturbed by a seeded, documented amount;
``description=`` gives another truth) and the unmodelled effects of ``RigImperfections``
(``imperfections=RigImperfections.none()`` and ``description=load_description()`` give the
ideal twin whose physics equals the model's). The encoders count the motor shafts (behind the
screw's compliance and backlash) a latency late; the ATI reading passes the sensor's low-pass
filter.

Time: the plant advances only through ``sync(t)``, holding the amplifier inputs constant
between calls (zero-order hold, as the real amplifiers see a DAC). The device backends call
``sync(clock())`` before every read, so the twin runs in lockstep with whatever clock the loop
uses: simulated time (as fast as possible) or the monotonic clock (real time).

Compiled (issue 16): by default each held command is one compiled call
(``rt.twin.kernels.advance``: physics, brakes, thermal model, encoder latency, the ATI's tool
weight and filter) and the ATI model's arithmetic is compiled too; ``compiled=False`` runs the
interpreted reference (same substep kernels, Python around them), which gives the same
results within 1e-12 (``tests/test_twin_compiled.py``).
"""
from __future__ import annotations

import math
from array import array
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from rt.ati.twin_sensor import AtiSample, AtiSensorParams, TwinAtiSensorModel
from rt.devices.interfaces import DigitalInputState
from rt.drivers.fake_comedi import FakeComedi
from rt.drivers.fake_pcl833 import FakePcl833Port
from rt.drivers.pci1720 import code_to_volts
from rt.drivers.pcl833 import encode_position
from rt.epoch import bump
from rt.errors import InputError
from rt.model.description import RobotDescription, load_description
from rt.model.dynamics import Payload
from rt.twin import kernels
from rt.twin.environment import ForcePlateContact, FreeMotion, PayloadStep
from rt.twin.faults import FaultPlan
from rt.twin.plant import TwinPlant
from rt.twin.realism import RigImperfections, default_truth

#: Longest stretch integrated with one held command and one fault/schedule check (s).
_MAX_CHUNK_S = 0.001
#: Where the plant's time sits in its block's store (``TwinPlant.t``).
_T_AT = kernels.B_X + kernels.X_T
#: The ATI's packed array (``TwinAtiSensorModel._packed``): a sample committed by the fused
#: period whose ``AtiSample`` is not built (1.0), its counter and status word.
_ATI_PENDING, _ATI_SEQ, _ATI_STATUS = kernels.ATI_PENDING, kernels.ATI_SEQ, kernels.ATI_STATUS


class SimClock:
    """Simulated time for lockstep runs as fast as possible: whoever drives the loop sets ``t``.

    The time is held in ``cell`` (``array('d')`` of one float): a compiled loop that advances
    the twin between Python's events (issue 16's pre-flight driver) writes it there, and the
    twin reads it without a call (``Twin.sync``)."""

    __slots__ = ("cell",)

    def __init__(self, t: float = 0.0) -> None:
        self.cell = array("d", (t,))

    @property
    def t(self) -> float:
        """The simulated time (s)."""
        return self.cell[0]

    @t.setter
    def t(self, value: float) -> None:
        self.cell[0] = value

    def __call__(self) -> float:
        return self.cell[0]


def _check_reachable(environment: object, plant: TwinPlant) -> None:
    """Refuse a force plate the tool tip cannot meet from outside (InputError).

    A plate below the tip's lowest point starts the robot deep inside it: the contact spring
    then throws the platform at tens of m/s. A plate above its highest point is never touched.
    """
    if not isinstance(environment, ForcePlateContact):
        return
    offset_z = plant.kin.description.sensor.offset_m[2] + environment.tool_length_m
    lo, hi = (plant.kin.fk([s] * 3).z + offset_z for s in plant.kin.description.limits.stroke_m)
    if not lo < environment.plate_height_m < hi:
        raise InputError(f"plate height {environment.plate_height_m:g} m is outside the tool "
                         f"tip's reach ({lo:.3f} .. {hi:.3f} m, level platform)")


#: A session's foot is strapped once every slider is this close to the protocol's start (m) ...
ARRIVAL_TOLERANCE_M = 1.0e-3
#: ... and slower than this (m/s): the approach has ended (its residual error loads nothing,
#: the environment being built at the actual positions).
ARRIVAL_SPEED_M_S = 2.0e-3


@dataclass(frozen=True)
class _Arrival:
    make: Callable[[np.ndarray], object]
    q_target: np.ndarray
    tolerance_m: float
    speed_m_s: float


class Twin:
    """The robot, its sensors and environment in one object (see module docstring)."""

    #: Run a fault-free period as one compiled call with its sensor readings
    #: (``_sync_fused``); False takes the general path (``bench/twin.py`` compares the two).
    fused_period: bool = True

    def __init__(self, description: RobotDescription | None = None, environment=None,
                 seed: int = 0, physics_rate_hz: float = 5000.0,
                 integrator: str = "symplectic_euler", frictionless: bool = False,
                 ati_params: AtiSensorParams | None = None,
                 clock: Callable[[], float] | None = None,
                 imperfections: RigImperfections | None = None, compiled: bool = True):
        self.compiled = compiled
        self._plant_args = (physics_rate_hz, integrator, frictionless)   # a warm-up twin's
        self.imperfections = imperfections if imperfections is not None else RigImperfections()
        self.description = description or default_truth()
        self.environment = environment or FreeMotion()
        self.plant = TwinPlant(self.description, self.environment, physics_rate_hz, integrator,
                               frictionless, self.imperfections, compiled=compiled)
        self._encoder_latency_s = self.imperfections.encoder_latency_s
        self._ati_tau_s = (0.0 if self.imperfections.ati_filter_hz <= 0.0
                           else 1.0 / (2.0 * math.pi * self.imperfections.ati_filter_hz))
        # Views into the plant's packed state: the compiled period computes them there.
        self._wrench_filtered = self.plant.wrench_filtered
        self._wrench_sensed = self.plant.wrench_sensed
        self._tool_mg = self.imperfections.ati_tool_mass_kg * self.description.gravity_m_s2
        self._tool_com = self.imperfections.ati_tool_com_m
        self._encoder_q = self.plant.encoder_q
        _check_reachable(self.environment, self.plant)
        self.rng = np.random.default_rng(seed)
        self.clock = clock                   # (also binds ``_clock_cell``: the setter)
        self.faults = FaultPlan()
        enc = self.description.encoder
        self.m_per_count = enc.m_per_count
        self.encoder_port = FakePcl833Port(m_per_count=enc.m_per_count)
        # The encoders sit at the current slider positions before the card counts anything.
        self.encoder_port.set_positions_m(self.plant.q)
        self.dac_libs = (FakeComedi(keep_log=False), FakeComedi(keep_log=False))
        self.card_enabled = [False, False]
        self._stuck_volts: dict[tuple[int, int], float] = {}
        self.command_limit_v = self.description.drive.command_limit_v
        # The amplifier inputs (V): a view into the plant's state, where the compiled period
        # computes them from the DAC codes.
        self.amp_volts = self.plant.S[kernels.S_AMP:kernels.S_AMP + 3]
        self._amp_key: tuple | None = None     # (card, codes) amp_volts was computed from
        self._codes = np.full(3, kernels.NO_CODE, dtype=np.int64)  # the codes of no card
        self.ati = TwinAtiSensorModel(ati_params, seed=seed, compiled=compiled)
        self._ati_sample: AtiSample | None = None
        self.inputs = DigitalInputState()
        self._payload_applied = False
        self._arrival: _Arrival | None = None
        self._contact_removed = False        # a ``contact_removed`` fault holds it away
        self._jumps_done: set[int] = set()
        # Delayed sensor history for the latency fault: (t, positions, ATI sample).
        self._history: deque = deque(maxlen=512)
        # The encoder card whose sign and scale the fused period holds (set on first use,
        # again if the port is replaced).
        self._port_params_of: FakePcl833Port | None = None
        self.plant.set_payload(None)
        self._n_chunk = self.plant.substeps(_MAX_CHUNK_S)   # a whole chunk's substeps
        # The fault-free period's kernel loaded now, not in a loop's cycle (see warm_period).
        self.plant.warm_period(self.encoder_port._st, self.ati._packed)

    # ------------------------------------------------------------------ setup
    @classmethod
    def ideal(cls, description: RobotDescription | None = None, **kwargs) -> Twin:
        """A twin whose physics is the model's: truth = ``description`` (default the nominal
        one) and no unmodelled effect. For tests of the ideal physics, not of the product."""
        return cls(description or load_description(), imperfections=RigImperfections.none(),
                   **kwargs)

    def place(self, q, qd=(0.0, 0.0, 0.0)) -> None:
        """Put the robot at slider positions ``q`` (m); the encoder counters then read q."""
        self.plant.set_state(q, qd)
        self.encoder_port.set_positions_m(self.plant.q)
        self._wrench_filtered[:] = self.plant.wrench_s
        if self._ati_tau_s != 0.0:
            self._wrench_filtered[:] = self._filtered_wrench(1e9)      # settled at placement

    def set_environment(self, environment) -> None:
        """Change what the platform touches (e.g. a patient's foot placed before a session);
        call between physics steps (the loop's boundary)."""
        self.environment = environment
        self.plant.set_environment(environment)
        self._payload_applied = False
        self._arrival = None
        self._contact_removed = False        # an active contact_removed takes it away again

    def set_environment_on_arrival(self, make: Callable[[np.ndarray], object], q_target,
                                   tolerance_m: float = ARRIVAL_TOLERANCE_M,
                                   speed_m_s: float = ARRIVAL_SPEED_M_S) -> None:
        """Put ``make(q)`` in place once the sliders are within ``tolerance_m`` of ``q_target``
        (m) and slower than ``speed_m_s``, ``q`` being where they then are.

        A session's foot: the clinician straps the patient's foot once the platform has reached
        the protocol's start, not while it travels there from rest (a foot placed at the start
        pose while the platform still stood at rest, a few mm away, took the heel pad's 1e5 N/m
        as a spike of hundreds of N at every session's start). ``make`` builds the environment
        unloaded at the sliders' actual positions, so a residual position error loads nothing.
        Until then the platform touches what it touched (call :meth:`set_environment` first to
        clear it). Replaced by the next call of either method."""
        target = np.asarray(q_target, dtype=float)
        if target.shape != (3,) or not np.all(np.isfinite(target)):
            raise InputError(f"arrival target must be 3 finite slider positions (m), got {q_target!r}")
        if not (tolerance_m > 0.0 and speed_m_s > 0.0):
            raise InputError("arrival tolerance and speed must be positive")
        self._arrival = _Arrival(make, target, float(tolerance_m), float(speed_m_s))

    def _arrive_if_there(self) -> None:
        a = self._arrival
        assert a is not None
        q, qd = self.plant.q, self.plant.qd
        if (np.max(np.abs(q - a.q_target)) <= a.tolerance_m
                and np.max(np.abs(qd)) <= a.speed_m_s):
            self.set_environment(a.make(q.copy()))      # clears self._arrival

    def warm_session_paths(self, q: np.ndarray | None = None) -> None:
        """Load every compiled kernel a session's start calls, before a real-time loop runs.

        Why: numba loads a kernel from its cache (or compiles it) at its first call with a
        given signature, holding the GIL for tens of ms. A strapped foot's contact is the first
        use of the plant's general period with a compliant contact: the RT process's first
        session stalled one cycle by 30-54 ms at the strap (measured on the twin, FIFO, fast
        mode; ``docs/worklog/2026-11-26``). Runs on a throwaway twin of the same truth and
        imperfections at ``q`` (default: this twin's sliders), so this one is untouched."""
        from rt.twin.environment import patient_foot

        rate_hz, integrator, frictionless = self._plant_args
        w = Twin(self.description, None, physics_rate_hz=rate_hz, integrator=integrator,
                 frictionless=frictionless, clock=None, imperfections=self.imperfections,
                 compiled=self.compiled)
        w.place(self.plant.q.copy() if q is None else np.asarray(q, dtype=float))
        w.sync(w.t + 0.002)                                  # the fused period
        w.set_environment(FreeMotion())
        c = w.plant.kin.fk(w.plant.q, check=False)
        foot = patient_foot(w.plant.kin, c.z, c.roll, c.pitch)
        w.set_environment_on_arrival(lambda _q: foot, w.plant.q.copy())
        w.sync(w.t + 0.002)                                  # arrival: the general period
        w.sync(w.t + 0.002)                                  # with the foot's contact
        w.set_environment(FreeMotion())
        w.sync(w.t + 0.002)

    def home_encoders(self) -> None:
        """Preset the counters so the decoded positions are absolute (the rig's homing)."""
        for axis in range(3):
            self.encoder_port.set_count(
                axis, encode_position(float(self.plant.q[axis]), m_per_count=self.m_per_count))

    @property
    def t(self) -> float:
        return self.plant.t

    @property
    def clock(self) -> Callable[[], float] | None:
        """The time ``sync()`` advances to (s); None: only ``sync(t)`` advances."""
        return self._clock

    @clock.setter
    def clock(self, clock: Callable[[], float] | None) -> None:
        self._clock = clock
        # A SimClock's time is read from its cell, without a call: every device backend
        # syncs before it reads (three or four times a cycle), almost always a no-op.
        self._clock_cell = clock.cell if type(clock) is SimClock else None
        bump()                        # the fused cycle's fast path reads this cell

    # ------------------------------------------------------------------ running
    def sync(self, t: float | None = None) -> None:
        """Advance the physics to time ``t`` (s; default ``clock()``) with the held commands."""
        if t is None:
            cell = self._clock_cell
            if cell is not None:
                t = cell[0]
            elif self._clock is None:
                return
            else:
                t = self._clock()
        if t - self.plant._store[_T_AT] <= 1e-12:
            # Already there (every device backend syncs before it reads, after the loop's
            # twin block advanced the physics): nothing to integrate, as below, at less cost.
            return
        if (self.fused_period and self.compiled and not self.faults.faults
                and not self.ati._faults_possible and self._arrival is None
                and (self._payload_applied or not isinstance(self.environment, PayloadStep))):
            self._sync_fused(t)
            return
        if self.ati._packed[_ATI_PENDING] != 0.0:   # a fused period's sample: the object now
            self._ati_sample = self.ati.last_sample()
        while t - self.plant.t > 1e-12:
            chunk = min(_MAX_CHUNK_S, t - self.plant.t)
            if self._arrival is not None:
                self._arrive_if_there()
            env = self.environment
            if isinstance(env, PayloadStep) and not self._payload_applied:
                remaining = env.at_s - self.plant.t
                if remaining <= 1e-12:
                    self.plant.set_payload(Payload(env.mass_kg, env.com_m))
                    self._payload_applied = True
                else:
                    chunk = min(chunk, remaining)
            if self.faults.faults:
                self._remove_contact_if_faulted()
            self._update_amplifier_input()
            self.plant.advance(chunk, self.amp_volts)
            self._update_sensors(chunk)

    def _sync_fused(self, t: float) -> None:
        """``sync`` without faults or a pending payload change (pre-flight's case): each held
        command is one compiled call (``kernels.period``: the amplifier input from the DAC
        codes, the physics, the encoder card's counters and the ATI sample), with the same
        arithmetic in the same order as the general path (``_update_amplifier_input``,
        ``plant.advance``, ``_update_sensors``). The ATI's bookkeeping is advanced by the same
        call in the model's packed array (``kernels.period_ati``); Python only draws the next
        random block when one is used up. The sample's object is built when someone asks for
        it (``ati_sample``)."""
        plant = self.plant
        port = self.encoder_port
        ati = self.ati
        st = ati._state
        if self._port_params_of is not port:
            plant.set_encoder_card(port.sign, port.m_per_count)
            self._port_params_of = port
        no_codes = self._codes
        dac_libs, enabled = self.dac_libs, self.card_enabled
        port_state, packed = port._st, ati._packed
        # The kernel computes amp_volts from the codes: the general path's cache of the key
        # it last computed them from is void now.
        self._amp_key = None
        # ``plant.period`` inline: the plant's block, its time read from the block's store
        # (the kernel advances it), the substeps of a whole chunk computed once.
        period = kernels.period_ati
        block, store, t_at = plant.B, plant._store, _T_AT
        n_chunk = self._n_chunk
        left = t - store[t_at]
        while left > 1e-12:
            chunk = min(_MAX_CHUNK_S, left)
            # The enabled card's codes, read every chunk as the general path does: a twin
            # behind a real-time loop in another thread (tests/test_rig.py) catches up in
            # many chunks while the loop writes new codes between them.
            card = 0 if enabled[0] else (1 if enabled[1] else -1)
            # The card's own code array (``FakeComedi.codes3``, NO_CODE where never written),
            # passed as it is; no card enabled: this twin's array of NO_CODE. The kernel
            # computes amp_volts from it (the period's kernel is loaded at construction, so no
            # cycle runs against a stale input while it compiles: preflight6).
            codes = dac_libs[card].codes3 if card >= 0 else no_codes
            bits = period(block, port_state, codes, packed, st.block, chunk,
                          n_chunk if chunk == _MAX_CHUNK_S else plant.substeps(chunk))
            if bits < 0:
                if bits == kernels.NEED_DRAWS:
                    ati._next_block_row()           # the next random block; then the period
                    continue
                raise plant._fk_failed()
            left = t - store[t_at]

    @property
    def ati_sample(self) -> AtiSample | None:
        """The ATI's last sample (None before the first)."""
        if self.ati._packed[_ATI_PENDING] != 0.0:
            self._ati_sample = self.ati.last_sample()
        return self._ati_sample

    @ati_sample.setter
    def ati_sample(self, sample: AtiSample | None) -> None:
        self._ati_sample = sample

    def latest_ati(self) -> tuple[np.ndarray | tuple[float, ...], int, int] | None:
        """The ATI's last sample as (wrench N/N·m, ft_sequence, status), None before the first,
        without building an ``AtiSample`` when the fused period left it in the model's array
        (the force reader's path every cycle). Undelayed: see :meth:`delayed`."""
        pk = self.ati._packed
        if pk[_ATI_PENDING] != 0.0:
            return self.ati._out, int(pk[_ATI_SEQ]), int(pk[_ATI_STATUS])
        s = self._ati_sample
        return None if s is None else (s.wrench, s.ft_sequence, s.status)

    def _update_amplifier_input(self) -> None:
        t = self.plant.t
        card = 0 if self.card_enabled[0] else (1 if self.card_enabled[1] else -1)
        if self.compiled and not self.faults.faults:
            # Without DAC faults the input is a function of the card's codes: recompute it
            # only when they changed (most chunks of a catch-up hold the same codes).
            key = (card, self.dac_libs[card].codes3.tobytes()) if card >= 0 else (card,)
            if key == self._amp_key:
                return
            self._amp_key = key
        else:
            self._amp_key = None
        codes = self.dac_libs[card].codes3.tolist() if card >= 0 else None
        for ch in range(3):
            v = 0.0
            if codes is not None:
                code = codes[ch]
                v = code_to_volts(code) if code != kernels.NO_CODE else 0.0
            if self.faults.faults:
                for f in self.faults.active("dac_dead", t):
                    if f.card == card and f.channel == ch:
                        v = 0.0
                for f in self.faults.active("dac_stuck", t):
                    if f.card == card and f.channel == ch:
                        v = self._stuck_volts.setdefault((card, ch), v)
            self.amp_volts[ch] = max(-self.command_limit_v, min(self.command_limit_v, v))

    def _encoder_positions(self) -> np.ndarray:
        """What the motor encoders hold now: the motor position ``latency`` ago (to first
        order, x − v·latency)."""
        p = self.plant
        lat = self._encoder_latency_s
        if lat == 0.0:
            return p.xm
        e = self._encoder_q
        for i in range(3):
            e[i] = p.xm[i] - p.vm[i] * lat
        return e

    def _filtered_wrench(self, dt: float) -> np.ndarray:
        """What the gauges feel — the environment's wrench plus the weight of the sensor's
        tool side (static: its inertial part is < 4 % of it at the robot's accelerations) —
        through the sensor's first-order low-pass filter (exact for a wrench held over
        ``dt``)."""
        w_in = self.plant.wrench_s
        if self._tool_mg != 0.0:
            # Weight −m g ẑ_B in the sensor frame S (axes of P): −m g R_BPᵀ ẑ = −m g (row 2 of
            # R); its moment about the origin, the COM at c = (0, 0, h) in S: c × F.
            r = self.plant.rot
            w_in = self._wrench_sensed
            w_in[:] = self.plant.wrench_s
            fx, fy, fz = (-self._tool_mg * r[2, 0], -self._tool_mg * r[2, 1],
                          -self._tool_mg * r[2, 2])
            h = self._tool_com
            w_in[0] += fx
            w_in[1] += fy
            w_in[2] += fz
            w_in[3] += -h * fy
            w_in[4] += h * fx
        if self._ati_tau_s == 0.0:
            return w_in
        a = 1.0 - math.exp(-dt / self._ati_tau_s)
        w = self._wrench_filtered
        w += a * (w_in - w)
        return w

    def _remove_contact_if_faulted(self) -> None:
        """The ``contact_removed`` fault: while it is active the plant touches nothing (free
        motion: the foot or the plate has gone); when it ends, the twin's environment is back
        where it was (a foot put back in the straps, a plate remounted), its contact state
        fresh."""
        removed = bool(self.faults.active("contact_removed", self.plant.t))
        if removed != self._contact_removed:
            self._contact_removed = removed
            self.plant.set_environment(FreeMotion() if removed else self.environment)

    def _update_sensors(self, chunk: float) -> None:
        t = self.plant.t
        port = self.encoder_port
        if self.faults.faults:
            frozen = {f.axis for f in self.faults.active("encoder_freeze", t)}
            for axis in range(3):
                port.set_frozen(axis, axis in frozen)
            for i, f in enumerate(self.faults.faults):
                if f.kind == "encoder_jump" and f.active(t) and i not in self._jumps_done:
                    port.move_counts(f.axis, f.counts)
                    self._jumps_done.add(i)
            for f in self.faults.active("encoder_noise", t):
                port.move_counts(f.axis, round(self.rng.normal(0.0, f.sigma_counts)))
            for kind, name in (("ati_dropout", "dropout"), ("ati_stale", "stale"),
                               ("ati_saturation", "saturate")):
                self.ati.set_fault(name, bool(self.faults.active(kind, t)))
            self.inputs.hardware_estop = bool(self.faults.active("hardware_estop", t))
            self.inputs.hand_stop = bool(self.faults.active("hand_stop", t))
        if self.compiled:       # the period's kernel computed both
            port.set_positions_m(self.plant.encoder_q)
            sample = self.ati.measure(self.plant.wrench_measured, t)
        else:
            port.set_positions_m(self._encoder_positions())
            sample = self.ati.measure(self._filtered_wrench(chunk), t)
        if sample is not None:
            self.ati_sample = sample
        if self.faults.faults and any(f.kind == "latency" for f in self.faults.faults):
            self._history.append((t, port_counts(port), self.ati_sample))

    # ------------------------------------------------------------------ reads for backends
    def delayed(self) -> tuple[tuple[int, int, int] | None, AtiSample | None]:
        """With a latency fault active: (counter values, ATI sample) from ``seconds`` ago."""
        faults = self.faults.active("latency", self.plant.t) if self.faults.faults else []
        if not faults:
            return None, self.ati_sample
        target = self.plant.t - max(f.seconds for f in faults)
        best = None
        for entry in self._history:
            if entry[0] <= target:
                best = entry
            else:
                break
        if best is None:
            return None, None
        return best[1], best[2]

    def set_card_enabled(self, card: int, enabled: bool) -> None:
        if card not in (0, 1):
            raise InputError(f"DAC card must be 0 or 1, got {card}")
        self.card_enabled[card] = enabled
        self.plant.set_drives_enabled(any(self.card_enabled))

    @property
    def drives_enabled(self) -> bool:
        return any(self.card_enabled)

    def true_state(self) -> dict:
        """Ground truth for tests and logs (not visible to the controller on a real rig)."""
        p = self.plant
        return {"t": p.t, "q": p.q.tolist(), "qd": p.qd.tolist(), "qdd": p.qdd.tolist(),
                "wrench": p.wrench_s.tolist(), "amp_volts": self.amp_volts.tolist(),
                "in_contact": p.in_contact}


def port_counts(port: FakePcl833Port) -> tuple[int, int, int]:
    return (port.count(0), port.count(1), port.count(2))


