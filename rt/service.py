"""The RT process (``talus rt serve``): owns the hardware (the twin by default) and the loop,
runs motion programs and clinical sessions, records them, serves commands and publishes
telemetry and safety events over ZeroMQ.

    client ──request/heartbeat──▶ RtServer ──▶ RtService (this) ──▶ loop (1 kHz)
       ▲                              │                                │
       └──── telemetry, events ───────┘◀──── event log, session tap ───┘──▶ recorder thread

Commands act on the loop only through thread-safe requests taken at a cycle boundary (the
supervisor's stop/e-stop/reset requests, the sequencer's program request, the loop's parameter
and call commands), so a client never blocks the cycle; a reply that depends on the cycle or on
a pre-flight is deferred (``rt.ipc.server.Deferred``), never waited for on the IPC thread.

Ownership (DESIGN §3): one client controls the robot (:class:`Ownership`). Motion, gains and
resets only from the owner; stops from anyone. While a motion or a session runs, only the
owner's heartbeat counts: when it is silent for ``heartbeat_timeout_s`` the supervisor
soft-stops.
"""
from __future__ import annotations

import logging
import math
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from rt.components.blocks import SignalTap
from rt.control.base import Reference
from rt.control.experiment import benchmark_reference
from rt.devices.rig_config import RigConfig
from rt.errors import ConfigurationError, InputError, TalusError, validation_summary
from rt.ipc.messages import (
    DEFAULT_ENDPOINT,
    DEFAULT_PUB_ENDPOINT,
    PatientArgs,
    RecordArgs,
    describe_validation_error,
)
from rt.ipc.security import ServerCurveConfig
from rt.model.ankle import AnkleMonitor, AnkleSetup, parse_ankle_setup
from rt.position_loop import PositionLoop, build_protocol_loop, shm_devices, sim_devices
from rt.preflight_reuse import (
    DEFAULT_MAX_AGE_S,
    KeptPreflight,
    PreflightKeeper,
    PreflightKey,
    canonical_sha256,
    why_not_reusable,
)
from rt.references.program import Program, TrajectoryProgram
from rt.references.sequencer import Phase
from rt.safe_yaml import load_yaml_file
from rt.safety.events import Reaction, SafetyEvent, SupervisorMode
from rt.safety.limits import PatientLimits, RobotLimits, effective
from rt.sessions import (
    COL_FREF,
    COL_FZ,
    COL_PHASE,
    COL_PROGRESS,
    COLUMNS,
    SESSION_SIGNALS,
    SESSION_SOURCES,
    PatientInfo,
    PreparedSession,
    SessionContext,
    SessionFactory,
    record_rows,
    recording_name,
    unique_path,
)

log = logging.getLogger(__name__)

#: The robot counts as at rest below this slider speed (m/s): 1 mm/s.
REST_SPEED_M_S = 1e-3
#: Window over which the encoders' positions judge "at rest" when the estimator failed (s).
REST_WINDOW_S = 0.1
#: Longest pre-flight the IPC client waits for before its session_start reply is an error (s).
SESSION_START_TIMEOUT_S = 120.0
#: How long a stopping RT process lets a running session abort and come to rest (s).
SHUTDOWN_SESSION_WAIT_S = 10.0
#: GIL switch interval of the RT process (s).
SWITCH_INTERVAL_S = 0.0002
#: The GIL switch interval while the loop is awake with its guard on (s): longer than the guard
#: and a cycle together, so that no other thread can force the loop off the GIL meanwhile.
GIL_HOLD_S = 0.001
#: How often a running session's pump drains the session tap (s).
PUMP_PERIOD_S = 0.05
#: How often a session_start/preflight reply is polled besides its worker's notification (s).
DEFERRED_BACKSTOP_S = 0.25
#: A program request not taken by the loop within this time is reported lost (s).
PROGRAM_TAKE_TIMEOUT_S = 2.0


def default_recordings_dir() -> Path:
    """``<user data dir>/talus/recordings`` (XDG on Linux)."""
    base = os.environ.get("XDG_DATA_HOME") or os.path.join(os.path.expanduser("~"),
                                                            ".local", "share")
    return Path(base) / "talus" / "recordings"


