"""The RT process (``talus rt serve``): owns the hardware (the twin by default) and the loop,
serves commands and publishes telemetry and safety events over ZeroMQ.

    client ──request/heartbeat──▶ RtServer ──▶ RtService (this) ──▶ position loop (1 kHz)
       ▲                              │                                  │
       └──── telemetry, events ───────┘◀──── event log, recorder ring ──┘

Commands act on the loop only through thread-safe requests taken at a cycle boundary (the
supervisor's stop/e-stop/reset flags, the reference's program request, the loop's parameter
commands), so a client never blocks the cycle. A client that starts a program must keep
sending heartbeats: when none arrives for the timeout (0.25 s) the supervisor soft-stops.
"""
from __future__ import annotations

import math
import threading
import time
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from rt.control.base import Reference
from rt.control.experiment import benchmark_reference
from rt.errors import ConfigurationError, InputError, validation_summary
from rt.ipc.messages import DEFAULT_ENDPOINT, DEFAULT_PUB_ENDPOINT
from rt.position_loop import (PositionLoop, build_position_loop, build_sim_position_loop,
                              shm_devices)
from rt.safe_yaml import load_yaml_file
from rt.safety.events import Reaction
from rt.safety.limits import PatientLimits


class RtConfig(BaseModel):
    """``talus rt serve --config FILE`` (YAML); every field has a documented default."""

    model_config = ConfigDict(extra="forbid")
    schema_version: Literal[1] = 1
    backend: Literal["sim", "twin_shm"] = "sim"
    #: With backend twin_shm: the rig process's shared-memory segment (talus twin rig --shm).
    shm: str | None = None
    rate_hz: float = Field(1000.0, ge=100.0, le=2000.0)
    controller: str = "paden_panja"
    gains: dict[str, float] = Field(default_factory=dict)
    environment: str = "free"
    endpoint: str = DEFAULT_ENDPOINT
    pub_endpoint: str = DEFAULT_PUB_ENDPOINT
    heartbeat_timeout_s: float = Field(0.25, gt=0.0, le=5.0)
    telemetry_hz: float = Field(50.0, gt=0.0, le=500.0)
    patient_limits: PatientLimits = Field(default_factory=PatientLimits)


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


