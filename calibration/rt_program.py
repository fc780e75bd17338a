"""The RT process's side of a calibration trial: the ``calibration_push`` program.

``talus calibrate run --backend rt`` (:mod:`calibration.rt_runner`) sends each trial to the RT
process as ``run calibration_push {plan, trial, out}``. The RT process (this module, composed in
by ``talus.composition``) plays it like any program — approach, play, return, rest under the
supervisor — and writes the trial's recording to ``out`` (``.npz``, temp + rename) when the
robot is back at rest or stopped:

* ``robot``: rows of the loop's session tap while the program ran, reduced to the columns the
  calibration needs — t (loop time, s), the ATI wrench (6, sensor frame), q (3, m), the force
  reference (3), the sequencer's phase (1);
* ``contact``: the plate's sensing element. On the twin it is the twin's true contact wrench
  and slider positions (t, wrench 6, q 3), sampled at the cycle the program plays — what the
  plate feels, which the loop never sees; the calibration client turns it into the twin plate's
  channels on the plate's own clock. Empty when the client acquires the plate's DAQ itself.

Where the plate's channels come from (param ``plate_daq``):

* ``rt_twin`` (the default; twin only): from ``contact`` above, as just described.
* ``client``: the calibration client reads the plate's DAQ on its own thread and clock
  (:mod:`calibration.plate_daq`) while this program pushes — the rig's way (the RT process
  never owns the plate's card). On the twin the twin plate then sits behind a comedi double in
  the client, fed through the shared-memory wire ``twin_contact_shm`` that this program
  publishes the twin's contact to every played cycle (:mod:`calibration.twin_plate_daq`). The
  rig refuses ``rt_twin`` and ``twin_contact_shm`` (it has no twin).
* ``meta``: JSON: the trial, the plate height, the outcome (``completed`` or ``stopped``) and the
  supervisor's causes when stopped.

Why the whole plan travels and not the force samples: a trial is 10-20 s at 1 kHz, beyond the
IPC's 64 KB message bound; the profile is recomputed here by the same function
(:func:`calibration.plan.force_profile`) and its digest returned so the client can check it.

The program runs under the RT process's configured limits (``patient_limits`` of its config):
a trial whose peak force exceeds them is refused, never raised by the program. An RT process
serving a calibration is configured for it (e.g. ``patient_limits: {max_force_n: 1800}``).
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import tempfile
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from pydantic import ValidationError

from calibration.plan import Plan, Trial, force_profile, tilt_profile, trial_pose
from calibration.push import (
    TOOL_LENGTH_M,
    ForceTableGenerator,
    tool_plate,
)
from calibration.twin_plate_daq import WirePublisher
from rt.errors import InputError, validation_summary
from rt.references.program import ProgramInput, ReferenceOutput
from rt.references.sequencer import STOP_EVENTS_SETTLE_S, program_outcome
from rt.sessions import COLUMNS

if TYPE_CHECKING:
    from rt.service import RtService

PROGRAM_NAME = "calibration_push"
#: ``plate_daq`` values (module docstring).
PLATE_DAQ_RT_TWIN = "rt_twin"
PLATE_DAQ_CLIENT = "client"
#: Gap between the tool tip and the plate at the held pose before loading (m), as in the
#: in-process runner: the explicit force law closes it under its preload, and the impact on a
#: stiff plate (2e6 N/m) grows with the gap (2 mm made the tool bounce to 900 N on the twin).
#: The push starts from rest at the trial's pose, which the position law holds to ~0.05 mm.
START_GAP_M = 0.5e-3
#: The recording ends this long after the robot came to rest or stopped (s), at the latest
#: after the program's duration plus :data:`END_MARGIN_S`.
END_MARGIN_S = 30.0
#: How close the robot must be to the trial's pose when the push is requested (m, rad).
POSE_TOLERANCE_M = 1.0e-3
POSE_TOLERANCE_RAD = math.radians(0.2)
#: Robot columns written: t, ATI wrench (6), q (3), force reference (3), phase (1).
ROBOT_COLUMNS = ("t", "wrench", "q", "force", "phase")
ROBOT_WIDTH = 14
CONTACT_WIDTH = 10


def profile_digest(profile_n: np.ndarray) -> str:
    """sha256 of the profile's float64 bytes: the client checks the RT process played its own."""
    return hashlib.sha256(np.ascontiguousarray(profile_n, dtype=np.float64).tobytes()).hexdigest()