class RtConfig(BaseModel):
    """``talus rt serve --config FILE`` (YAML); every field has a documented default."""

    model_config = ConfigDict(extra="forbid")
    schema_version: Literal[1] = 1
    backend: Literal["sim", "twin_shm", "rig"] = "sim"
    #: With backend twin_shm: the rig process's shared-memory segment (talus twin rig --shm).
    shm: str | None = None
    #: With backend rig: the rig's cards and wiring (rt.devices.rig_config; example:
    #: rt/data/rig_example.yaml).
    rig: RigConfig | None = None
    #: Robot description YAML (None: the packaged nominal twin); a lab's identified robot.
    robot: str | None = None
    #: CurveZMQ keys; required when an endpoint is not loopback (rt.ipc.security).
    curve: ServerCurveConfig | None = None
    #: Backend sim: the twin's own description (default: ``robot`` perturbed by the
    #: documented, seeded amount, with the rig's imperfections; rt.twin.realism).
    truth: str | None = None
    #: Backend sim: an ideal twin (truth = the model, no unmodelled effect), for comparisons.
    ideal_twin: bool = False
    rate_hz: float = Field(default=1000.0, ge=100.0, le=2000.0)
    #: "realtime" paces the loop by the clock; "fast" (the twin only) runs it back to back in
    #: simulated time, for demos and tests.
    loop_mode: Literal["realtime", "fast"] = "realtime"
    controller: str = "paden_panja"
    gains: dict[str, float] = Field(default_factory=dict)
    #: What the twin's platform touches between sessions (backend sim).
    environment: str = "free"
    #: On the twin, a session places the patient's foot (unloaded) at the protocol's start
    #: pose ("patient_foot"), or keeps ``environment`` ("configured", e.g. a plate).
    session_environment: Literal["patient_foot", "configured"] = "patient_foot"
    endpoint: str = DEFAULT_ENDPOINT
    pub_endpoint: str = DEFAULT_PUB_ENDPOINT
    #: The owner's silence after which the supervisor soft-stops a motion (s).
    heartbeat_timeout_s: float = Field(default=0.25, gt=0.0, le=5.0)
    #: Telemetry publication rate for live GUIs (Hz).
    telemetry_hz: float = Field(default=60.0, gt=0.0, le=500.0)
    #: Limits in force outside sessions (a session brings its patient's).
    patient_limits: PatientLimits = Field(default_factory=PatientLimits)
    #: The machine's limits (stroke margin, speeds, forces, overruns ...); its heartbeat
    #: timeout is ``heartbeat_timeout_s`` above.
    robot_limits: RobotLimits = Field(default_factory=RobotLimits)
    #: Where sessions are recorded unless the client names a directory (default:
    #: :func:`default_recordings_dir`).
    recordings_dir: str | None = None
    #: SCHED_FIFO priority of the RT process's other threads (IPC, telemetry, sessions, the
    #: recorder), below the loop's 80: they share the GIL with the loop, and one of them
    #: descheduled while holding it makes the loop late (``rt_hygiene.gil_peer``). None (the
    #: default until a quiet machine shows it helps) leaves them ordinary threads; 1 is the
    #: value studied.
    service_priority: int | None = Field(default=None, ge=1, le=79)
    #: How long a passing ``session_preflight`` may be reused by the same client's
    #: ``session_start`` with the same protocol and patient (s; 0: never reused, every start
    #: pre-flights again). ``rt.preflight_reuse`` lists what else invalidates it.
    preflight_reuse_s: float = Field(default=DEFAULT_MAX_AGE_S, ge=0.0, le=3600.0)
    #: The loop takes the GIL back this long before each deadline and keeps it, sleeping in C,
    #: until its cycle has run (µs; realtime mode). The RT process's other threads (IPC,
    #: telemetry, sessions, the recorder) then run Python only between a cycle's end and the
    #: next guard, and cannot stretch a cycle. None: the loop shares the GIL by the 0.2 ms
    #: switch interval. The default since the quiet machine's 5 interleaved pairs
    #: (``bench/rt_deadlines.py --variants base,guard --reps 5``; docs/worklog/2026-11-26):
    #: session misses 68 against 102 per 1000 (medians), fewer in every phase, sessions
    #: soft-stopped by ``deadline_overruns`` 2 of 5 against 3 of 5. Known hazard, measured in
    #: those figures: a thread forced off the GIL as the loop wakes may take it back at the
    #: guard's end, and the loop then waits ``GIL_HOLD_S`` (closing note of branch rtloop3).
    gil_guard_us: float | None = Field(default=400.0, ge=0.0, le=500.0)
    #: Bound on every CPU's wake-up latency while the loop runs, through the kernel's PM QoS
    #: (µs; 0: idle CPUs poll rather than halt; realtime mode; ``rt_hygiene``): an idle vCPU
    #: otherwise halts and the loop's wake-up waits for the host to run it again. 0 by default
    #: since the quiet machine's 3 interleaved pairs (``bench/rt_deadlines.py --variants
    #: base,qos --reps 3``, docs/worklog/2026-11-26): session misses 14-26 against 45-154 per
    #: 1000, no session soft-stopped against 2 of 3. None: not requested.
    cpu_latency_us: int | None = Field(default=0, ge=0, le=10_000)

    def limits_of_robot(self) -> RobotLimits:
        return self.robot_limits.model_copy(
            update={"heartbeat_timeout_s": self.heartbeat_timeout_s})

    def recordings_path(self) -> Path:
        return Path(self.recordings_dir) if self.recordings_dir else default_recordings_dir()


def load_config(path: str | Path | None) -> RtConfig:
    if path is None:
        return RtConfig()
    data = load_yaml_file(path, "RT config") or {}
    if not isinstance(data, dict):
        raise ConfigurationError(f"RT config {path} must be a YAML mapping, "
                                 f"got {type(data).__name__}")
    try:
        return RtConfig.model_validate(data)
    except ValidationError as exc:
        raise ConfigurationError(
            f"RT config {path} is invalid: {validation_summary(exc)}") from None


# ------------------------------------------------------------------------------ ownership
@dataclass
class Ownership:
    """Who controls the robot. ``client`` is the envelope's client id, ``name`` the label the
    owner gave (shown to the others)."""

    client: str | None = None
    name: str | None = None
    since_wall: float | None = None

    def as_dict(self, age_s: float | None) -> dict[str, Any] | None:
        if self.client is None:
            return None
        return {"client": self.client, "name": self.name, "since": self.since_wall,
                "heartbeat_age_s": age_s}


# ------------------------------------------------------------------------------ sessions
@dataclass
class _Session:
    """One session's life in the RT process (fields written by its worker and pump threads,
    read by the IPC thread: each a single attribute assignment)."""

    id: str
    owner: str
    patient: PatientInfo
    record_dir: Path
    state: str = "preflight"       # preflight → running → ended | refused
    error: str | None = None
    prepared: PreparedSession | None = None
    recording: Path | None = None
    t_start: float = math.nan       # loop time at the start (s)
    started_wall: float = math.nan
    phase: Phase = Phase.REST
    progress: float = 0.0
    force_ref_n: float = math.nan
    force_n: float = math.nan
    aborted_by: str | None = None
    summary: dict[str, Any] | None = None
    first_event: int = 0
    start_latency_s: float = math.nan
    stop: threading.Event = field(default_factory=threading.Event)
    #: The pump's ankle monitor (``/ankle/state``) when the patient has an ankle setup: its
    #: last message is the ankle's live state in telemetry.
    ankle: AnkleMonitor | None = None
    #: The kept pre-flight this session may run on (``rt.preflight_reuse``), or why it may
    #: not; once started, which pre-flight it ran on (the recording's metadata says too).
    kept: KeptPreflight | None = None
    not_reused: str | None = None
    preflight_run: dict[str, Any] | None = None


