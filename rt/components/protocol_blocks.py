"""The hybrid position/force controller that programs in force mode drive (the sequencer,
``rt.references.sequencer.ProgramReference``, says which mode each sample is in)."""
from __future__ import annotations

import math

import numpy as np

from rt.components import hybrid_kernel as hk
from rt.control import kernels as ck
from rt.control.base import Controller, Reference
from rt.control.force import ExplicitForce, ForceReference
from rt.engine import Array, Component, Struct
from rt.errors import InputError, TalusError
from rt.model.dynamics import State
from rt.safety.events import SupervisorMode
from rt.safety.supervisor import Supervisor


class HybridController(Component):
    """Ports: in ``state``: model ``State``; ``q_ref``, ``qd_ref``, ``qdd_ref``: float64[3];
    ``force``: float64[3]; ``pose``: float64[3]; ``ctrl_mode``: float64[1]; ``wrench``:
    float64[6] (sensor frame); ``mode``: float64[1] (supervisor, one cycle late). Out ``tau``:
    float64[3] N.

    Position mode: the position law tracks the slider references. Force mode: hybrid explicit
    force in z (F = −w_S.fz, the platform's push) with roll and pitch held; while the program
    asks a force rate the robot cannot follow (a heel strike, a fast toe off: ``_lead``) the
    law tracks the reference read ahead (``force_preview``), and during such a rise its
    integral holds. Switching between
    them resets the force law's integrals so the force starts from its feedforward; with
    ``remember_contact`` (off by default) its contact-stiffness estimate starts from the last
    contact's on the new contact's first loaded cycle (:meth:`forget_contact` and a recovery
    from a hard stop forget it: the contact may then have changed), so a second push on the
    same plate is gain-scheduled from the moment it loads, while its approach runs the
    guess's gains as the first one's did.
    Roll and pitch are held at ``pose`` with its rate (the backward difference of the pose
    reference: a tilt under load is tracked, not resisted by the angle PD's damping). The
    supervisor is told when the loop depends on the force sensor. The force reference handed
    to the law is never below the law's preload (``preload_n``, N): the platform only pushes
    on a foot (``rt.control.force``).

    The fused cycle (``rt.components.fused``) runs the steady force-mode cycle compiled
    (``rt.components.hybrid_kernel``) on a copy of this block's force-mode state in ``_hs``
    (:meth:`_push` when it takes over, ``_hs_live`` set while the copy is the current one);
    this interpreted ``update`` is its reference, runs every switch, and takes the state back
    first (:meth:`_pull`).
    """

    def __init__(self, name: str, position: Controller, force: ExplicitForce,
                 supervisor: Supervisor):
        super().__init__(name)
        self.position = position
        self.force_law = force
        self.supervisor = supervisor
        self.state_in = self.declare_input("state", Struct(State))
        self.q_ref = self.declare_input("q_ref", Array(3))
        self.qd_ref = self.declare_input("qd_ref", Array(3))
        self.qdd_ref = self.declare_input("qdd_ref", Array(3))
        self.force = self.declare_input("force", Array(3))
        self.force_preview = self.declare_input("force_preview", Array(3))
        self.pose = self.declare_input("pose", Array(3))
        self.ctrl_mode = self.declare_input("ctrl_mode", Array(1))
        self.wrench = self.declare_input("wrench", Array(6))
        self.mode = self.declare_input("mode", Array(1))
        self.tau = self.declare_output("tau", Array(3))
        #: The position law, by the name the RT process reports and tunes (``set_gains``).
        self.controller = position
        self._ref = Reference()
        self._fref = ForceReference()
        self._hs = np.full(hk.H_SIZE, math.nan)
        #: True while ``_hs`` holds the force-mode state (compiled cycles ran since _push).
        self._hs_live = False
        self._in_force = False
        self._sup_mode = SupervisorMode.RUN
        self._sup_raw = float(SupervisorMode.RUN)
        self._offset = 0.0
        self.entry_time_s = 0.3
        self._decay_per_s = math.exp(-1.0 / self.entry_time_s)
        #: Deceleration (m/s²) the unloading governor plans for the platform's fall as the
        #: force comes down to the preload. 1 m/s²: the force law's own bound on the motion it
        #: commands by feedforward (``max_feedforward_accel_m_s2``), a ninth of what the drives
        #: give in z (3 × 2036 N less the moving parts' ≈ 180 N weight over ≈ 630 kg at the
        #: sliders: ≈ 9 m/s²). It was 0.5 without the lag allowance below: at 0.75-1 m/s² the
        #: platform, following late, overshot the preload into a pull (−2.9 N at 1 m/s² on
        #: functional_walk plate 0).
        self.unload_decel_m_s2 = 1.0
        #: How late (s) the platform follows the unloading reference's motion (the force
        #: loop's lag); the governor brakes that much earlier (``_govern``). 10 ms: a 20 kN/s
        #: step lags 6-11 ms on the twin (``ExplicitForceGains.preview_s``), and the 2.9 N
        #: overshoot at 0.75 m/s² without it is k a τ²/2 for τ = 8.8 ms. 0: no allowance.
        self.unload_lag_s = 0.01
        self._f_gov = math.nan
        #: How long (s) the law takes to come back from the previewed reference to the
        #: program's own once the transient is over: the reference's time runs at
        #: 1 − preview/release of its speed meanwhile, so nothing jumps.
        self.preview_release_s = 0.02
        self._ahead_weight = 0.0
        self._rising = False
        #: Schedule each contact's gains from the last contact's stiffness estimate, applied
        #: on the first loaded cycle (the measured force past the law's contact threshold,
        #: ``rt.control.kernels.CONTACT_LOADED_N``). Until then the approach runs the gains'
        #: guess, as without memory (with the plate's k̂ applied at the entry the gains were
        #: scheduled down, s ≈ 1/8, while the tool still closed its 0.5 mm gap: contact 74 ms
        #: after the entry instead of 31 ms). Off by default: the tool reaches the plate at
        #: ≈ 45 mm/s; without memory the unscheduled gains of the contact's first 1-2 cycles
        #: brake that impact hard (drives at 2.4 kN), with memory the scheduled loop (ζ ≈ 0.13
        #: on the plate) rebounds off it, so the first 0.2 s after contact track worse (twin,
        #: 400 N pushes: force error RMS 168-175 N against 103-105 N; peak command 1.0 against
        #: 2.4 kN). A bounded approach speed is what would make memory pay.
        self.remember_contact = False
        #: The last contact's stiffness estimate (N/m; NaN: none known), applied at the next
        #: force-mode entry's first loaded cycle.
        self._k_contact = math.nan
        #: That stiffness while this force-mode entry waits for its first loaded cycle (NaN:
        #: nothing to apply, or applied).
        self._k_pending = math.nan
        self._k_entry = math.nan
        self._forget = False
        #: The pose reference's roll and pitch one cycle earlier (NaN: none yet).
        self._roll_prev = math.nan
        self._pitch_prev = math.nan

    def _beyond(self, f_dot: float) -> bool:
        """True when a force rate (N/s) asks the platform, through the contact's stiffness,
        to move faster than the law's motion feedforward may (``max_feedforward_speed_m_s``):
        a heel strike, a fast toe off. There the force lags the reference by tens of ms
        (the drives at their limit, the unloading governed); slower, it follows within a
        cycle or two."""
        law = self.force_law
        return abs(f_dot) > law.gains.max_feedforward_speed_m_s * law.k_est

    def _lead(self, fr: ForceReference, dt: float) -> None:
        """The reference the law tracks: the program's (``force``), or the one read ahead
        (``force_preview``, equal to ``force`` when the program has no preview) while the
        program, now or ahead, asks more than the robot follows (:meth:`_beyond`): the law
        then starts the heel strike's push and the toe off's fall that much earlier. The
        preview is taken at once (at the transient's onset the two differ little) and left
        over ``preview_release_s``."""
        f, ahead = self.force.data, self.force_preview.data
        rate = ahead[1] if self._beyond(ahead[1]) else f[1] if self._beyond(f[1]) else 0.0
        if rate != 0.0:
            if self._ahead_weight == 0.0:
                # What kind of transient this is, fixed at its onset: a heel strike's spike
                # falls back within it.
                self._rising = rate > 0.0
            w = 1.0
        else:
            w = max(0.0, self._ahead_weight - dt / self.preview_release_s)
        self._ahead_weight = w
        # A rise beyond the drives (a heel strike) is a transient the integral must not wind
        # up on. A fall is not: the governor (``_govern``) slows it to what the platform can
        # brake, and the integral's share is needed to stop at the preload.
        fr.transient = w > 0.0 and self._rising
        fr.f = f[0] + w * (ahead[0] - f[0])
        fr.f_dot = f[1] + w * (ahead[1] - f[1])
        fr.f_ddot = f[2] + w * (ahead[2] - f[2])

    def _govern(self, fr: ForceReference, dt: float) -> None:
        """The force reference as the law gets it: never below the preload, and falling to it
        no faster than the platform can brake. Unloading at rate Ḟ moves the platform down at
        Ḟ/k through a contact of stiffness k; stopping that motion within the force left above
        the preload, (F − F_min)/k of travel, needs Ḟ² ≤ 2 a k (F − F_min); the platform
        follows ``unload_lag_s`` (τ) late, so it travels v τ more: v²/(2a) + v τ ≤
        (F − F_min)/k. A toe off that unloads faster (≈ 8 kN/s in real records) would carry
        the platform past the preload into pulling on the foot; the reference is slowed there
        instead (rising is followed as it is)."""
        floor = self.preload_n
        target = max(floor, fr.f)
        g = self._f_gov
        if math.isnan(g) or target >= g:
            self._f_gov = target
            if target == floor:
                fr.f_dot = fr.f_ddot = 0.0
            fr.f = target
            return
        k = self.force_law.k_est
        a, lag = self.unload_decel_m_s2, self.unload_lag_s
        if lag > 0.0:
            # The platform follows the reference's motion ``lag`` late, so it stops that much
            # later: v²/(2a) + v·lag ≤ (F − F_min)/k, i.e. v = −a·lag + √((a·lag)² +
            # 2a (F − F_min)/k). Near the preload the fall becomes an exponential approach
            # with time constant ``lag`` instead of a stop the platform overshoots.
            al = a * lag
            max_rate = k * (math.sqrt(al * al + 2.0 * a * (g - floor) / k) - al)
        else:
            max_rate = math.sqrt(2.0 * a * k * (g - floor))
        step = min(g - target, max_rate * dt)
        self._f_gov = g - step
        fr.f, fr.f_dot, fr.f_ddot = self._f_gov, -step / dt, 0.0

    def forget_contact(self) -> None:
        """The contact may have changed (a new session, another patient): the next force-mode
        entry starts the stiffness estimate from the gains' guess again. Any thread: taken at
        the next cycle."""
        self._forget = True

    def _leave_force(self) -> None:
        """Remember the contact's stiffness if the estimate learned it (it moved from the
        prior it started from: it only learns while the contact is loaded)."""
        k = self.force_law.k_est
        if self.remember_contact and k != self._k_entry:
            self._k_contact = k

    @property
    def law_force_ref_n(self) -> float:
        """The force reference (N) the law got in the last force-mode cycle."""
        return float(self._hs[hk.H_REF_F]) if self._hs_live else float(self._fref.f)

    def _push(self) -> None:
        """The force-mode state and parameters into ``_hs`` for the compiled cycle (the
        parameters as they are now: ``entry_time_s`` etc. are read at each take-over)."""
        hs = self._hs
        hs[hk.H_OFFSET] = self._offset
        hs[hk.H_AHEAD_WEIGHT] = self._ahead_weight
        hs[hk.H_RISING] = 1.0 if self._rising else 0.0
        hs[hk.H_F_GOV] = self._f_gov
        hs[hk.H_ENTRY_TIME] = self.entry_time_s
        hs[hk.H_ENTRY_TIME_SQ] = self.entry_time_s ** 2
        hs[hk.H_DECAY_PER_S] = self._decay_per_s
        hs[hk.H_UNLOAD_DECEL] = self.unload_decel_m_s2
        hs[hk.H_RELEASE_S] = self.preview_release_s
        hs[hk.H_REF_F] = self._fref.f
        hs[hk.H_UNLOAD_LAG] = self.unload_lag_s
        hs[hk.H_ROLL_PREV] = self._roll_prev
        hs[hk.H_PITCH_PREV] = self._pitch_prev
        hs[hk.H_K_PENDING] = self._k_pending
        self._hs_live = True

    def _pull(self) -> None:
        """The state back from ``_hs`` after compiled cycles (the next cycle is this block's)."""
        hs = self._hs
        self._offset = float(hs[hk.H_OFFSET])
        self._ahead_weight = float(hs[hk.H_AHEAD_WEIGHT])
        self._rising = bool(hs[hk.H_RISING] != 0.0)
        self._f_gov = float(hs[hk.H_F_GOV])
        self._fref.f = float(hs[hk.H_REF_F])
        self._roll_prev = float(hs[hk.H_ROLL_PREV])
        self._pitch_prev = float(hs[hk.H_PITCH_PREV])
        self._k_pending = float(hs[hk.H_K_PENDING])
        self._hs_live = False

    @property
    def preload_n(self) -> float:
        """The force reference's floor (N): the force law's preload."""
        return float(self.force_law.gains.preload_n)

    def set_params(self, **values) -> None:
        """Gains of the position law change at a cycle boundary; invalid ones are refused
        with ``InputError`` and nothing changes."""
        try:
            self.position.set_gains(**values)
        except TalusError as exc:
            raise InputError(f"component {self.name!r}: rejected {values!r}: {exc}") from exc

    def on_start(self) -> None:
        r = self._ref
        r.q, r.qd, r.qdd = self.q_ref.data, self.qd_ref.data, self.qdd_ref.data
        # The position law's compiled cycle on this block's buffers (``Controller.bind_cycle``).
        self.position.bind_cycle(self.state_in.data, r, self.tau.data)

    def update(self, t: float, dt: float) -> int:
        if self._hs_live:
            self._pull()
        raw = self.mode.data[0]
        # The enum is built only when the mode changed.
        if raw != self._sup_raw:
            self._sup_raw = raw
            mode = SupervisorMode.from_port(raw)
            if mode != self._sup_mode:
                if self._sup_mode == SupervisorMode.HARD_STOP:
                    # Drives back after a hard stop: integrators and estimates start afresh
                    # (the foot may have been taken off meanwhile).
                    self.position.reset()
                    self.force_law.reset()
                    self._k_contact = self._k_pending = math.nan
                self._sup_mode = mode
        if self._forget:
            self._forget = False
            self._k_contact = self._k_pending = math.nan
        force_mode = self.ctrl_mode.data[0] > 0.5
        measured = -self.wrench.data[2]
        if force_mode != self._in_force:
            if self._in_force:
                self._leave_force()
            # The approach runs the guess's gains; a remembered stiffness waits for the
            # contact's first loaded cycle (below).
            self.force_law.reset()
            self._k_entry = self.force_law.k_est
            self._k_pending = self._k_contact if force_mode else math.nan
            if not math.isnan(self._k_pending):
                # ... but the approach is bounded for it already (a stiffer contact is
                # met slower: ``rt.control.kernels.approach_speed``).
                self.force_law.expect_stiffness(self._k_pending)
            self._roll_prev = self._pitch_prev = math.nan
            self._in_force = force_mode
            self.supervisor.force_control = force_mode
            # Bumpless entry: the reference starts from the force the contact already carries
            # and converges to the protocol's with time constant ``entry_time_s``.
            self._offset = 0.0 if math.isnan(measured) else measured - self.force.data[0]
            self._ahead_weight = 0.0
            self._f_gov = math.nan
        st = self.state_in.data
        if force_mode:
            if not math.isnan(self._k_pending) and measured > ck.CONTACT_LOADED_N:
                # The contact's first loaded cycle: its gains scheduled from the remembered
                # stiffness from here on (the compiled cycle does the same first thing).
                self.force_law.prime_stiffness(self._k_pending)
                self._k_pending = math.nan
            fr = self._fref
            self._lead(fr, dt)
            off = self._offset
            self._offset = off * self._decay_per_s ** dt
            fr.f += off
            fr.f_dot -= off / self.entry_time_s
            fr.f_ddot += off / self.entry_time_s ** 2
            self._govern(fr, dt)
            roll, pitch = self.pose.data[1], self.pose.data[2]
            fr.roll, fr.pitch = roll, pitch
            # The pose's rate: the backward difference of its reference (exact on a ramp; 0 at
            # the entry). Without it the angle PD's damping resists a tilt under load and its
            # integral stores that torque: 0.1° overshoot at a 2°-in-1 s ramp's end.
            fr.roll_rate = 0.0 if math.isnan(self._roll_prev) else (roll - self._roll_prev) / dt
            fr.pitch_rate = (0.0 if math.isnan(self._pitch_prev)
                             else (pitch - self._pitch_prev) / dt)
            self._roll_prev, self._pitch_prev = roll, pitch
            return self.force_law.update(st, measured, fr, dt, self.tau.data)
        cycle = self.position.cycle
        if cycle is not None:
            return cycle(dt)
        return self.position.update(st, self._ref, dt, self.tau.data)