def plate_height_m(model: Any, z_m: float, tool_length_m: float, gap_m: float) -> float:
    """Height (base frame) of the plate's surface: the level pose's tool tip plus ``gap_m``; the
    same for every pose of a campaign (tilted pushes lower the tip, so they start clear too)."""
    cfg = model.kin.fk(model.kin.ik(z_m, 0.0, 0.0).q, check=False)
    R = np.array(cfg.rotation).reshape(3, 3)
    s = np.array(model.description.sensor.offset_m)
    tip = np.array([cfg.x, cfg.y, cfg.z]) + R @ s + tool_length_m * R[:, 2]
    return float(tip[2]) + gap_m


class ContactRecordingProgram:
    """A program that plays ``inner`` and, on the twin, samples the twin's true contact each
    cycle it plays (preallocated ring, no allocation in ``update``) and publishes it to the twin
    plate's wire when there is one (``publisher``). On the rig (``twin`` None) it only plays."""

    def __init__(self, inner: Any, twin: Any, loop: Any, capacity: int,
                 publisher: WirePublisher | None = None) -> None:
        self.inner = inner
        self.duration_s = inner.duration_s
        self.twin = twin
        self.loop = loop
        self.ring = np.full((capacity if twin is not None else 0, CONTACT_WIDTH), np.nan)
        self.written = 0
        self.armed = False
        self.publisher = publisher

    def close_wire(self) -> None:
        """Stop publishing and unmap the wire (the recorder's thread, after the program ended:
        the loop no longer calls ``update``; a few cycles' grace all the same)."""
        pub, self.publisher = self.publisher, None
        if pub is not None:
            time.sleep(0.05)
            pub.close()

    def new_output(self) -> ReferenceOutput:
        return self.inner.new_output()

    def reset(self) -> None:
        self.inner.reset()
        # The sequencer's _begin calls update once to read the first sample, then reset:
        # sampling starts with the first played cycle, after that last reset.
        self.written = 0

    def update(self, out: ReferenceOutput, inp: ProgramInput | None = None) -> int:
        status: int = self.inner.update(out, inp)
        if self.written < self.ring.shape[0]:
            row = self.ring[self.written]
            row[0] = self.loop.t
            row[1:7] = self.twin.plant.wrench_s
            row[7:10] = self.twin.plant.q
            self.written += 1
        pub = self.publisher
        if pub is not None:
            pub.publish(self.loop.t, self.twin.plant.wrench_s, self.twin.plant.q)
        return status


def _check_out(value: Any) -> Path:
    if not isinstance(value, str) or not value:
        raise InputError("calibration_push: out must be the path of the trial file to write")
    out = Path(value)
    if out.suffix != ".npz":
        raise InputError(f"calibration_push: out {out} must end in .npz")
    if out.exists():
        raise InputError(f"calibration_push: {out} exists; the RT process never overwrites")
    if not out.parent.is_dir() or not os.access(out.parent, os.W_OK):
        raise InputError(f"calibration_push: {out.parent} is not a writable directory")
    return out