class RtService:
    """The command handler behind the RT server (see ``rt.ipc.server.RtServer``)."""

    def __init__(self, pl: PositionLoop, config: RtConfig, tap: SignalTap,
                 sessions: SessionFactory | None = None,
                 programs: dict[str, Callable[[dict[str, Any], RtService], Program]]
                 | None = None):
        self.pl = pl
        self.config = config
        self.tap = tap
        # What the twin's platform touches between sessions (config.environment): a session's
        # foot replaces it (patient_foot) and the next session's start restores it first.
        self._between_sessions = None if pl.twin is None else pl.twin.environment
        self.sessions = sessions
        self.server: Any = None      # set by serve() once the server exists
        self.endpoint = config.endpoint
        self.programs: dict[str, Callable[[dict[str, Any], RtService], Program]] = {
            "benchmark": _benchmark, "move": _move, **(programs or {})}
        self.owner = Ownership()
        self._lock = threading.Lock()           # ownership and session transitions
        self.session: _Session | None = None
        self.last_summary: dict[str, Any] | None = None
        self._session_count = 0
        self._preflight_count = 0
        #: The last passing session_preflight, which a session_start may reuse.
        self.preflights = PreflightKeeper(config.preflight_reuse_s)
        self._robot_digest: tuple[Any, str] | None = None
        self._base_limits = pl.supervisor.limits
        #: Set when the RT process is stopping: a running session's pump finishes its
        #: recording at once.
        self.shutting_down = threading.Event()
        pl.supervisor.heartbeat_required = True
        pl.supervisor.heartbeat_age = self._owner_heartbeat_age

    # ------------------------------------------------------------------ helpers
    def _now(self) -> float:
        return time.monotonic()

    def _owner_age(self) -> float:
        if self.owner.client is None or self.server is None:
            return math.inf
        return self.server.last_seen_age_s(self.owner.client)

    def _moving(self) -> bool:
        """A program plays or a session runs: the owner must heartbeat."""
        s = self.session
        return self.pl.reference.busy or (s is not None and s.state == "running")

    def _motion_active(self) -> bool:
        """Moving, or a session in pre-flight (the robot does not move yet, but no other
        motion may start; the owner must still be there when it does)."""
        s = self.session
        return self._moving() or (s is not None and s.state == "preflight")

    def _owner_heartbeat_age(self) -> float:
        """What the supervisor checks every cycle: the owner's silence while the robot moves
        (0 otherwise: heartbeats are not required then)."""
        if not self._moving():
            return 0.0
        return self._owner_age()

    def _owner_lost(self) -> bool:
        return self._owner_age() > self.config.heartbeat_timeout_s

    def _at_rest(self) -> bool:
        if self.pl.reference.busy:
            return False
        if "estimator" in self.pl.graph.failed:
            return self._still_by_encoders()
        qd = self.pl.graph.output("estimator.qd")
        return bool(np.all(np.abs(qd) < REST_SPEED_M_S))

    def _still_by_encoders(self) -> bool:
        """At rest judged without the estimator, which a fault took out of the loop: its q̇
        stays what it was when it failed, possibly a speed, and a lost owner's robot could
        then never be taken over (nor reset) without restarting the RT process. The encoders'
        positions, as the recorder tap kept them every cycle since, moved less than
        ``REST_SPEED_M_S`` × ``REST_WINDOW_S`` over the last ``REST_WINDOW_S``. Not judged (not
        at rest) when the encoders or the tap failed too, or fewer cycles than the window ran
        since the estimator failed: nothing measured says it stands still."""
        g = self.pl.graph
        if "encoders" in g.failed or "recorder" in g.failed:
            return False
        rec = self.pl.recorder
        n = max(2, round(REST_WINDOW_S * self.config.rate_hz))
        failed_t = max((f.t for f in g.faults() if f.slot == "estimator"), default=None)
        written = rec.written
        if failed_t is None or written < n or n > rec.capacity:
            return False
        rows = rec.ring[np.arange(written - n, written) % rec.capacity]
        if rows[0, 0] <= failed_t:             # the window must lie after the failure
            return False
        q = rows[:, 1:4]                       # the tap's layout: t, q[3], qd, q_ref, tau, V
        return bool(np.all(q.max(axis=0) - q.min(axis=0) < REST_SPEED_M_S * REST_WINDOW_S))

    def _require_owner(self, client: str, what: str) -> None:
        if self.owner.client != client:
            who = "nobody" if self.owner.client is None else \
                f"{self.owner.name!r} ({self.owner.client})"
            raise InputError(f"{what} refused: only the client that controls the robot may "
                             f"do this (controlled by {who}); send control_acquire first")

    def _mode(self) -> SupervisorMode:
        return SupervisorMode.from_port(self.pl.graph.output("supervisor.mode")[0])

    # ------------------------------------------------------------------ commands
    def status(self, client: str | None = None) -> dict[str, Any]:
        pl = self.pl
        sup = pl.supervisor
        g = pl.graph
        cfg = g.output("model.state").cfg
        stats = pl.loop.stats()
        age = self._owner_age()
        return {
            "state": self._mode().name.lower(),
            "causes": sorted(sup.causes), "latched": sup.latched(),
            # What the staff must act on now (``Supervisor.alarms``: a pull in a stop).
            "alarms": sup.alarms(),
            "failed_blocks": dict(g.failed),
            "t": stats.t, "cycles": stats.cycles, "deadline_misses": stats.misses,
            # The periods the loop dropped when it fell behind (a host stall of 0.1 s drops
            # ≈ 100 at 1 kHz): an operator's and a test's evidence that the machine stalled.
            "skipped_periods": stats.skipped_periods,
            "rate_hz": self.config.rate_hz,
            "controller": pl.controller.name,
            "phase": int(g.output("reference.phase")[0]),
            "phase_name": Phase(int(g.output("reference.phase")[0])).name.lower(),
            "q": g.output("encoders.q").tolist(),
            "pose": None if cfg is None else {"z": cfg.z, "roll": cfg.roll, "pitch": cfg.pitch},
            "drives_enabled": bool(g.output("supervisor.enable")[0] > 0.5),
            "active_card": int(g.output("drive.active_card")[0]),
            "owner": self.owner.as_dict(_finite(age)),
            "you_own": client is not None and client == self.owner.client,
            "heartbeat_age_s": _finite(age),
            "session": None if self.session is None else self.session.id,
            "pid": os.getpid(),
        }

    def heartbeat(self, client: str) -> dict[str, Any]:
        return {"owner": client == self.owner.client}

    def stop(self, client: str) -> dict[str, Any]:
        self.pl.supervisor.request_stop()
        return {"requested": "soft_stop"}

    def estop(self, client: str, source: str) -> dict[str, Any]:
        self.pl.supervisor.request_estop(source)
        return {"requested": "hard_stop", "source": source}

    def control_acquire(self, client: str, name: str) -> dict[str, Any]:
        with self._lock:
            if self.owner.client == client:
                self.owner.name = name
                return {"owner": True, "name": name}
            if self.owner.client is not None:
                if not self._owner_lost():
                    raise InputError(
                        f"control refused: {self.owner.name!r} controls the robot and is "
                        f"connected (last heard {self._owner_age():.2f} s ago)")
                if not self._at_rest():
                    raise InputError(
                        f"control refused: {self.owner.name!r} was lost while the robot "
                        "moves; wait until it has stopped")
            previous = self.owner.name
            if self.owner.client is None:
                # The pre-flight's own client taking a free robot is the GUI's flow (check,
                # take control, start); anyone else taking it is a change of owner.
                self.preflights.keep_only_for(client, f"control was taken by {name!r}")
            else:
                self.preflights.drop(f"control passed from {previous!r} to {name!r}")
            self.owner = Ownership(client, name, time.time())
        return {"owner": True, "name": name, "took_over_from": previous}

    def control_release(self, client: str) -> dict[str, Any]:
        with self._lock:
            self._require_owner(client, "control_release")
            if self._motion_active():
                raise InputError("control_release refused while a motion or a session runs: "
                                 "stop it first")
            self.owner = Ownership()
            self.preflights.drop("control was released")
        return {"owner": False}

    def reset(self, client: str, acknowledge: list[int]) -> Any:
        from rt.ipc.server import Deferred

        self._require_owner(client, "reset")
        # Blocks a fault put in error are restarted first, in the loop's thread between cycles;
        # the supervisor then takes the reset with their cause gone, or still present.
        # The estimator restarts with the encoders: their stale reading is no history to judge
        # the next one against (it would be flagged as a jump). A jump seen while the encoders
        # worked (spurious counts) is not cleared this way: the position is then unknown.
        also = ("estimator",) if "encoders" in self.pl.graph.failed else ()
        restart = None
        if self.pl.graph.failed or also:
            restart = self.pl.loop.call(lambda loop: loop.graph.restart_failed(also),
                                        "restart the failed blocks")
        tickets: list[Any] = []

        def outcome() -> dict[str, Any] | None:
            if not tickets:
                if restart is not None and not restart.done():
                    return None
                tickets.append(self.pl.supervisor.request_reset(acknowledge))
            ticket = tickets[0]
            if not ticket.done:
                return None
            if ticket.refused:
                causes = ", ".join(f"{r['cause']} (event {r['id']})" for r in ticket.refused)
                raise InputError(f"reset refused: cause still present: {causes}")
            unknown = sorted(set(acknowledge) - {c["id"] for c in ticket.cleared})
            return {"reset": bool(ticket.cleared), "cleared": ticket.cleared,
                    "still_latched": ticket.still_latched, "not_latched": unknown}
        return Deferred(outcome, timeout_s=2.0, what="reset")

    def set_gains(self, client: str, controller: str, gains: dict[str, float]) -> dict[str, Any]:
        self._require_owner(client, "set_gains")
        law = self.pl.controller
        if controller != law.name:
            raise InputError(f"controller {controller!r} is not running (running: {law.name!r})")
        try:
            law.check_gains(**gains)      # refused at once, with the range, not a cycle later
        except ConfigurationError as exc:
            raise InputError(str(exc)) from None
        self.preflights.drop("the controller's gains changed")
        self.pl.loop.set_params("controller", **gains).result(timeout=1.0)
        return {"controller": controller, "gains": gains}

    def _check_can_move(self, client: str, what: str) -> None:
        self._require_owner(client, what)
        if self.pl.supervisor.reaction >= Reaction.SOFT_STOP:
            raise InputError(f"{what} refused: the robot is stopped: reset the faults first")
        if self._motion_active():
            raise InputError(f"{what} refused: a motion or a session is already running")

    def run(self, client: str, program: str, params: dict[str, Any]) -> dict[str, Any]:
        if program not in self.programs:
            raise InputError(f"unknown program {program!r}; known: {sorted(self.programs)}")
        with self._lock:
            self._check_can_move(client, "run")
            prog = self.programs[program](params, self)
            self.preflights.drop(f"program {program!r} moved the robot")
            self.pl.reference.request(prog)
        return {"program": program, "duration_s": prog.duration_s}

    # ------------------------------------------------------------------ sessions
    def session_start(self, client: str, protocol: dict[str, Any], patient: PatientArgs,
                      record: RecordArgs) -> Any:
        from rt.ipc.server import Deferred

        if self.sessions is None:
            raise InputError("this RT process offers no protocol sessions (started without "
                             "the protocols package)")
        limits = self._patient_limits(patient)
        info = PatientInfo(patient.id, patient.weight_kg, limits, self._patient_ankle(patient))
        key = self._preflight_key(protocol, info)
        record_dir = Path(record.dir) if record.dir else self.config.recordings_path()
        if record.dir is None:
            record_dir.mkdir(parents=True, exist_ok=True)
        if not record_dir.is_dir():
            raise InputError(f"recording directory {record_dir} does not exist or is not a "
                             "directory")
        if not os.access(record_dir, os.W_OK):
            raise InputError(f"recording directory {record_dir} is not writable")
        with self._lock:
            self._check_can_move(client, "session_start")
            self._session_count += 1
            stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
            session = _Session(id=f"S{stamp}-{os.getpid()}-{self._session_count}",
                               owner=client, record_dir=record_dir, patient=info)
            # A start uses the kept pre-flight at most once, and any start drops it (it moves
            # the robot); reused only when nothing it depended on changed.
            dropped = self.preflights.dropped_because
            kept = self.preflights.take()
            session.not_reused = self._why_not_reusable(kept, client, key, dropped)
            session.kept = kept if session.not_reused is None else None
            self.session = session
        requested = self._now()

        def outcome() -> dict[str, Any] | None:
            if session.state == "preflight":
                return None
            if session.state == "refused":
                raise InputError(session.error or "session refused")
            prep = session.prepared
            assert prep is not None
            return {"session_id": session.id, "protocol": prep.name, "kind": prep.kind,
                    "duration_s": prep.program.duration_s, "preflight": prep.preflight,
                    "recording": None if session.recording is None else str(session.recording),
                    "start_latency_s": session.start_latency_s,
                    "preflight_id": (session.preflight_run or {}).get("id"),
                    "preflight_reused": bool((session.preflight_run or {}).get("reused")),
                    "preflight_not_reused": session.not_reused}
        reply = Deferred(outcome, timeout_s=SESSION_START_TIMEOUT_S, what="session_start",
                         poll_interval_s=DEFERRED_BACKSTOP_S)
        # The worker notifies the reply when the session leaves pre-flight (no polling).
        threading.Thread(target=self._session_worker,
                         args=(session, protocol, requested, key, reply.notify),
                         name=f"session-{session.id}", daemon=True).start()
        return reply

    def session_preflight(self, client: str, protocol: dict[str, Any],
                          patient: PatientArgs) -> Any:
        """The pre-flight alone (a GUI shows it before Start is enabled); nothing moves."""
        from concurrent.futures import Future

        from rt.ipc.server import Deferred

        sessions = self.sessions
        if sessions is None:
            raise InputError("this RT process offers no protocol sessions")
        info = PatientInfo(patient.id, patient.weight_kg, self._patient_limits(patient),
                           self._patient_ankle(patient))
        entry = self._new_preflight(client, self._preflight_key(protocol, info))
        self.preflights.begin(entry)
        future: Future = Future()

        def work() -> None:
            try:
                prep = sessions.prepare(protocol, info, self._context())
                kept = self.preflights.passed(entry, prep, self._now())
                future.set_result({"ok": True, "protocol": prep.name, "kind": prep.kind,
                                   "duration_s": prep.program.duration_s,
                                   "start_pose": list(prep.start_pose),
                                   "predicted": prep.preflight, "preflight_id": entry.id,
                                   "kept_for_s": self.preflights.max_age_s if kept else 0.0})
            except TalusError as exc:
                self.preflights.failed(entry)
                future.set_exception(exc)
            except Exception as exc:  # a bug must still answer the client
                self.preflights.failed(entry)
                log.exception("session_preflight failed")
                future.set_exception(InputError(f"internal error: {type(exc).__name__}: {exc}"))
        reply = Deferred(lambda: future.result() if future.done() else None,
                         timeout_s=SESSION_START_TIMEOUT_S, what="session_preflight",
                         poll_interval_s=DEFERRED_BACKSTOP_S)
        future.add_done_callback(lambda _: reply.notify())
        threading.Thread(target=work, name="session-preflight", daemon=True).start()
        return reply

    def preflight_reuse(self, client: str, protocol: dict[str, Any],
                        patient: PatientArgs) -> str | None:
        """Read-only: None when a ``session_start`` from ``client`` with ``protocol`` and
        ``patient`` would now reuse the kept pre-flight, else why it would not."""
        info = PatientInfo(patient.id, patient.weight_kg, self._patient_limits(patient),
                           self._patient_ankle(patient))
        return self._why_not_reusable(self.preflights.kept, client,
                                      self._preflight_key(protocol, info),
                                      self.preflights.dropped_because)

    def _why_not_reusable(self, kept: KeptPreflight | None, client: str, key: PreflightKey,
                          dropped: str | None) -> str | None:
        event_count = self.pl.events.count      # before the snapshot: it holds them all
        return why_not_reusable(kept, client, key, self._now(), self.preflights.max_age_s,
                                self._robot_q(), self.pl.events.snapshot(), event_count,
                                self.pl.reference.epoch, dropped)

    def _new_preflight(self, client: str, key: PreflightKey) -> KeptPreflight:
        with self._lock:
            self._preflight_count += 1
            n = self._preflight_count
        stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
        return KeptPreflight(id=f"P{stamp}-{os.getpid()}-{n}", client=client, key=key,
                             q=self._robot_q(), events=self.pl.events.count,
                             epoch=self.pl.reference.epoch, requested=self._now(),
                             requested_wall=time.time())

    def _robot_q(self) -> np.ndarray:
        return np.array(self.pl.graph.output("encoders.q"), dtype=float)

    def _preflight_key(self, protocol: dict[str, Any], info: PatientInfo) -> PreflightKey:
        """What a pre-flight for ``protocol`` and ``info`` depends on here and now
        (``rt.preflight_reuse.PreflightKey``). The patient is keyed as parsed (the limits
        with their defaults filled in), so the GUI's form and the clinical record's snapshot
        of the same limits match; the robot's digest is computed once per description."""
        d = self.pl.model.description
        if self._robot_digest is None or self._robot_digest[0] is not d:
            self._robot_digest = (d, canonical_sha256({
                "description": d.model_dump(mode="json"),
                "robot_limits": self.config.limits_of_robot().model_dump(mode="json"),
                "rate_hz": self.config.rate_hz, "backend": self.config.backend,
                "twin": self.pl.twin is not None}))
        patient = {"id": info.id, "weight_kg": info.weight_kg,
                   "limits": info.limits.model_dump(mode="json"),
                   "ankle": None if info.ankle is None else info.ankle.model_dump(mode="json")}
        start = {"mode": self._mode().name, "controller": self.pl.controller.name,
                 "environment": self.config.environment,
                 "session_environment": self.config.session_environment}
        return PreflightKey(protocol=canonical_sha256(protocol),
                            patient=canonical_sha256(patient),
                            robot=self._robot_digest[1], start=canonical_sha256(start))

    def _patient_ankle(self, patient: PatientArgs) -> AnkleSetup | None:
        """The patient's ankle setup checked against this robot's platform (None when not
        sent); ``InputError`` naming the field when it is implausible."""
        if patient.ankle is None:
            return None
        return parse_ankle_setup(patient.ankle,
                                 self.pl.model.description.geometry.platform_radius_m)

    def _patient_limits(self, patient: PatientArgs) -> PatientLimits:
        try:
            return PatientLimits(**(patient.limits or {}))
        except ValidationError as exc:
            raise InputError(f"bad patient limits: {describe_validation_error(exc)}") from None

    def _context(self) -> SessionContext:
        return SessionContext(self.pl.model, self.config.limits_of_robot(), self.config.rate_hz,
            twin=self.pl.twin is not None)

    def session_status(self, client: str) -> dict[str, Any]:
        s = self.session
        if s is None:
            return {"session": None, "last_summary": self.last_summary}
        t = float(self.pl.loop.stats().t)
        return {"session": s.id, "state": s.state, "phase": s.phase.name.lower(),
                "progress": s.progress,
                "elapsed_s": None if math.isnan(s.t_start) else max(0.0, t - s.t_start),
                "force_ref_n": _finite(s.force_ref_n), "force_n": _finite(s.force_n),
                "stops": self._stops(s), "error": s.error,
                "summary": s.summary, "last_summary": self.last_summary}

    def session_abort(self, client: str) -> dict[str, Any]:
        s = self.session
        if s is None or s.state not in ("preflight", "running"):
            raise InputError("no session is running")
        s.aborted_by = client
        if s.state == "preflight":
            s.stop.set()
            return {"aborted": s.id, "during": "preflight"}
        self.pl.reference.request_abort()
        return {"aborted": s.id, "during": "run"}

    def _stops(self, s: _Session) -> list[dict[str, Any]]:
        return [_stop_dict(e) for e in self.pl.events.snapshot()
                if e.id > s.first_event and e.kind == "fault"
                and e.reaction >= Reaction.SOFT_STOP]

    # -- worker: pre-flight, then start --------------------------------------------------
    def _session_worker(self, s: _Session, protocol: dict[str, Any], requested: float,
                        key: PreflightKey, notify: Callable[[], None] = lambda: None) -> None:
        try:
            self._prepare_and_start(s, protocol, requested, key)
        finally:
            notify()                   # its session_start reply is ready (started or refused)
        if s.state == "running":
            self._pump(s)

    def _prepare_and_start(self, s: _Session, protocol: dict[str, Any], requested: float,
                           key: PreflightKey) -> None:
        assert self.sessions is not None
        try:
            kept = s.kept
            if kept is not None:
                # What the IPC thread could not check cheaply: the data files it read.
                unchanged = getattr(kept.prepared, "inputs_unchanged", None)
                if unchanged is not None and not unchanged():
                    s.not_reused = f"a data file of pre-flight {kept.id} changed"
                    kept = s.kept = None
            if kept is not None:
                prep = kept.prepared
                s.preflight_run = kept.describe(self._now(), reused=True)
            else:
                own = self._new_preflight(s.owner, key)
                prep = self.sessions.prepare(protocol, s.patient, self._context())
                own.finished = self._now()
                s.preflight_run = own.describe(self._now(), reused=False)
            if s.stop.is_set():
                raise InputError("session aborted during pre-flight")
            self._start(s, prep)
            s.start_latency_s = self._now() - requested
            s.state = "running"
        except TalusError as exc:
            s.error = str(exc)
            s.state = "refused"
            with self._lock:
                if self.session is s:
                    self.session = None
            return
        except Exception as exc:  # a bug must not leave the session hanging in "preflight"
            log.exception("session %s failed to start", s.id)
            s.error = f"internal error: {type(exc).__name__}: {exc}"
            s.state = "refused"
            with self._lock:
                if self.session is s:
                    self.session = None

    def _start(self, s: _Session, prep: PreparedSession) -> None:
        """At a cycle boundary: the session's limits, the twin's environment; then the program;
        the recorder opens first so nothing of the session is missed."""
        from rt.recording.writer import SessionRecorder

        pl = self.pl
        if pl.supervisor.reaction >= Reaction.SOFT_STOP:
            raise InputError("session_start refused: the robot was stopped during pre-flight "
                             f"({', '.join(sorted(pl.supervisor.causes))})")
        if self.owner.client != s.owner or self._owner_lost():
            raise InputError("session_start refused: the client that started it was lost "
                             "during pre-flight")
        d = pl.model.description
        limits = effective(d.limits.stroke, self.config.limits_of_robot(),
                           s.patient.limits,
            prep.protocol_limits)
        started = datetime.now(UTC)
        s.recording = unique_path(s.record_dir, recording_name(
            started.strftime("%Y%m%dT%H%M%SZ"), s.patient.id, prep.name))
        t_now = float(pl.loop.stats().t)
        meta = {**prep.metadata, "patient_id": s.patient.id,
                "limits": s.patient.limits.model_dump(), "session_id": s.id,
                "ankle": None if s.patient.ankle is None else s.patient.ankle.model_dump(),
                "rt": {"pid": os.getpid(), "endpoint": self.endpoint,
                       "backend": self.config.backend},
                "robot_description": d.name, "preflight": prep.preflight,
                # Which pre-flight this session ran on: its own, or a kept one (its id, age,
                # key); ``preflight_not_reused`` says why a kept one was not used.
                "preflight_run": {**(s.preflight_run or {}),
                                  "not_reused": s.not_reused},
                # The force law's floor: the reference the session's force error is taken to.
                "preload_n": float(getattr(pl.graph.component("controller"), "preload_n",
                                           0.0))}
        recorder = SessionRecorder(s.recording, meta, loop_t0=t_now,
                                   extra_channels={SUMMARY_CHANNEL.topic: SUMMARY_CHANNEL})
        s.prepared = prep
        s.started_wall = time.time()
        s.first_event = pl.events.count
        self._recorder = recorder
        self._tap_start = self.tap.written
        recorder.attach_state_ring(pl.recorder, start=pl.recorder.written)
        # The pump gives these for every cycle: talus.v4 joins them with the state.
        recorder.expect("/robot/wrench", "/protocol/reference")
        pl.events.listener = self._event_listener(recorder)
        strap = None
        if pl.twin is not None and self.config.session_environment == "patient_foot":
            strap = _foot_strap(pl.model.kin, prep.start_pose, s.patient.ankle)
        between = self._between_sessions

        def begin(loop: Any) -> float:
            pl.supervisor.limits = limits
            # A new session: another foot (or none) on the platform, so the force law's
            # remembered contact stiffness (from a calibration's pushes, an earlier patient)
            # no longer applies.
            forget = getattr(pl.graph.components.get("controller"), "forget_contact", None)
            if forget is not None:
                forget()
            if strap is not None and pl.twin is not None:
                # The previous session's foot is unstrapped; this one's is strapped once the
                # approach has brought the platform to the protocol's start.
                pl.twin.set_environment(between)
                pl.twin.set_environment_on_arrival(*strap)
            pl.reference.request(prep.program)
            return float(loop.t)
        epoch = pl.reference.epoch
        refused = pl.reference.refused
        s.t_start = pl.loop.call(begin, f"start session {s.id}").result(timeout=2.0)
        deadline = self._now() + PROGRAM_TAKE_TIMEOUT_S
        while pl.reference.epoch == epoch:
            if pl.reference.refused != refused:
                recorder.close()
                raise InputError(f"session_start refused: {pl.reference.last_error}")
            if self._now() > deadline:
                recorder.close()
                raise InputError("session_start: the loop did not take the program")
            time.sleep(0.002)

    def _event_listener(self, recorder: Any) -> Callable[[dict], None]:
        server = self.server

        def listener(ev: dict) -> None:
            recorder.event(ev)
            if server is not None:
                server.publish("event", ev)
        return listener

    # -- pump: recording channels, figures, the end --------------------------------------
    def _pump(self, s: _Session) -> None:
        """Non-real-time: the session tap's rows → the recorder's wrench and reference
        channels and the figures; ends the session when the robot is back at rest."""
        assert s.prepared is not None
        recorder = self._recorder
        figures = s.prepared.figures(float(getattr(
            self.pl.graph.component("controller"), "preload_n", 0.0)))
        start = self._tap_start
        seen_motion = False
        still_since: float | None = None
        ankle = None if s.patient.ankle is None else \
            AnkleMonitor(self.pl.model.kin, s.patient.ankle, s.prepared.start_pose)
        s.ankle = ankle
        fz, fr = COL_FZ, COL_FREF
        qd = COLUMNS["qd"]
        # Realtime: drained right after a cycle, in the loop's sleep (see serve's telemetry).
        tick = self.pl.loop.cycle_signal(max(1, round(PUMP_PERIOD_S * self.config.rate_hz))) \
            if self.config.loop_mode == "realtime" else None
        try:
            while True:
                if tick is not None:
                    tick.wait(2.0 * PUMP_PERIOD_S)
                    stopping = self.shutting_down.is_set()
                else:
                    stopping = self.shutting_down.wait(PUMP_PERIOD_S)
                if stopping:
                    rows, start = self.tap.drain(start)
                    figures.add(rows[rows[:, 0] >= s.t_start])
                    record_rows(recorder, rows[rows[:, 0] >= s.t_start], ankle)
                    break
                rows, start = self.tap.drain(start)
                rows = rows[rows[:, 0] >= s.t_start]
                if len(rows):
                    figures.add(rows)
                    record_rows(recorder, rows, ankle)
                    last = rows[-1]
                    s.phase = Phase(int(last[COL_PHASE]))
                    s.progress = float(last[COL_PROGRESS])
                    s.force_ref_n = float(last[fr])
                    s.force_n = -float(last[fz])
                    seen_motion = seen_motion or bool(np.any(rows[:, COL_PHASE] < Phase.STOPPED))
                    if seen_motion and s.phase == Phase.REST:
                        break
                    if s.phase == Phase.STOPPED:
                        moving = bool(np.any(np.abs(last[qd]) >= REST_SPEED_M_S))
                        still_since = None if moving else (still_since or last[0])
                        if still_since is not None and last[0] - still_since >= 0.2:
                            break
        finally:
            if tick is not None:
                tick.close()
            self._finish(s, figures, recorder)

    def _finish(self, s: _Session, figures: Any, recorder: Any) -> None:
        pl = self.pl
        events = [e for e in pl.events.snapshot() if e.id > s.first_event]
        try:
            summary = figures.result(events)
        except Exception as exc:
            log.exception("session %s: figures failed", s.id)
            summary = {"error": f"figures failed: {type(exc).__name__}: {exc}"}
        stops = [_stop_dict(e) for e in events
                 if e.kind == "fault" and e.reaction >= Reaction.SOFT_STOP]
        outcome = "stopped" if stops else "aborted" if s.aborted_by is not None else \
            "completed" if summary.get("completed") else "stopped"
        summary["completed"] = outcome == "completed"
        summary.update({
            "session_id": s.id, "patient_id": s.patient.id, "outcome": outcome,
            "aborted_by": s.aborted_by, "stops": stops,
            "preflight": None if s.prepared is None else s.prepared.preflight,
            "preflight_run": s.preflight_run,
            "rt": {"pid": os.getpid(), "endpoint": self.endpoint,
                   "backend": self.config.backend},
            "limits": s.patient.limits.model_dump(),
            "started_wall": s.started_wall, "duration_s": float(pl.loop.stats().t) - s.t_start})
        t_end = float(pl.loop.stats().t)
        recorder.publish(SUMMARY_CHANNEL.topic, {"t": t_end, "summary": summary})
        pl.events.listener = (lambda ev: self.server.publish("event", ev)) \
            if self.server is not None else None
        info = recorder.close()
        summary["recording"] = {"path": str(s.recording), "sha256": info.get("sha256"),
                                "bytes": info.get("bytes")}
        pl.loop.call(lambda loop: setattr(pl.supervisor, "limits", self._base_limits),
                     "restore the limits after a session")
        s.summary = summary
        s.state = "ended"
        self.last_summary = summary
        with self._lock:
            if self.session is s:
                self.session = None
        if self.server is not None:
            self.server.publish("event", {"t": t_end, "kind": "session_end",
                                          "cause": outcome, "summary": summary})