class RtService:
    """The command handler behind the RT server (see ``rt.ipc.server.RtServer``)."""

    def __init__(self, pl: PositionLoop, config: RtConfig):
        self.pl = pl
        self.config = config
        self.server = None           # set by serve() once the server exists
        self.programs = {"benchmark": self._benchmark, "move": self._move}

    # -- commands ---------------------------------------------------------------------------
    def status(self) -> dict[str, Any]:
        pl = self.pl
        sup = pl.supervisor
        g = pl.graph
        mode = float(g.output("supervisor.mode")[0])
        cfg = g.output("model.state").cfg
        stats = pl.loop.stats()
        return {
            "state": "hard_stop" if mode >= 3 else "soft_stop" if mode >= 2 else "run",
            "causes": sorted(sup.causes), "t": stats.t, "cycles": stats.cycles,
            "deadline_misses": stats.misses, "rate_hz": self.config.rate_hz,
            "controller": g.component("controller").controller.name,
            "phase": int(g.output("reference.phase")[0]),
            "q": g.output("encoders.q").tolist(),
            "pose": None if cfg is None else {"z": cfg.z, "roll": cfg.roll, "pitch": cfg.pitch},
            "drives_enabled": bool(g.output("supervisor.enable")[0] > 0.5),
            "active_card": int(g.output("drive.active_card")[0]),
            "heartbeat_age_s": None if self.server is None else _finite(
                self.server.heartbeat_age_s()),
        }

    def heartbeat(self, client: str | None = None) -> dict[str, Any]:
        return {}

    def stop(self) -> dict[str, Any]:
        self.pl.supervisor.request_stop()
        return {"requested": "soft_stop"}

    def estop(self, source: str) -> dict[str, Any]:
        self.pl.supervisor.request_estop(source)
        return {"requested": "hard_stop", "source": source}

    def reset(self) -> dict[str, Any]:
        before = self.pl.events.count
        self.pl.supervisor.request_reset()
        deadline = time.monotonic() + 0.5
        while self.pl.events.count == before and time.monotonic() < deadline:
            time.sleep(0.002)
        new = self.pl.events.snapshot()[-(self.pl.events.count - before):] \
            if self.pl.events.count > before else []
        refused = [e for e in new if e.kind == "reset_refused"]
        if refused:
            raise InputError(f"reset refused: cause still present ({refused[0].cause})")
        return {"reset": True, "cleared": [e.cause for e in new if e.kind == "reset"]}

    def set_gains(self, controller: str, gains: dict[str, float]) -> dict[str, Any]:
        current = self.pl.graph.component("controller").controller.name
        if controller != current:
            raise InputError(f"controller {controller!r} is not running (running: {current!r})")
        self.pl.loop.set_params("controller", **gains).result(timeout=1.0)
        return {"controller": controller, "gains": gains}

    def run(self, program: str, params: dict[str, Any]) -> dict[str, Any]:
        if program not in self.programs:
            raise InputError(f"unknown program {program!r}; known: {sorted(self.programs)}")
        if self.pl.supervisor.reaction >= Reaction.SOFT_STOP:
            raise InputError("the robot is stopped: reset the faults first")
        trajectory, duration = self.programs[program](params)
        self.pl.reference.request(trajectory, duration)
        # From now on a client must keep the heartbeat going while the robot moves.
        self.pl.supervisor.heartbeat_required = True
        return {"program": program, "duration_s": duration}

    # -- programs ---------------------------------------------------------------------------
    def _benchmark(self, params: dict[str, Any]):
        _only(params, {"duration_s"})
        duration = _number(params, "duration_s", 26.0, 0.1, 3600.0)
        return benchmark_reference(), duration

    def _move(self, params: dict[str, Any]):
        _only(params, {"z", "roll", "pitch", "hold_s"})
        kin = self.pl.model.kin
        z = _number(params, "z", 0.633, 0.0, 2.0)
        roll = _number(params, "roll", 0.0, -1.0, 1.0)
        pitch = _number(params, "pitch", 0.0, -1.0, 1.0)
        hold = _number(params, "hold_s", 0.5, 0.0, 3600.0)
        try:
            cfg = kin.ik(z, roll, pitch)
        except Exception as exc:
            raise InputError(f"move: {exc}") from None
        target = tuple(cfg.q)

        def hold_pose(t: float, out: Reference) -> None:
            out.q[:] = target
            out.qd[:] = 0.0
            out.qdd[:] = 0.0
        return hold_pose, hold


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


def serve(config: RtConfig, stop_event: threading.Event, ready=None) -> dict:
    """Run the RT process until ``stop_event`` is set; returns a summary."""
    from rt.ipc.server import RtServer
    from rt.twin.environment import parse_environment

    common = dict(rate_hz=config.rate_hz, mode="realtime",
                  patient_limits=config.patient_limits, start_program=False)
    if config.backend == "twin_shm":
        if not config.shm:
            raise ConfigurationError("backend twin_shm needs the rig's segment name (--shm)")
        pl = build_position_loop(shm_devices(config.shm), config.controller,
                                 config.gains or None, **common)
    else:
        pl = build_sim_position_loop(config.controller, config.gains or None,
                                     environment=parse_environment(config.environment),
                                     **common)
    service = RtService(pl, config)
    with RtServer(service, config.endpoint, config.pub_endpoint,
                  heartbeat_timeout_s=config.heartbeat_timeout_s) as server:
        service.server = server
        pl.supervisor.heartbeat_age = server.heartbeat_age_s
        pl.events.listener = lambda ev: server.publish("event", {**ev, "t": ev["t"]})
        pl.loop.start()
        if ready is not None:
            ready(server)
        period = 1.0 / config.telemetry_hz
        g = pl.graph
        try:
            while not stop_event.wait(period):
                rec = pl.recorder
                server.publish("telemetry", {
                    "t": float(rec.ring[(rec.written - 1) % rec.capacity, 0]),
                    "q": g.output("encoders.q").tolist(),
                    "q_ref": g.output("reference.q_ref").tolist(),
                    "tau": g.output("controller.tau").tolist(),
                    "volts": g.output("supervisor.volts").tolist(),
                    "mode": float(g.output("supervisor.mode")[0]),
                    "phase": float(g.output("reference.phase")[0])})
        finally:
            pl.loop.stop()
            pl.graph.stop()
            if pl.devices is not None and pl.devices.close is not None:
                pl.devices.close()
    stats = pl.loop.stats()
    return {"cycles": stats.cycles, "deadline_misses": stats.misses,
            "events": [e.as_dict() for e in pl.events.snapshot()]}