def calibration_push(params: dict[str, Any], service: RtService) -> ContactRecordingProgram:
    """``run calibration_push {plan, trial, out}`` (module docstring)."""
    allowed = {"plan", "trial", "out", "plate_daq", "twin_contact_shm"}
    extra = sorted(set(params) - allowed)
    if extra:
        raise InputError(f"calibration_push: unknown parameter(s) {extra}; allowed: "
                         f"{sorted(allowed)}")
    plate_daq = params.get("plate_daq", PLATE_DAQ_RT_TWIN)
    if plate_daq not in (PLATE_DAQ_RT_TWIN, PLATE_DAQ_CLIENT):
        raise InputError(f"calibration_push: plate_daq must be {PLATE_DAQ_RT_TWIN!r} or "
                         f"{PLATE_DAQ_CLIENT!r}, got {plate_daq!r}")
    wire_name = params.get("twin_contact_shm")
    try:
        plan = Plan.model_validate(params.get("plan"))
        trial = Trial.model_validate(params.get("trial"))
    except ValidationError as exc:
        raise InputError(f"calibration_push: {validation_summary(exc)}") from None
    out = _check_out(params.get("out"))
    pl = service.pl
    if pl.twin is None and plate_daq != PLATE_DAQ_CLIENT:
        raise InputError("calibration_push: this RT process drives the rig: the plate's DAQ is "
                         "read by the calibration client (plate_daq: client; talus calibrate "
                         "run --backend rt --plate-daq FILE)")
    if pl.twin is None and wire_name is not None:
        raise InputError("calibration_push: twin_contact_shm: this RT process drives the rig "
                         "and has no twin contact to publish")
    if pl.twin is not None and plate_daq == PLATE_DAQ_CLIENT and wire_name is None:
        raise InputError("calibration_push: on the twin a plate read by the client needs "
                         "twin_contact_shm (the twin plate's wire, calibration.twin_plate_daq)")
    if plate_daq == PLATE_DAQ_RT_TWIN and wire_name is not None:
        raise InputError("calibration_push: twin_contact_shm goes with plate_daq: client")
    dt = 1.0 / service.config.rate_hz
    try:
        profile = force_profile(plan, trial, dt)
    except ValueError as exc:
        raise InputError(f"calibration_push: {exc}") from None
    limit = pl.supervisor.limits.max_force_n
    if float(profile.max()) > limit:
        raise InputError(f"calibration_push: trial {trial.id} peaks at {profile.max():.0f} N, "
                         f"above the RT process's force limit {limit:.0f} N (raise "
                         "patient_limits.max_force_n in its config for a calibration)")
    pose = trial_pose(plan, trial)
    try:
        tilt = tilt_profile(plan, trial, dt)
    except ValueError as exc:
        raise InputError(f"calibration_push: {exc}") from None
    gen = ForceTableGenerator(trial.id, profile, pose, dt, pl.model.kin, tilt)
    report = gen.validate()
    if not report.ok:
        raise InputError(f"calibration_push: trial {trial.id}: " + "; ".join(report.violations))
    height = plate_height_m(pl.model, plan.pose_z_m, TOOL_LENGTH_M, START_GAP_M)
    _check_at_pose(pl, trial.id, pose, height)
    twin = pl.twin
    publisher = WirePublisher(wire_name) if wire_name is not None else None
    if twin is not None:
        env = tool_plate(height)

        def place_plate(loop: Any) -> None:
            twin.set_environment(env)          # the operator placed the plate (simulated)
        try:
            pl.loop.call(place_plate, f"calibration plate at {height:.4f} m").result(timeout=2.0)
        except BaseException:
            if publisher is not None:
                publisher.close()
            raise
    program = ContactRecordingProgram(gen, twin, pl.loop, len(profile) + 16, publisher)
    meta = {"trial": trial.model_dump(mode="json"), "plate_height_m": height,
            "tool_length_m": TOOL_LENGTH_M, "dt": dt, "pose": list(pose),
            "profile_sha256": profile_digest(profile), "rt_pid": os.getpid(),
            "plate_daq": plate_daq}
    threading.Thread(target=_record, args=(service, program, out, meta, service.tap.written),
                     name=f"calibration-{trial.id}", daemon=True).start()
    return program