def _stop_dict(e: SafetyEvent) -> dict[str, Any]:
    return {"id": e.id, "t": round(e.t, 3), "cause": e.cause,
            "reaction": e.reaction.name.lower(), "message": e.message}


# ------------------------------------------------------------------------------ the summary
def _summary_channel() -> Any:
    from rt.recording.channels import ChannelSpec
    return ChannelSpec("/session/summary", "talus.SessionSummary", {
        "type": "object", "title": "talus.SessionSummary",
        "description": "The session's summary, written once by the RT process when it ends.",
        "properties": {"t": {"type": "number", "description": "loop time, s"},
                       "summary": {"type": "object"}},
        "required": ["t", "summary"]})


SUMMARY_CHANNEL = _summary_channel()


# ------------------------------------------------------------------------------ programs
def _benchmark(params: dict[str, Any], service: RtService) -> Program:
    _only(params, {"duration_s"})
    duration = _number(params, "duration_s", 26.0, 0.1, 3600.0)
    return TrajectoryProgram(benchmark_reference(), duration, 1.0 / service.config.rate_hz)


def _move(params: dict[str, Any], service: RtService) -> Program:
    _only(params, {"z", "roll", "pitch", "hold_s"})
    kin = service.pl.model.kin
    z = _number(params, "z", 0.633, 0.0, 2.0)
    roll = _number(params, "roll", 0.0, -1.0, 1.0)
    pitch = _number(params, "pitch", 0.0, -1.0, 1.0)
    hold = _number(params, "hold_s", 0.5, 0.0, 3600.0)
    try:
        cfg = kin.ik(z, roll, pitch)
    except TalusError as exc:
        raise InputError(f"move: {exc}") from None
    target = tuple(float(x) for x in cfg.q)

    def hold_pose(t: float, out: Reference) -> None:
        out.q[:] = target
        out.qd[:] = 0.0
        out.qdd[:] = 0.0
    return TrajectoryProgram(hold_pose, hold, 1.0 / service.config.rate_hz)


def _only(params: dict, allowed: set[str]) -> None:
    extra = sorted(set(params) - allowed)
    if extra:
        raise InputError(f"unknown parameter(s) {extra}; allowed: {sorted(allowed)}")


def _number(params: dict, key: str, default: float, lo: float, hi: float) -> float:
    v = params.get(key, default)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
            or not lo <= v <= hi:
        raise InputError(f"{key} must be a number in [{lo}, {hi}], got {v!r}")
    return float(v)


def _finite(x: float) -> float | None:
    return x if math.isfinite(x) else None


# ------------------------------------------------------------------------------ the process
def build_rt_loop(config: RtConfig) -> tuple[PositionLoop, SignalTap]:
    """The RT process's loop: every program (positions through the configured controller,
    forces through the hybrid law), holding until one is requested, with the session tap."""
    from rt.model import RobotModel
    from rt.twin.environment import parse_environment
    from rt.twin.twin import SimClock, Twin

    model = RobotModel.load(config.robot) if config.robot else RobotModel.load()
    tap = SignalTap("session", SESSION_SIGNALS, capacity=1 << 16)
    common: dict[str, Any] = {
        "model": model, "rate_hz": config.rate_hz, "mode": config.loop_mode, "controller": config.controller,
        "gains": config.gains or None, "patient_limits": config.patient_limits,
        "robot_limits": config.limits_of_robot(),
        "extra_blocks": [tap],
        **({} if config.gil_guard_us is None or config.loop_mode != "realtime" else
           {"gil_hold_s": GIL_HOLD_S, "gil_guard_us": config.gil_guard_us}),
        **({} if config.cpu_latency_us is None or config.loop_mode != "realtime" else
           {"cpu_latency_us": config.cpu_latency_us}),
        "extra_connections": [(src, f"session.{name}") for name, src in SESSION_SOURCES.items()]}
    if config.loop_mode == "fast" and config.backend != "sim":
        raise ConfigurationError("loop_mode fast is for the in-process twin (backend sim) only")
    if config.backend == "twin_shm":
        if not config.shm:
            raise ConfigurationError("backend twin_shm needs the rig's segment name (--shm)")
        devices = shm_devices(config.shm)
    elif config.backend == "rig":
        from rt.rig_devices import rig_devices

        if config.rig is None:
            raise ConfigurationError("backend rig needs the config's rig: section "
                                     "(see rt/data/rig_example.yaml)")
        devices = rig_devices(config.rig, model.description)
    else:
        from rt.model.description import load_description
        from rt.twin.realism import DEFAULT_TRUTH_SEED, RigImperfections, perturbed_truth

        clock = SimClock()
        imperfections = RigImperfections.none() if config.ideal_twin else None
        truth = load_description(config.truth) if config.truth else \
            model.description if config.ideal_twin else \
            perturbed_truth(model.description, DEFAULT_TRUTH_SEED) if config.robot else None
        twin = Twin(truth, parse_environment(config.environment), clock=clock,
                    imperfections=imperfections)
        twin.place((0.2, 0.2, 0.2))
        devices = sim_devices(twin, clock)
    return build_protocol_loop(devices, None, **common), tap