def _check_at_pose(pl: Any, trial_id: str, pose: tuple[float, float, float],
                   height: float) -> None:
    """The plate is placed only with the robot already at the trial's pose and its tool tip
    clear below the plate: the operator never mounts the plate onto the tool."""
    q = np.array(pl.graph.output("encoders.q"), dtype=float)
    cfg = pl.model.kin.fk(q, check=False)
    R = np.array(cfg.rotation).reshape(3, 3)
    s = np.array(pl.model.description.sensor.offset_m)
    tip_z = float((np.array([cfg.x, cfg.y, cfg.z]) + R @ s + TOOL_LENGTH_M * R[:, 2])[2])
    z, roll, pitch = pose
    off = (abs(cfg.z - z), abs(cfg.roll - roll), abs(cfg.pitch - pitch))
    if off[0] > POSE_TOLERANCE_M or max(off[1:]) > POSE_TOLERANCE_RAD:
        raise InputError(f"calibration_push: trial {trial_id}: the robot is not at the trial's "
                         f"pose (z {z:.4f} m, roll {math.degrees(roll):.2f}°, pitch "
                         f"{math.degrees(pitch):.2f}°); move it there first (run move)")
    if tip_z > height - 0.5 * START_GAP_M:
        raise InputError(f"calibration_push: trial {trial_id}: the tool tip ({tip_z:.4f} m) "
                         f"is not clear below the plate ({height:.4f} m)")


def _robot_rows(rows: np.ndarray) -> np.ndarray:
    return np.column_stack([rows[:, 0], rows[:, COLUMNS["wrench"]], rows[:, COLUMNS["q"]],
                            rows[:, COLUMNS["force"]], rows[:, COLUMNS["phase"]]])


def _record(service: RtService, program: ContactRecordingProgram, out: Path,
            meta: dict[str, Any], start: int) -> None:
    """Drain the session tap until the robot is back at rest (or stopped and still), then
    write the trial file. Runs on its own thread, never in the loop."""
    tap = service.tap
    chunks: list[np.ndarray] = []
    seen_motion = False
    outcome = "timeout"
    deadline = time.monotonic() + program.duration_s + END_MARGIN_S
    phase_col = COLUMNS["phase"].start
    try:
        while time.monotonic() < deadline and not service.shutting_down.is_set():
            time.sleep(0.05)
            rows, start = tap.drain(start)
            if not len(rows):
                continue
            chunks.append(_robot_rows(rows))
            phases = rows[:, phase_col]
            seen_motion, decided = program_outcome(phases, seen_motion)
            if decided is not None:
                outcome = decided
                if decided == "stopped":
                    time.sleep(STOP_EVENTS_SETTLE_S)   # the stop's events reach the log
                break
        program.close_wire()
        robot = np.vstack(chunks) if chunks else np.zeros((0, ROBOT_WIDTH))
        meta = {**meta, "outcome": outcome,
                "causes": sorted(service.pl.supervisor.causes),
                "events": [e.as_dict() for e in service.pl.events.snapshot()[-5:]]}
        _write(out, robot, program.ring[:program.written].copy(), meta)
    except Exception:
        import logging
        logging.getLogger(__name__).exception("calibration trial recording failed")
        program.close_wire()
        _write(out, np.zeros((0, ROBOT_WIDTH)), np.zeros((0, CONTACT_WIDTH)),
               {**meta, "outcome": "failed", "causes": [], "events": []})


def _write(out: Path, robot: np.ndarray, contact: np.ndarray, meta: dict[str, Any]) -> None:
    fd, tmp = tempfile.mkstemp(dir=out.parent, suffix=".tmp.npz")
    os.close(fd)
    try:
        np.savez(tmp, robot=robot, contact=contact,
                 meta=np.array(json.dumps(meta, default=str)))
        os.replace(tmp, out)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def rt_programs() -> dict[str, Any]:
    """The calibration programs the RT process offers (``talus.composition``)."""
    return {PROGRAM_NAME: calibration_push}