def serve(config: RtConfig, stop_event: threading.Event, ready: Callable | None = None,
          sessions: SessionFactory | None = None,
          programs: dict[str, Callable[[dict[str, Any], RtService], Program]] | None = None
          ) -> dict:
    """Run the RT process until ``stop_event`` is set; returns a summary. ``sessions`` and
    ``programs`` are what the entry point composes in (``talus.composition``)."""
    from rt.engine.rt_hygiene import gil_peer

    # Entered before any thread starts, so every thread of the RT process inherits it.
    with gil_peer(config.service_priority if config.loop_mode == "realtime" else None) as how:
        log.info("RT process threads: %s", how)
        return _serve(config, stop_event, ready, sessions, programs)


def _serve(config: RtConfig, stop_event: threading.Event, ready: Callable | None,
           sessions: SessionFactory | None,
           programs: dict[str, Callable[[dict[str, Any], RtService], Program]] | None) -> dict:
    import sys

    from rt.ipc.server import RtServer

    # The loop, IPC, pre-flight and recording threads share the GIL: a short switch interval
    # bounds how long a request waits for it (the default 5 ms per hand-over delays the owner's
    # heartbeats by hundreds of ms when the loop runs back to back in fast mode).
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    if config.curve is None:
        # Refused before any device is opened: off loopback, only with CurveZMQ.
        from rt.ipc.security import check_server_endpoint
        check_server_endpoint(config.endpoint, None)
        check_server_endpoint(config.pub_endpoint, None)
    pl, tap = build_rt_loop(config)
    if pl.twin is not None and config.loop_mode == "realtime":
        pl.twin.warm_session_paths()   # no kernel loads in a cycle at a session's foot strap
    warm = getattr(sessions, "warm", None)
    if warm is not None:
        warm(pl.model.description)   # the pre-flight worker starts while the loop does
    service = RtService(pl, config, tap, sessions, programs)
    with RtServer(service, config.endpoint, config.pub_endpoint,
                  heartbeat_timeout_s=config.heartbeat_timeout_s, curve=config.curve) as server:
        service.server = server
        service.endpoint = server.endpoint
        pl.events.listener = lambda ev: server.publish("event", ev)
        pl.loop.start()
        if ready is not None:
            ready(server)
        period = 1.0 / config.telemetry_hz
        # Realtime: telemetry is built right after a cycle, in the loop's sleep, woken by the
        # loop every N cycles; a free-running 60 Hz timer woke it at random times, a third of
        # them inside a cycle, which then lost the GIL for a switch interval or more.
        tick = pl.loop.cycle_signal(max(1, round(config.rate_hz / config.telemetry_hz))) \
            if config.loop_mode == "realtime" else None
        try:
            last = -math.inf
            while not stop_event.is_set():
                if tick is None:
                    if stop_event.wait(period):
                        break
                elif not tick.wait(2.0 * period):
                    # No cycle for two periods (the loop stalled or stopped): publish anyway,
                    # a GUI must see the robot's state whatever the loop does.
                    pass
                now = time.monotonic()
                if now - last >= 0.9 * period:
                    last = now
                    server.publish("telemetry", telemetry(service))
        finally:
            if tick is not None:
                tick.close()
            s = service.session
            if s is not None:
                # Stopping mid-session: abort it (soft stop, return to rest) while the loop
                # still runs, then let its recording close whatever happened.
                s.aborted_by = s.aborted_by or "the RT process (shutting down)"
                s.stop.set()
                pl.reference.request_abort()
                end = time.monotonic() + SHUTDOWN_SESSION_WAIT_S
                while s.state in ("preflight", "running") and time.monotonic() < end:
                    time.sleep(0.05)
                service.shutting_down.set()
                end = time.monotonic() + 5.0
                while s.state == "running" and time.monotonic() < end:
                    time.sleep(0.05)
            pl.loop.stop()
            pl.graph.stop()
            if pl.devices is not None and pl.devices.close is not None:
                pl.devices.close()
            close = getattr(sessions, "close", None)
            if close is not None:
                close()
    stats = pl.loop.stats()
    return {"cycles": stats.cycles, "deadline_misses": stats.misses,
            "events": [e.as_dict() for e in pl.events.snapshot()]}


def _foot_strap(kin: Any, start_pose: tuple[float, float, float], ankle: Any
                ) -> tuple[Callable[[Any], Any], tuple[float, float, float]]:
    """The twin's patient foot for a session: where the sliders stand at the protocol's start,
    and the foot built unloaded at the sliders' actual positions when they get there."""
    from rt.twin.environment import patient_foot

    z, roll, pitch = start_pose
    q_start = kin.ik(z, roll, pitch, check=False).q

    def make(q: Any) -> Any:
        c = kin.fk(q, check=False)
        return patient_foot(kin, c.z, c.roll, c.pitch, ankle)
    return make, q_start


def telemetry(service: RtService) -> dict[str, Any]:
    """One decimated sample for live plots (SI units; angles in rad)."""
    pl = service.pl
    g = pl.graph
    cfg = g.output("model.state").cfg
    rec = pl.recorder
    w = g.output("force.wrench")
    s = service.session
    return {
        "t": float(rec.ring[(rec.written - 1) % rec.capacity, 0]),
        "q": g.output("encoders.q").tolist(),
        "q_ref": g.output("reference.q_ref").tolist(),
        "tau": g.output("controller.tau").tolist(),
        "volts": g.output("supervisor.volts").tolist(),
        "pose": None if cfg is None else [cfg.z, cfg.roll, cfg.pitch],
        "pose_ref": g.output("reference.pose").tolist(),
        "wrench": [None if math.isnan(x) else float(x) for x in w],
        "force_ref_n": float(g.output("reference.force")[0]),
        "force_n": None if math.isnan(w[2]) else -float(w[2]),
        "ctrl_mode": int(g.output("reference.ctrl_mode")[0]),
        "phase": Phase(int(g.output("reference.phase")[0])).name.lower(),
        "progress": float(g.output("reference.progress")[0]),
        "mode": service._mode().name.lower(),
        "causes": sorted(pl.supervisor.causes),
        "session": None if s is None else s.id,
        "owner": service.owner.name,
        # The ankle's state during a session with the patient's ankle setup: the last
        # /ankle/state message (rt.model.ankle.AnkleMonitor.state: angles from neutral deg,
        # torques about the ankle centre N·m, centre displacement mm), else None.
        "ankle": None if s is None or s.ankle is None else s.ankle.last,
        # An isometric hold's ankle-torque target now ({hold, direction, target_nm, now_nm}:
        # protocols.torque_hold.TorqueHoldGenerator.live_target), else None.
        "ankle_target": _live_target(s),
    }


def _live_target(s: _Session | None) -> dict[str, Any] | None:
    """The session program's live target, when it has one (duck-typed: rt does not know
    protocols)."""
    live = getattr(s.prepared.program, "live_target", None) \
        if s is not None and s.prepared is not None else None
    return None if live is None else live()
